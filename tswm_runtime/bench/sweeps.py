"""Sweeps end to end: ``tswm sweep`` as whole processes against its targets, and tswm's sweep
against a vmapped diffrax batch of the same scene at equal accuracy.

* Whole processes: ``python -m tswm_runtime.cli sweep paper-runup`` over a grid of m2 x F2_after
  with ``-o`` (tables written), warm numba cache; one case for the start-up; wall seconds from
  the parent, CPU seconds of the child (user + sys), the 1-minute load before each run.
* diffrax (``diffrax_peer``): on ACCURACY_CASES both against the quadrature reference
  (``reference.quadrature``); tswm at the sweep's rtol, diffrax at each of DIFFRAX_RTOLS; the
  loosest diffrax tolerance whose largest error on each of S1 max, v1(T), x1(T) is at most
  tswm's is "equal accuracy" (and, where it differs, the loosest matching x1(T) alone, the
  whole transient: tswm's S1 max and v1(T) sit on an equilibrium it holds exactly, which
  diffrax only approaches). Then the same grid through both, whole calls, rounds alternating
  tswm and diffrax (in one process when jax imports here; else in the interpreter named by
  TSWM_BENCH_JAX_PYTHON, whose timed calls then sit between two halves of tswm's).
"""
from __future__ import annotations

import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from tswm_runtime.bench import diffrax_peer

SCENE = "paper-runup"
M2_RANGE, F2_RANGE = (100.0, 400.0), (-20000.0, 5000.0)
ACCURACY_CASES = ((100.0, -5000.0), (200.0, -15000.0), (400.0, -20000.0), (200.0, 5000.0), (300.0, -20000.0),
                  (150.0, 2000.0))
DIFFRAX_RTOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
ATOL_PER_RTOL = 1e-3
TSWM_RTOL = 1e-6  # the scene's own (the sweep's default)
PROCESS_TARGETS = {10_000: 10_000.0, 100_000: 30_000.0}  # cases -> cases/s of the whole process
STARTUP_TARGET_S = 0.3
DIFFRAX_TARGET = 3.0  # tswm's cases/s over diffrax's at equal accuracy
JAX_PYTHON = "TSWM_BENCH_JAX_PYTHON"


def grid(cases: int) -> tuple[np.ndarray, np.ndarray]:
    """(m2, F2_after) of a grid of min(cases, 100) m2 values by the rest in F2_after, m2 slowest
    (as ``tswm sweep --grid``)."""
    nm = min(cases, 100)
    m2, F2 = np.meshgrid(np.linspace(*M2_RANGE, nm), np.linspace(*F2_RANGE, max(cases // nm, 1)), indexing="ij")
    return m2.ravel(), F2.ravel()


def _grid_options(cases: int) -> list[str]:
    m2, F2 = grid(cases)
    nm = np.unique(m2).size
    return ["--grid", f"m2={M2_RANGE[0]:g}:{M2_RANGE[1]:g}:{nm}", "--grid",
            f"F2_after={F2_RANGE[0]:g}:{F2_RANGE[1]:g}:{m2.size // nm}"]


def _process(argv: list[str]) -> dict:
    """One whole process: wall seconds, its CPU seconds, the load before it."""
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "tswm_runtime.cli", *argv], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"tswm {' '.join(argv)}: exit {done.returncode}: {done.stderr[-400:]}")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return {"wall_s": wall, "cpu_s": cpu, "load": load}


def _sweep_process(options: list[str]) -> dict:
    """``tswm sweep`` with ``options`` into a new directory (no chunk to reuse), timed by ``_process``."""
    with tempfile.TemporaryDirectory() as out:
        return _process(["sweep", SCENE, *options, "--no-progress", "-o", out])


def processes(sizes=tuple(PROCESS_TARGETS), repeats: int = 3, log=print, fraction: float = 1.0) -> list[dict]:
    """``tswm sweep`` as the user calls it: one warm-up, then ``repeats`` whole processes per size
    (and a one-case sweep for the start-up), interleaved; medians against the targets. ``fraction``
    < 1 (the quick bench) runs that share of each size's cases against the size's target
    (``target_cases``: the start-up's share of a process weighs more in a smaller one)."""
    from tswm_runtime.bench import report

    measured = {n: max(int(round(n * fraction)), 1) for n in sizes}
    runs = {"start-up (1 case)": ["--grid", "m2=200", "--grid", "F2_after=-15000"]}
    runs |= {f"{measured[n]} cases": _grid_options(measured[n]) for n in sizes}
    target_of = {measured[n]: n for n in sizes}
    times: dict[str, list[dict]] = {name: [] for name in runs}
    for options in runs.values():
        _sweep_process(options)   # numba's cache, the OS's file cache
    for _ in range(repeats):
        for name, options in runs.items():
            times[name].append(_sweep_process(options))
    rows = []
    for name, runs_of in times.items():
        wall = statistics.median(r["wall_s"] for r in runs_of)
        n = int(name.split()[0]) if name[0].isdigit() else 1
        row = {"command": f"tswm sweep {SCENE} {' '.join(runs[name])} -o DIR", "cases": n,
               "target_cases": target_of.get(n, 1) if name[0].isdigit() else 1, "wall_s_median": wall,
               "wall_s_min": min(r["wall_s"] for r in runs_of), "wall_s_max": max(r["wall_s"] for r in runs_of),
               "cpu_s_median": statistics.median(r["cpu_s"] for r in runs_of),
               "load_1min": ", ".join(f"{r['load']:.1f}" for r in runs_of), "cases_per_s": n / wall}
        row["verdict"] = (report.threshold_text(wall, STARTUP_TARGET_S, "s", higher_is_better=False) if n == 1 else
                          report.threshold_text(n / wall, PROCESS_TARGETS.get(row["target_cases"], math.nan),
                                                "cases/s"))
        log(f"tswm sweep process, {name}: {wall:.2f} s ({row['verdict']})")
        rows.append(row)
    return rows


def tswm_sweep(m2, F2, rtol: float = TSWM_RTOL) -> tuple[dict, float, float]:
    """tswm's ``sweep()`` over the cases: ({"S1", "v_end", "x_end", "ok"} lists, wall and CPU
    seconds of the call, all threads)."""
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.sweeps.sweep import sweep

    module = load_module(SCENE)
    P = np.tile(np.array(module.PARAM_DEFAULTS, np.float64), (len(m2), 1))
    P[:, module.PARAM_NAMES.index("m2")], P[:, module.PARAM_NAMES.index("F2_after")] = m2, F2
    t0, c0 = time.perf_counter(), time.process_time()
    table = sweep(SCENE, P, {"rtol": rtol, "atol": rtol * ATOL_PER_RTOL}).table
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"S1": table["S1m"].tolist(), "v_end": table["v1"].tolist(), "x_end": table["x1"].tolist(),
            "ok": (table["status"] == "finished").tolist()}, seconds, cpu


