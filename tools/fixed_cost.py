"""The fixed cost of simulate(): median wall and thread-CPU time of whole calls that read the status,
the maxima and the final state (a new F2_after on every call), then where the time goes (simulate's
helpers wrapped by timers). Reads ``final_state`` where the Result has it, else the last row (older
trees, for before/after comparisons run from each tree in turn). Run:
    PYTHONPATH=. .venv/bin/python tools/fixed_cost.py [SCENE] [CALLS] [T_END] [--quick]
"""
import statistics
import sys
import time
import numpy as np
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.simulation import simulate as S

scene = sys.argv[1] if len(sys.argv) > 1 else "paper-runup"
N = int(sys.argv[2]) if len(sys.argv) > 2 else 2000
t_end = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
rng = np.random.default_rng(1)

def final(r):
    fs = getattr(r, "final_state", None)
    return fs["v1"] if fs is not None else float(r.v1[-1])

CPU = []
def calls(n):
    out = []
    CPU.clear()
    for _ in range(n):
        F = -rng.uniform(5e3, 2e4)
        c0 = time.thread_time_ns()
        t0 = time.perf_counter_ns()
        r = simulate(scene, {"F2_after": F}, t_end=t_end)
        (r.status, r.S1_max, r.S2_max, final(r))
        out.append(time.perf_counter_ns() - t0)
        CPU.append(time.thread_time_ns() - c0)
    return out, r

calls(300)
whole, r = calls(N)
med = statistics.median(whole) / 1e3
print(f"{scene} t_end {t_end:g}: whole call median {med:.1f} us wall, {statistics.median(CPU)/1e3:.1f} us thread CPU "
      f"(n_steps {r.n_steps}, events {len(r.events)})")
if "--quick" in sys.argv:
    sys.exit()
# where the time goes: wrap simulate's helpers
spent = {}
def wrap(owner, name, label=None):
    f = getattr(owner, name)
    def timed(*a, **k):
        t0 = time.perf_counter_ns()
        try:
            return f(*a, **k)
        finally:
            spent.setdefault(label or name, []).append(time.perf_counter_ns() - t0)
    setattr(owner, name, timed)
for name in ("parameter_vector", "settings", "initial_state", "_output_times", "method_step", "_first_non_finite",
             "check_atol_scale", "status_message", "fill_rows", "_integrate", "last_state", "largest_states"):
    if hasattr(S, name):
        wrap(S, name)
wrap(S.entry, "integrate", "entry.integrate")
if hasattr(S.Result, "build"):
    build = S.Result.build.__func__
    def tb(cls, *a, **k):
        t0 = time.perf_counter_ns()
        try:
            return build(cls, *a, **k)
        finally:
            spent.setdefault("Result.build", []).append(time.perf_counter_ns() - t0)
    S.Result.build = classmethod(tb)
wrapped, _ = calls(N)
print(f"  with timers: whole {statistics.median(wrapped)/1e3:.1f} us; medians per call:")
for k, v in sorted(spent.items(), key=lambda kv: -statistics.median(kv[1])):
    print(f"    {k:22s} {statistics.median(v)/1e3:7.1f} us  (x{len(v)//N})")
