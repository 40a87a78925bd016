"""The two-stage drive train (worm gear and stem nut against a seat) in the bench: tswm's whole
simulate_chain call against scipy's solve_ivp written as a careful user writes it, at equal error
against the DOP853 reference at rtol 1e-13 (tswm_runtime/bench/chain.py). Interleaved shuffled
rounds, medians; prints the machine, the load before and after, the errors and the factor at
errors 1e-6 and 1e-9 against the 20x target. Run:
    PYTHONPATH=. .venv/bin/python tools/bench_chain.py [ROUNDS]
"""
import sys

from tswm_runtime.bench import chain
from tswm_runtime.common import provenance

ROUNDS = int(sys.argv[1]) if len(sys.argv) > 1 else 5

result = chain.run(ROUNDS, log=lambda line: print(line, file=sys.stderr))
box = provenance.machine()
print(f"{box['cpu']}, {box['cores']} cores; 1-minute load {result['load'][0]:.1f} before, {result['load'][1]:.1f} after; "
      f"rounds {result['rounds']}; reference: q0(t_end) = {result['reference'].q_end:.12g} rad, "
      f"{result['reference'].events} events")
for solver in ("tswm", *chain.PEERS):
    print(f"{solver:7s}", "  ".join(f"rtol {r:g}: err {result['errors'].get((solver, r), float('nan')):.1e} "
                                   f"{result['median_s'].get((solver, r), float('nan')) * 1e3:.2f} ms" for r in chain.TOLS))
for v in result["verdicts"]:
    print(f"error {v['level']:g}: tswm {v['tswm_s'] * 1e3:.3f} ms, fastest peer {v['peer']} {v['peer_s'] * 1e3:.3f} ms: "
          f"factor {v['factor']:.2f} (target {v['target']:g}x: {'met' if v['factor'] >= v['target'] else 'missed'})")
