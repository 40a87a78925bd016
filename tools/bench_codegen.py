"""What specialisation buys: operations and time per right-hand-side call, cold and warm start.

Compares the shipped paper module (fixed parameters folded in, forward + stick modes) with
a general module of the same scene: every parameter free, every mode. Run:
    .venv/bin/python tools/bench_codegen.py
"""
from __future__ import annotations

import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import sympy as sp

from derivation.codegen import compose_laws, generate_module
from derivation.model import build_model, param_symbol
from derivation.scene import load_scene, parse_scene
from tswm_runtime.model.contract import load_module
from tswm_runtime.jit.signatures import RhsFunction

ROOT = Path(__file__).resolve().parents[1]
CALLS = 2_000_000
REPEATS = 7


@numba.njit(numba.float64(RhsFunction, numba.int64, numba.float64[::1], numba.float64[::1]), cache=True)
def _call_loop(rhs, n, y, p):
    dy = np.empty_like(y)
    total = 0.0
    for i in range(n):
        y[0] = 1.0 + 1e-7 * i
        rhs(0, 0.0, y, p, dy)
        total += dy[0]
    return total


def ops(model, fixed: dict) -> int:
    """count_ops of the tractive-mode a1 with every law inlined, after folding ``fixed``."""
    accel = model.mode("fwd_a").accel.subs(compose_laws(model)).subs(fixed)
    return sp.count_ops(accel)


def ns_per_call(module, p) -> float:
    y = np.array([1.0] * len(module.STATES))
    _call_loop(module.rhs, 10, y, p)
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        _call_loop(module.rhs, CALLS, y, p)
        times.append((time.perf_counter() - start) / CALLS * 1e9)
    return statistics.median(times)


def start_time(cache_dir: str) -> float:
    probe = ("import time; t = time.perf_counter(); import numpy as np; import generated.paper as m; "
             "m.accel(0, 0.0, np.array([1.0]), np.array([200.0, -15000.0])); print(time.perf_counter() - t)")
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip())


def main() -> None:
    paper = load_scene("paper")
    text = (ROOT / "derivation/scenes/paper.toml").read_text().replace(
        'include = ["forward", "stick"]', 'include = ["forward", "backward", "stick"]')
    general_scene = parse_scene(text, "paper-general")
    special, general = build_model(paper), build_model(general_scene)
    fixed = {param_symbol(p): p.value for p in paper.params() if not p.free}
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}, numba {numba.__version__}, sympy {sp.__version__}")
    print(f"count_ops of a1 (tractive, laws inlined): general {ops(general, {})}, specialised {ops(special, fixed)}")
    with tempfile.TemporaryDirectory() as tmp:
        all_free = tuple(p.name for p in general_scene.params())
        path = Path(tmp) / "paper_general.py"
        path.write_text(generate_module(general, free=all_free))
        gen_module = load_module(path)
        p_general = np.array([p.value for p in general_scene.params()])
        t_general = ns_per_call(gen_module, p_general)
        t_special = ns_per_call(load_module("paper"), np.array([200.0, -15000.0]))
        print(f"rhs call, tractive mode, median of {REPEATS} x {CALLS} calls through the integrators' "
              f"function type: general {t_general:.1f} ns, specialised {t_special:.1f} ns "
              f"({t_general / t_special:.2f}x)")
        cold = [start_time(tempfile.mkdtemp(dir=tmp)) for _ in range(3)]
        warm_dir = tempfile.mkdtemp(dir=tmp)
        start_time(warm_dir)
        warm = [start_time(warm_dir) for _ in range(5)]
        print(f"start (new process: import generated.paper + first call): cold median {statistics.median(cold):.2f} s, "
              f"warm (numba cache) median {statistics.median(warm):.2f} s")


if __name__ == "__main__":
    main()
