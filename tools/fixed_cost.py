"""The fixed cost of simulate(): whole calls that read the status, the maxima and the final state (a new
F2_after on every call), the time spent in the compiled kernel (its entry point called directly, the
unboxing of its arguments included), and per call the fixed cost = whole call - kernel; medians of wall
and thread-CPU time. Then, unless --quick, where the rest goes (simulate's helpers wrapped by timers,
which add ~1 us each). Run:
    PYTHONPATH=. .venv/bin/python tools/fixed_cost.py [SCENE] [CALLS] [T_END] [--quick]
A tiny T_END (1e-9: one step) makes the integration trivial; the default 1 s is the whole run-up.
"""
import os
import statistics
import sys
import time

import numpy as np

from tswm_runtime.bench.cases import timed_calls
from tswm_runtime.common import provenance
from tswm_runtime.simulation import simulate as S

args = [a for a in sys.argv[1:] if not a.startswith("--")]
scene = args[0] if args else "paper-runup"
N = int(args[1]) if len(args) > 1 else 2000
t_end = float(args[2]) if len(args) > 2 else 1.0
rng = np.random.default_rng(1)


def calls(n):
    """n whole calls (``bench.cases.timed_calls``): wall, thread-CPU and kernel ns each, and the last Result."""
    return timed_calls(scene, lambda: {"F2_after": -rng.uniform(5e3, 2e4)}, n, t_end=t_end)


def med(ns):
    return statistics.median(ns) / 1e3


calls(300)
wall, cpu, kernel, r = calls(N)
fixed = [w - k for w, k in zip(wall, kernel)]
box = provenance.machine()
print(f"{scene} t_end {t_end:g} (n_steps {r.n_steps}, events {len(r.events)}), {N} calls; {box['cpu']}, "
      f"{box['cores']} cores, load {os.getloadavg()[0]:.1f}:")
print(f"  whole call {med(wall):.1f} us wall ({med(cpu):.1f} us thread CPU), kernel {med(kernel):.1f} us, "
      f"fixed cost (whole - kernel) {med(fixed):.1f} us; 10th/90th percentile of the fixed cost "
      f"{np.percentile(fixed, 10) / 1e3:.1f}/{np.percentile(fixed, 90) / 1e3:.1f} us")
if "--quick" in sys.argv:
    sys.exit()
spent = {}


def wrap(owner, name, label=None):
    f = getattr(owner, name)

    def timer(*a, **k):
        t0 = time.perf_counter_ns()
        try:
            return f(*a, **k)
        finally:
            spent.setdefault(label or name, []).append(time.perf_counter_ns() - t0)
    setattr(owner, name, timer)


for name in ("_load", "parameter_vector", "prepared", "method_step", "_integrate", "check_atol_scale", "RunRecord",
             "Rows"):
    wrap(S, name)
wrap(S.entry, "run", "entry.run")
wrap(S.Result, "build", "Result.build")
wrapped, _, kernel, _ = calls(N)
spent["kernel"] = kernel
print(f"  with timers: whole {med(wrapped):.1f} us; medians per call:")
for k, v in sorted(spent.items(), key=lambda kv: -statistics.median(kv[1])):
    print(f"    {k:22s} {med(v):7.1f} us")
