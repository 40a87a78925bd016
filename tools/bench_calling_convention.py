"""Measure how model functions are best passed to the numba integrator.

Variants, same integrator code (tswm_runtime.integration.segment):
  signature   integrate_segment, compiled with an explicit signature whose model
              arguments are numba FunctionTypes (the runtime's design).
  dispatcher  segment._run called with the model's dispatchers as plain arguments:
              numba types each as its own Dispatcher and specialises the integrator
              for that model (numba issue 9237).
and a micro-benchmark of one rhs call: through a FunctionType argument against a
direct call of a module global (what a per-model kernel would do).

Each variant runs twice in fresh processes sharing an initially empty
NUMBA_CACHE_DIR (cold, then warm); the project's own __pycache__ is not touched.
The model is written to a real file, as generated modules are.

    .venv/bin/python tools/bench_calling_convention.py
"""
import argparse
import importlib
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

MODEL_SOURCE = textwrap.dedent('''
    """Harmonic oscillator in the generated-module contract (benchmark model)."""
    from numba import float64, int64, njit
    from tswm_runtime.jit.signatures import GUARDS_SIG, JAC_SIG, RHS_SIG, RhsFunction, VECTOR

    @njit(RHS_SIG, cache=True)
    def rhs(mode, t, y, p, dy):
        dy[0] = y[1]
        dy[1] = -p[0] * y[0]

    @njit(JAC_SIG, cache=True)
    def jac(mode, t, y, p, J, dfdt):
        J[0, 0] = 0.0
        J[0, 1] = 1.0
        J[1, 0] = -p[0]
        J[1, 1] = 0.0
        dfdt[0] = 0.0
        dfdt[1] = 0.0

    @njit(GUARDS_SIG, cache=True)
    def guards(mode, t, y, p, g):
        g[0] = y[0] - 2.0

    @njit(float64(int64, VECTOR, VECTOR, VECTOR), cache=True)
    def loop_global(n, y, p, dy):
        for i in range(n):
            rhs(0, 0.0, y, p, dy)
            y[0] += 1e-9 * dy[0]
            y[1] += 1e-9 * dy[1]
        return y[0]

    @njit(float64(int64, RhsFunction, VECTOR, VECTOR, VECTOR), cache=True)
    def loop_argument(n, f, y, p, dy):
        for i in range(n):
            f(0, 0.0, y, p, dy)
            y[0] += 1e-9 * dy[0]
            y[1] += 1e-9 * dy[1]
        return y[0]
''')

T_END = 2000.0  # About 320 periods of the oscillator.
RTOL = {"dopri5": 1e-10, "rosenbrock23": 1e-6}  # About 5e4 and 1.6e5 steps.
MICRO_CALLS = 20_000_000
REPEATS = 5


def _arguments(np, seg, model, method, rtol, n_guards):
    """Keyword arguments of integrate_segment (segment._run takes them renamed)."""
    return dict(method=method, rhs=model.rhs, jac=model.jac, guards=model.guards, mode=0,
                p=np.ones(1), t0=0.0, y0=np.array([1.0, 0.0]), t_end=T_END, rtol=rtol,
                atol=np.full(2, rtol), h0=0.0, hmin=0.0, hmax=np.inf, max_steps=10**8,
                directions=np.zeros(n_guards, np.int64), gtol=0.0, ttol=0.0,
                t_out=np.zeros(0), i_out=0, y_out=np.zeros((0, 2)), y_stop=np.zeros(2),
                counters=np.zeros(4, np.int64))


def _call(seg, single, variant, kw):
    kw["counters"][:] = 0
    if variant == "signature":
        return single.integrate_segment(**kw)
    args = {k: v for k, v in kw.items() if k not in ("y0", "y_stop", "i_out")}
    return seg._run(**args, i=kw["i_out"], y=kw["y0"].copy())


