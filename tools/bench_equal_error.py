"""tswm simulate() against the peers at equal error 1e-6 and 1e-9, new parameters on every call.

Uses tswm_runtime.bench (cases, reference, peers, cost_at) on the run-up with a load step, the
decelerate-and-stick and the stiff-drive cases. Per case and solver (tswm with the scene's method,
"tswm", and with rosenbrock23; the peers available: CVODE when scikit-sundae imports), every rtol of
the grid: one untimed call (its error against the quadrature reference), then ROUNDS interleaved
rounds over all (solver, rtol) in a shuffled order, whole calls, one process; every call gets a new m2
(``bench.cases.new_m2``: new to every cache, the same problem to 1e-11). Costs at equal error:
bench.report.cost_at. Prints the machine and the load before and after. Run:
    PYTHONPATH=. .venv/bin/python tools/bench_equal_error.py [ROUNDS]
"""
import math
import os
import random
import statistics
import sys
import time

from tswm_runtime.bench.cases import CASES, errors, reference, run_peer, run_simulate
from tswm_runtime.bench.peers import available_methods
from tswm_runtime.bench.report import cost_at
from tswm_runtime.common import provenance

ROUNDS = int(sys.argv[1]) if len(sys.argv) > 1 else 5
NAMES = ("run-up then load", "decelerate-and-stick", "stiff drive m1=0.05")
TOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
TSWM = {"tswm": None, "tswm rosenbrock23": "rosenbrock23"}


def tswm(case, rtol, method):
    return run_simulate(case, rtol, rtol * 1e-3, method=method)


def peer(case, name, rtol):
    return run_peer(case, name, rtol, rtol * 1e-3)


load_before = os.getloadavg()
peers = available_methods()
configs = []
for name in NAMES:
    case = CASES[name]
    for rtol in TOLS:
        configs += [(case, label, rtol, lambda c=case, r=rtol, m=m: tswm(c, r, m)) for label, m in TSWM.items()]
        configs += [(case, p, rtol, lambda c=case, p=p, r=rtol: peer(c, p, r)) for p in peers]
errs, times = {}, {}
for case, solver, rtol, call in configs:
    try:
        errs[(case.name, solver, rtol)] = errors(call(), reference(case))["err"]
    except Exception as error:  # noqa: BLE001 - a solver that fails at a tolerance is left out there
        print(f"  {solver} {rtol:g} {case.name}: {error}", file=sys.stderr)
live = [c for c in configs if (c[0].name, c[1], c[2]) in errs]
for rep in range(ROUNDS):
    order = live.copy()
    random.Random(rep).shuffle(order)
    for case, solver, rtol, call in order:
        t0 = time.perf_counter()
        call()
        times.setdefault((case.name, solver, rtol), []).append(time.perf_counter() - t0)
box = provenance.machine()
print(f"{box['cpu']}, {box['cores']} cores; 1-minute load {load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} "
      f"after; peers: {', '.join(peers)}; rounds {ROUNDS}")
for name in NAMES:
    for level in (1e-6, 1e-9):
        cost = {}
        for solver in (*TSWM, *peers):
            pts = [(errs[k], statistics.median(times[k])) for k in times if k[0] == name and k[1] == solver]
            cost[solver] = cost_at(pts, level)
        best = min((s for s in peers if not math.isnan(cost[s])), key=cost.get, default=None)
        line = f"{name:22s} err {level:g}: fastest peer {best} {cost[best] * 1e6 if best else math.nan:9.1f} us"
        for label in TSWM:
            f = cost[best] / cost[label] if best else math.nan
            line += f"; {label} {cost[label] * 1e6:8.1f} us, factor {f:6.1f}"
        print(line)
for name in NAMES:
    for label in TSWM:
        print(f"{name} {label} errors:", {r: f"{errs.get((name, label, r), math.nan):.1e}" for r in TOLS})