def _threads() -> int:
    import numba

    return numba.get_num_threads()


def diffrax_runs(jobs: list[dict]) -> tuple[dict | None, str]:
    """``diffrax_peer.run(jobs)`` here if jax imports, else in TSWM_BENCH_JAX_PYTHON; (None, why) if neither."""
    if diffrax_peer.available():
        return {"runs": diffrax_peer.run(jobs), "versions": diffrax_peer.versions()}, "in this process"
    python = os.environ.get(JAX_PYTHON)
    if not python:
        return None, (f"jax and diffrax not importable: the diffrax peer is left out (pip install -e '.[bench-jax]', "
                      f"or name an interpreter that has them in {JAX_PYTHON})")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([python, "-m", "tswm_runtime.bench.diffrax_peer"], input=json.dumps(jobs),
                          capture_output=True, text=True, env=env)
    if done.returncode != 0:
        return None, f"{JAX_PYTHON}={python}: exit {done.returncode}: {done.stderr[-300:]}"
    return json.loads(done.stdout), f"in {python}"


def reference_outcomes() -> list[dict]:
    """The quadrature reference of every ACCURACY_CASES case: S1 max (signed), v1(T), x1(T)."""
    from tswm_runtime.bench.cases import RUNUP
    from tswm_runtime.reference import quadrature as q

    out = []
    for m2, F2 in ACCURACY_CASES:
        loads = [(t, F2 if t > 0 else f) for t, f in RUNUP]
        tr = q.solve(q.paper_wedge(m2), loads, 0.0, 1.0)
        out.append({"S1": float(tr.S_extrema()["S1"][0]), "v_end": float(tr.v_at(1.0)), "x_end": float(tr.x_at(1.0))})
    return out


def largest_errors(outcome: dict, refs: list[dict]) -> dict:
    """Largest over the cases of the bench's errors (``cases.errors``: S1 and x1 relative, v1 relative
    to max(|v1|, 1 m/s)); inf where a case failed."""
    e = {"err_S1": 0.0, "err_v1": 0.0, "err_x1": 0.0}
    for i, ref in enumerate(refs):
        if not outcome["ok"][i]:
            return dict.fromkeys(e, math.inf)
        e["err_S1"] = max(e["err_S1"], abs(outcome["S1"][i] - ref["S1"]) / abs(ref["S1"]))
        e["err_v1"] = max(e["err_v1"], abs(outcome["v_end"][i] - ref["v_end"]) / max(abs(ref["v_end"]), 1.0))
        e["err_x1"] = max(e["err_x1"], abs(outcome["x_end"][i] - ref["x_end"]) / abs(ref["x_end"]))
    return e