def phase(variant):
    """One process: import, first call (compiles or loads), steady-state timings."""
    t0 = time.perf_counter()
    import numpy as np
    importlib.import_module("numba")      # timed: the import alone
    t_numba = time.perf_counter()
    from tswm_runtime.integration import segment as seg
    from tswm_runtime.integration import single
    import bench_model as model
    t_import = time.perf_counter()
    out = {"import_numba_s": t_numba - t0, "import_runtime_and_model_s": t_import - t_numba}
    if variant == "micro":
        y, p, dy = np.array([1.0, 0.0]), np.ones(1), np.zeros(2)
        for name, call in (("global", lambda: model.loop_global(MICRO_CALLS, y, p, dy)),
                           ("argument", lambda: model.loop_argument(MICRO_CALLS, model.rhs, y,
                                                                      p, dy))):
            call()
            out[f"{name}_ns_per_call"] = 1e9 * _best(call) / MICRO_CALLS
        return out
    for n_guards, method, label in ((0, seg.DOPRI5, "dopri5"), (1, seg.DOPRI5, "dopri5_guard"),
                                    (0, seg.ROSENBROCK23, "rosenbrock23")):
        kw = _arguments(np, seg, model, method, RTOL[label.split("_")[0]], n_guards)
        t1 = time.perf_counter()
        result = _call(seg, single, variant, kw)
        out[f"{label}_first_call_s"] = time.perf_counter() - t1
        out[f"{label}_run_s"] = _best(lambda: _call(seg, single, variant, kw))
        out[f"{label}_rhs_calls"] = int(kw["counters"][2])
        out[f"{label}_steps"] = int(kw["counters"][0])
        assert result[0] == seg.REACHED_END, result
    disp = single.integrate_segment if variant == "signature" else seg._run
    out["cache_hits"] = sum(disp.stats.cache_hits.values())
    out["cache_misses"] = sum(disp.stats.cache_misses.values())
    return out


def _best(call):
    times = []
    for _ in range(REPEATS):
        t = time.perf_counter()
        call()
        times.append(time.perf_counter() - t)
    return min(times)


def _spawn(variant, workdir, cache_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir),
               PYTHONPATH=os.pathsep.join([str(workdir), str(ROOT)]))
    proc = subprocess.run([sys.executable, __file__, "--phase", variant], env=env,
                          capture_output=True, text=True, check=True)
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    result["warnings"] = sorted({line for line in proc.stderr.splitlines() if "Warning" in line})
    return result


def main():
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        (workdir / "bench_model.py").write_text(MODEL_SOURCE)
        for variant in ("signature", "dispatcher", "micro"):
            cache = workdir / f"cache_{variant}"
            results[variant] = {"cold": _spawn(variant, workdir, cache),
                                "warm": _spawn(variant, workdir, cache)}
    _report(results)


def _report(results):
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} cpus")
    print("\nstart-up per process (s): 'import' = import of tswm_runtime.integration.segment and the model;"
          "\n'1st calls' = first call minus a steady-state run, summed over the three runs")
    print(f"{'variant':<11}{'':6}{'numba':>8}{'import':>8}{'1st calls':>10}{'hits':>6}"
          f"{'misses':>7}")
    for variant in ("signature", "dispatcher"):
        for when in ("cold", "warm"):
            r = results[variant][when]
            first = sum(r[f"{label}_first_call_s"] - r[f"{label}_run_s"]
                        for label in ("dopri5", "dopri5_guard", "rosenbrock23"))
            print(f"{variant:<11}{when:<6}{r['import_numba_s']:8.2f}"
                  f"{r['import_runtime_and_model_s']:8.2f}{first:10.3f}{r['cache_hits']:6d}"
                  f"{r['cache_misses']:7d}")
            for w in r["warnings"]:
                print(f"{'':17}{w[:100]}")
    print("\nsteady state (warm processes, best of %d)" % REPEATS)
    sig, dis = results["signature"]["warm"], results["dispatcher"]["warm"]
    for label in ("dopri5", "dopri5_guard", "rosenbrock23"):
        calls = sig[f"{label}_rhs_calls"]
        extra = (sig[f"{label}_run_s"] - dis[f"{label}_run_s"]) / calls * 1e9
        print(f"  {label:<13} {sig[f'{label}_steps']:7d} steps {calls:8d} rhs calls: "
              f"signature {sig[f'{label}_run_s'] * 1e3:7.1f} ms, dispatcher "
              f"{dis[f'{label}_run_s'] * 1e3:7.1f} ms, ratio "
              f"{sig[f'{label}_run_s'] / dis[f'{label}_run_s']:.2f}, "
              f"difference {extra:5.1f} ns per rhs call")
    micro = results["micro"]["warm"]
    print(f"  one rhs call: FunctionType argument {micro['argument_ns_per_call']:.2f} ns, "
          f"module global {micro['global_ns_per_call']:.2f} ns "
          f"(overhead {micro['argument_ns_per_call'] - micro['global_ns_per_call']:.2f} ns)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phase", choices=["signature", "dispatcher", "micro"])
    args = parser.parse_args()
    if args.phase:
        print(json.dumps(phase(args.phase)))
    else:
        main()
