"""tswm simulate() against the peers at equal error 1e-6 and 1e-9, new parameters on every call.

Uses tswm_runtime.bench (cases, reference, peers, cost_at) on the run-up with a load step, the
decelerate-and-stick and the stiff-drive cases. Per case and solver, every rtol of the grid: one
untimed call (its error against the quadrature reference), then ROUNDS interleaved rounds over all
(solver, rtol) in a shuffled order, whole calls, one process; each call gets m2 = 200 kg + k * 1e-10 kg
(k: the call's number), new to every cache, the same problem to 1e-12. Costs at equal error:
bench.report.cost_at. Run:
    PYTHONPATH=. .venv/bin/python tools/bench_equal_error.py [ROUNDS]
"""
import dataclasses
import math
import random
import statistics
import sys
import time

from tswm_runtime.bench.cases import CASES, errors, reference, run_peer
from tswm_runtime.bench.peers import available_methods
from tswm_runtime.bench.report import cost_at
from tswm_runtime.bench.peers import Outcome
from tswm_runtime.simulation.simulate import simulate

ROUNDS = int(sys.argv[1]) if len(sys.argv) > 1 else 5
NAMES = ("run-up then load", "decelerate-and-stick", "stiff drive m1=0.05")
TOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
count = [0]

def new_m2(case):
    count[0] += 1
    return case.m2 + count[0] * 1e-10

def tswm(case, rtol):
    m2 = new_m2(case)
    r = simulate(case.scene, {**dict(case.params), "m2": m2}, rtol=rtol, atol=rtol * 1e-3, **case.overrides())
    end = getattr(r, "final_state", None) or {"v1": float(r.v1[-1]), "x1": float(r.x1[-1])}  # before: the rows
    if r.status != "finished":
        raise RuntimeError(r.message)
    return Outcome(r.S1_max, end["v1"], [("load" if e.guard.startswith("load") else e.guard, e.t) for e in r.events],
                   r.nfev, end["x1"] - r.settings["x1"])

def peer(case, method, rtol):
    return run_peer(dataclasses.replace(case, m2=new_m2(case)), method, rtol, rtol * 1e-3)

peers = available_methods()
configs = []
for name in NAMES:
    case = CASES[name]
    for rtol in TOLS:
        configs.append((case, "tswm", rtol, lambda c=case, r=rtol: tswm(c, r)))
        for m in peers:
            configs.append((case, m, rtol, lambda c=case, m=m, r=rtol: peer(c, m, r)))
errs, times = {}, {}
for case, solver, rtol, call in configs:
    try:
        errs[(case.name, solver, rtol)] = errors(call(), reference(case))["err"]
    except Exception as error:
        print(f"  {solver} {rtol:g} {case.name}: {error}", file=sys.stderr)
live = [c for c in configs if (c[0].name, c[1], c[2]) in errs]
for rep in range(ROUNDS):
    order = live.copy(); random.Random(rep).shuffle(order)
    for case, solver, rtol, call in order:
        t0 = time.perf_counter(); call(); times.setdefault((case.name, solver, rtol), []).append(time.perf_counter() - t0)
print(f"peers: {', '.join(peers)}; rounds {ROUNDS}")
for name in NAMES:
    for level in (1e-6, 1e-9):
        cost = {}
        for solver in ("tswm", *peers):
            pts = [(errs[k], statistics.median(times[k])) for k in times if k[0] == name and k[1] == solver]
            cost[solver] = cost_at(pts, level)
        best = min((s for s in peers if not math.isnan(cost[s])), key=cost.get, default=None)
        f = cost[best] / cost["tswm"] if best else math.nan
        print(f"{name:24s} err {level:g}: tswm {cost['tswm']*1e6:9.1f} us, fastest peer {best} "
              f"{cost[best]*1e6 if best else math.nan:10.1f} us, factor {f:6.1f}")
for name in NAMES:
    print(name, "tswm errors:", {r: f"{errs.get((name, 'tswm', r), math.nan):.1e}" for r in TOLS})