def _levels(levels: list[dict], tswm_errors: dict) -> list[tuple[dict, str]]:
    """The diffrax levels to time: the loosest whose three errors are all at most tswm's (else the
    tightest, said so), and the loosest that matches tswm's x1(T) (the whole transient) if it differs."""
    def loosest(keys):
        return next((lv for lv in levels if all(lv[k] <= tswm_errors[k] for k in keys)), None)
    every = loosest(tswm_errors)
    out = [(every, "S1 max, v1(T), x1(T)") if every else (levels[-1], "none (the tightest tried)")]
    transient = loosest(["err_x1"])
    if transient is not None and transient["rtol"] != out[0][0]["rtol"]:
        out.append((transient, "x1(T) only"))
    return out


def versus_diffrax(cases: int = 10_000, repeats: int = 5, log=print) -> dict:
    """tswm's sweep() against the vmapped diffrax batch: errors per tolerance, and cases/s of both
    on a grid of ``cases`` at the tolerances of equal accuracy (``_levels``; module docstring)."""
    from tswm_runtime.bench import report

    refs = reference_outcomes()
    m2a, F2a = (np.array(c) for c in zip(*ACCURACY_CASES))
    tswm_errors = largest_errors(tswm_sweep(m2a, F2a)[0], refs)
    accuracy, where = diffrax_runs([{"m2": m2a.tolist(), "F2": F2a.tolist(), "rtol": r, "atol": r * ATOL_PER_RTOL}
                                    for r in DIFFRAX_RTOLS])
    out = {"scene": SCENE, "tswm_rtol": TSWM_RTOL, "tswm_errors": tswm_errors, "diffrax": where}
    if accuracy is None:
        log(where)
        return out
    levels = [{"rtol": run["rtol"], **largest_errors(run, refs)} for run in accuracy["runs"]]
    chosen = _levels(levels, tswm_errors)
    m2, F2 = grid(cases)
    jobs = [{"m2": m2.tolist(), "F2": F2.tolist(), "rtol": lv["rtol"], "atol": lv["rtol"] * ATOL_PER_RTOL}
            for lv, _ in chosen]
    tswm_s, diffrax_runs_of, loads = [], [[] for _ in jobs], []
    tswm_sweep(m2[:1000], F2[:1000])   # warm-up
    if diffrax_peer.available():
        diffrax_peer.run([{**job, "repeats": 0} for job in jobs])
        for _ in range(repeats):
            loads.append(os.getloadavg()[0])
            tswm_s.append(tswm_sweep(m2, F2)[1:])
            for k, job in enumerate(jobs):
                diffrax_runs_of[k].append(diffrax_peer.run([{**job, "repeats": 1}])[0])
    else:
        tswm_s = [tswm_sweep(m2, F2)[1:] for _ in range(repeats // 2 + 1)]
        loads.append(os.getloadavg()[0])
        diffrax_runs_of = [[run] for run in diffrax_runs([{**job, "repeats": repeats} for job in jobs])[0]["runs"]]
        loads.append(os.getloadavg()[0])
        tswm_s += [tswm_sweep(m2, F2)[1:] for _ in range(repeats - len(tswm_s))]
    rate = len(m2) / statistics.median(s for s, _ in tswm_s)
    tswm_cpu = statistics.median(c for _, c in tswm_s)
    timings = []
    for (lv, matches), runs in zip(chosen, diffrax_runs_of):
        seconds = [s for run in runs for s in run["seconds"]]
        rate_d = len(m2) / statistics.median(seconds)
        cpu_d = statistics.median(c for run in runs for c in run["cpu_seconds"])
        timings.append({"diffrax_rtol": lv["rtol"], "matches_tswm_on": matches, "diffrax_s_median": statistics.median(seconds),
                        "diffrax_cpu_s_median": cpu_d, "diffrax_cases_per_s": rate_d, "tswm_over_diffrax": rate / rate_d,
                        "tswm_over_diffrax_cpu": cpu_d / tswm_cpu,   # the steadier figure on a loaded machine
                        "verdict": report.threshold_text(rate / rate_d, DIFFRAX_TARGET, "x")})
        log(f"tswm sweep() {rate:.0f} cases/s, diffrax at rtol {lv['rtol']:g} ({matches}) {rate_d:.0f} cases/s "
            f"({timings[-1]['verdict']}; CPU seconds {cpu_d / tswm_cpu:.2f}x)")
    return out | {"versions": accuracy["versions"], "diffrax_levels": levels, "cases": len(m2),
                  "tswm_s_median": statistics.median(s for s, _ in tswm_s),
                  "tswm_cpu_s_median": tswm_cpu, "tswm_cases_per_s": rate,
                  "tswm_threads": _threads(), "timings": timings,
                  "load_1min": loads}
