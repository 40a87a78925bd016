"""Work-precision benchmark: tswm against scipy's solve_ivp and SUNDIALS CVODE.

Every solver is timed the way a user calls it, one whole call in this process:

    tswm simulate            simulate(scene, params, rtol=, atol=) with its default
                             output (1001 points), then max |S1|, v1(t_end), events
    tswm simulate points=2   the same with points=2
    tswm sweep per case      sweep(scene, P) over N identical rows (all cores), the whole
                             call divided by N
    RK45 ... LSODA, CVODE    the careful user's peer (``bench_peers``): set-up,
                             integration with events and restarts, max |S1|, events

against an independent reference (``quadrature``, per case). Each configuration gets
one untimed warm-up call (numba's cache, imports; its outcome gives the errors), then
``repeats`` rounds over all configurations, each round in its own shuffled order (seeded
by the round), so that load drifts hit every solver alike and no configuration always
follows the same one: a call finds the caches as another solver left them, and in a fixed
order the peers would always follow another scipy call and each tswm variant the same
neighbour. Medians with min and max. The cold-start target is reported with the
measured factor, never asserted.

Beside these rounds, ``main`` runs the other parts of the bench (PARTS: the fixed cost, the sweeps
end to end, ``tswm generate``, the empty cache, the drive train) and prints every figure beside its
target (``targets``).

Run: ``tswm bench [--quick] [-o DIR]`` or ``python tools/bench_work_precision.py``.
"""
from __future__ import annotations

import json
import math
import os
import random
import statistics
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

from tswm_runtime.bench import report
from tswm_runtime.common import provenance
from tswm_runtime.common.words import plural
from tswm_runtime.bench.cases import (CASES, FIXED_COST_T_END, errors, fixed_cost, reference, run_fixed_cost,
                                      run_peer, run_simulate, run_sweep)
from tswm_runtime.bench.peers import available_methods
from tswm_runtime.bench.targets import MESSAGE_TARGET_S

TOLS_FULL = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11)
TOLS_QUICK = (1e-4, 1e-6, 1e-8, 1e-10)
ATOL_PER_RTOL = 1e-3  # atol = rtol * 1e-3 for every solver (v1 ~ 7 m/s)
THROUGHPUT_RTOL = 1e-6
NO_ERRORS = dict.fromkeys(("err_S1", "err_v1", "err_x1", "err_t", "err"), math.nan)  # a failed run, the fixed cost


def configurations(cases, tols, peers, sweep_n):
    """[(case, solver, rtol, call, divisor)]: every solver at every tolerance on every case (tswm's
    simulate() with the scene's method, "tswm simulate", and with each other method, each down to
    the tightest rtol it accepts, ``METHOD_RTOL_MIN``), and per case tswm's fixed cost per call
    (``run_fixed_cost``, at rtol 1e-6)."""
    from tswm_runtime.model.scenes import load_model
    from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN, METHODS

    out = []
    for case in cases:
        own = load_model(case.scene).RUN["method"]
        others = [m for m in METHODS if m != own]
        out.append((case, report.TSWM_FIXED_COST, THROUGHPUT_RTOL,
                    partial(run_fixed_cost, case, THROUGHPUT_RTOL, THROUGHPUT_RTOL * ATOL_PER_RTOL), 1))
        for rtol in tols:
            atol = rtol * ATOL_PER_RTOL
            if rtol >= METHOD_RTOL_MIN[own][0]:
                out.append((case, report.TSWM_SIMULATE, rtol, partial(run_simulate, case, rtol, atol), 1))
                out.append((case, "tswm simulate points=2", rtol, partial(run_simulate, case, rtol, atol, 2), 1))
                out.append((case, "tswm sweep per case", rtol, partial(run_sweep, case, rtol, atol, sweep_n),
                            sweep_n))
            out += [(case, f"tswm simulate {m}", rtol, partial(run_simulate, case, rtol, atol, method=m), 1)
                    for m in others if rtol >= METHOD_RTOL_MIN[m][0]]
            out += [(case, p, rtol, partial(run_peer, case, p, rtol, atol), 1) for p in peers]
    return out


def measure(configs, repeats, log=print):
    """Rows of errors and median/min/max seconds per call (see the module docstring)."""
    outcomes, times = [], [[] for _ in configs]
    for case, solver, rtol, call, _ in configs:
        try:
            outcomes.append(call())
        except Exception as error:  # noqa: BLE001 - a failing solver is reported, not fatal
            outcomes.append(error)
            log(f"  {solver} rtol {rtol:g} on {case.name} failed: {error}")
    live = [i for i, o in enumerate(outcomes) if not isinstance(o, Exception)]
    for rep in range(repeats):
        order = live.copy()
        random.Random(rep).shuffle(order)
        for i in order:
            t0 = time.perf_counter()
            configs[i][3]()
            times[i].append((time.perf_counter() - t0) / configs[i][4])
        log(f"  round {rep + 1}/{repeats} done")
    rows = []
    for (case, solver, rtol, _, _), out, ts in zip(configs, outcomes, times):
        row = {"case": case.name, "solver": solver, "rtol": rtol, "atol": rtol * ATOL_PER_RTOL}
        if isinstance(out, Exception):
            row |= NO_ERRORS
            row |= {"t_med": math.nan, "t_min": math.nan, "t_max": math.nan, "repeats": 0, "events": -1,
                    "nfev": -1, "steps": -1, "status": f"failed: {out}"}
        else:
            row |= errors(out, reference(case)) if solver != report.TSWM_FIXED_COST else NO_ERRORS
            row |= {"t_med": statistics.median(ts), "t_min": min(ts), "t_max": max(ts), "repeats": len(ts),
                    "events": len(out.events) if out.events is not None else "n/a", "nfev": out.nfev,
                    "steps": out.steps, "status": "finished"}
        rows.append(row)
    return rows


def throughput(n_cases: int, repeats: int = 3, log=print) -> dict:
    """Cases per second of a real grid (paper-runup, m2 x F2_after) through sweep() at
    rtol 1e-6 on all cores: whole calls, median of repeats after one warm-up call."""
    import numba
    import numpy as np

    from tswm_runtime.model.contract import load_module
    from tswm_runtime.sweeps.sweep import grid_cases, sweep

    module = load_module("paper-runup")
    nm = max(int(round(math.sqrt(n_cases))), 1)
    nf = max(n_cases // nm, 1)
    P = grid_cases(module, {"m2": np.linspace(100.0, 400.0, nm), "F2_after": np.linspace(-20000.0, 5000.0, nf)})
    settings = {"rtol": THROUGHPUT_RTOL, "atol": THROUGHPUT_RTOL * ATOL_PER_RTOL}
    table = sweep("paper-runup", P, settings).table
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sweep("paper-runup", P, settings)
        times.append(time.perf_counter() - t0)
    rate = len(P) / statistics.median(times)
    out = {"scene": "paper-runup", "grid": f"m2 100..400 ({nm}) x F2_after -20000..5000 ({nf})", "cases": len(P),
           "rtol": THROUGHPUT_RTOL, "threads": numba.get_num_threads(), "cores": os.cpu_count(),
           "s_median": statistics.median(times), "s_min": min(times), "s_max": max(times),
           "cases_per_s": rate, "statuses": table["status"].value_counts().to_dict(),
           "verdict": report.threshold_text(rate, report.SWEEP_TARGET, "cases/s")}
    log(f"sweep throughput: {rate:.0f} cases/s ({out['verdict']})")
    return out


def flat_cost(rows, short="run-up then load", long="long run T=100", rtol=THROUGHPUT_RTOL) -> list[dict]:
    """tswm's median time on the long run over the same case with t_end = 1 s, at rtol 1e-6."""
    out = []
    for solver in (report.TSWM_SIMULATE, "tswm simulate points=2"):
        pick = {r["case"]: r for r in rows if r["solver"] == solver and r["rtol"] == rtol}
        if short in pick and long in pick:
            ratio = pick[long]["t_med"] / pick[short]["t_med"]
            out.append({"solver": solver, "t_end_1s": pick[short]["t_med"], "t_end_100s": pick[long]["t_med"],
                        "ratio": ratio, "nfev_1s": pick[short]["nfev"], "nfev_100s": pick[long]["nfev"],
                        "verdict": report.threshold_text(ratio, report.FLAT_TARGET, "x", higher_is_better=False)})
    return out


COLD = {
    "tswm simulate('paper-runup')": "from tswm_runtime.simulation.simulate import simulate; simulate('paper-runup')",
    "RK45 peer, run-up then load": ("from tswm_runtime.bench.peers import peer_run; "
                                    "peer_run('RK45', 1e-6, 1e-9, 200.0, [(0.0, 0.0), (0.3, -15000.0)], 0.0, 1.0)"),
}


def cold_start() -> list[dict]:
    """Seconds from the first import to the first result in a fresh process (interpreter
    start-up excluded): what a one-off script pays once."""
    out = []
    for name, code in COLD.items():
        prog = f"import time; t0 = time.perf_counter(); {code}; print(time.perf_counter() - t0)"
        run = subprocess.run([sys.executable, "-c", prog], capture_output=True, text=True, check=True)
        out.append({"call": name, "first_call_s": float(run.stdout.split()[-1])})
    return out


COLD_TARGET_S = 15.0     # with an empty cache, the first result within 15 s
EMPTY_CACHE = [  # (name, TSWM_COLD_START, command line after the interpreter, the output line that is the first result)
    ("tswm simulate paper", "background", ["-m", "tswm_runtime.cli", "simulate", "paper"], "status:"),
    ("tswm sweep paper (100 samples)", "background",
     ["-m", "tswm_runtime.cli", "sweep", "paper", "--samples", "100", "--range", "F2=-20000:5000", "--no-progress"],
     "cases in"),
    ("tswm simulate paper", "foreground", ["-m", "tswm_runtime.cli", "simulate", "paper"], "status:"),
]
WAIT_FOR_BACKGROUND = "from tswm_runtime.startup import warmup; warmup.wait()"


def _timed_run(argv, env, result_mark) -> dict:
    """Run ``argv``; seconds from its start to its first ``tswm:`` line on stderr, to its first
    stdout line holding ``result_mark``, and to its exit; the stderr lines."""
    import threading

    seen: dict = {}
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)

    def watch(stream, key, mark, lines):
        for line in stream:
            lines.append(line)
            if mark in line and key not in seen:
                seen[key] = time.perf_counter() - t0
    errors, results = [], []
    readers = [threading.Thread(target=watch, args=(proc.stderr, "message", "tswm: ", errors)),
               threading.Thread(target=watch, args=(proc.stdout, "result", result_mark, results))]
    for reader in readers:
        reader.start()
    code = proc.wait()
    for reader in readers:
        reader.join()
    return {"message_s": seen.get("message", math.nan), "first_result_s": seen.get("result", math.nan),
            "process_s": time.perf_counter() - t0, "exit": code, "stderr": errors}


def empty_cache(log=print, commands=None) -> list[dict]:
    """Each of ``commands`` (default EMPTY_CACHE) in a fresh process with a fresh, empty
    NUMBA_CACHE_DIR, as a first run on a new machine or in CI: seconds from starting the process to
    its message on stderr and to the first result line, against the targets (interpreter start-up
    included: that is what the user waits for). Then the same command again in the default mode,
    which finds what the first run compiled, or says what it does not find: after a forced compile
    (foreground) at once, after a background one when that has filled the cache."""
    import tempfile

    out = []
    for name, cold_start_mode, argv, result_mark in EMPTY_CACHE if commands is None else commands:
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, "TSWM_COLD_START": cold_start_mode}
            load = os.getloadavg()[0]
            t0 = time.perf_counter()
            first = _timed_run(argv, env, result_mark)
            compiled = None
            if cold_start_mode == "background":
                subprocess.run([sys.executable, "-c", WAIT_FOR_BACKGROUND], env=env, check=True)
                compiled = time.perf_counter() - t0
            again = _timed_run(argv, {**env, "TSWM_COLD_START": "background"}, result_mark)
        result = first["first_result_s"]
        row = {"command": name, "TSWM_COLD_START": cold_start_mode, "message_s": first["message_s"],
               "first_result_s": result, "over_target_s": max(result - COLD_TARGET_S, 0.0),
               "process_s": first["process_s"], "exit": first["exit"],
               "cache_filled_s": math.nan if compiled is None else compiled,
               "next_run_s": again["process_s"], "next_run_silent": not again["stderr"],
               "loadavg_1min_before": load,
               "message": first["stderr"][0].strip() if first["stderr"] else "",
               "message_verdict": ("none printed" if math.isnan(first["message_s"]) else report.threshold_text(
                   first["message_s"], MESSAGE_TARGET_S, "s", higher_is_better=False)),
               "result_verdict": report.threshold_text(result, COLD_TARGET_S, "s", higher_is_better=False)}
        log(f"empty cache, {name} ({cold_start_mode}): message after {row['message_s']:.2f} s, first result "
            f"after {result:.1f} s ({row['result_verdict']})"
            + (f"; cache filled after {compiled:.1f} s" if compiled else "")
            + f"; next run {row['next_run_s']:.2f} s, {'silent' if row['next_run_silent'] else 'not silent'}")
        out.append(row)
    return out


def machine(load_before, load_after) -> dict:
    import numba

    return {**provenance.machine(),
            **provenance.package_versions(("tswm", "numpy", "scipy", "numba", "mpmath", "scikit-sundae")),
            "numba_threads": numba.get_num_threads(), "numba_threading_layer": _threading_layer(),
            "loadavg_before": load_before, "loadavg_after": load_after}


def _threading_layer():
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel kernel has run
        return None


def _print(*args):
    print(*args, flush=True)


PARTS = ("fixed cost", "sweeps", "generate", "empty cache", "chain")  # beside the work-precision rounds
FORCED_COMPILE = [c for c in EMPTY_CACHE if c[1] == "foreground"]


def _part(record: list, name: str, measure, log, fatal: bool = False):
    """Run one part of the bench: its result (None if it failed: the error in ``record``, the bench goes
    on, unless ``fatal``); its seconds and the 1-minute load before and after in ``record``."""
    load, t0 = os.getloadavg()[0], time.perf_counter()
    log(f"== {name} (1-minute load {load:.1f})")
    done = {"part": name, "error": ""}
    try:
        out = measure()
    except Exception as error:  # noqa: BLE001 - a failing part is reported beside its targets, not fatal
        out, done["error"] = None, f"{type(error).__name__}: {error}"
        log(f"{name} failed: {done['error']}")
        if fatal:
            raise
    record.append(done | {"seconds": time.perf_counter() - t0, "load_before": load, "load_after": os.getloadavg()[0]})
    return out


def auto_comparisons(rows) -> list[dict]:
    """``report.versus_peers`` for method auto (the scene's own method where that is auto)."""
    from tswm_runtime.model.scenes import load_model

    def solvers(case):
        own = load_model(CASES[case].scene).RUN["method"]
        return {"auto": report.TSWM_SIMULATE if own == "auto" else "tswm simulate auto"}
    return report.versus_peers(rows, solvers)


def main(quick: bool = False, output: str | os.PathLike = "tswm-report/bench", cases: int | None = None,
         case_names=None, peers=None, tols=None, repeats: int | None = None, sweep_n: int | None = None,
         log=_print, skip=()) -> int:
    """Run the benchmark and write DIR/work-precision.md, targets.csv, runs.csv, verdicts.csv, bench.json,
    work-precision.png and one work-precision-CASE.png per case. The parts (PARTS; ``skip`` leaves
    some out, their targets then "not measured"): the work-precision rounds with the sweep throughput
    (``cases``: its grid) and the first calls; the fixed cost; ``tswm sweep`` as whole processes and
    against a vmapped diffrax batch; ``tswm generate`` of the shipped scenes and of schedules, and the
    schedule's events; the first run on an empty numba cache; the two-stage drive train. ``quick``:
    smaller counts of each; the other keywords narrow the work-precision part (tests)."""
    import pandas as pd

    from tswm_common.files import write_atomic
    from tswm_runtime.bench import targets

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    start, load_before, done = time.perf_counter(), os.getloadavg(), []
    chosen = [CASES[n] for n in (case_names or CASES)]
    peers = tuple(peers or available_methods())
    tols = tuple(tols or (TOLS_QUICK if quick else TOLS_FULL))
    repeats = repeats or (2 if quick else 5)
    sweep_n = sweep_n or (20 if quick else 100)
    if "CVODE" not in available_methods():
        log("scikit-sundae not importable: CVODE left out (pip install -e '.[bench]')")
    t0 = time.perf_counter()
    for case in chosen:
        reference(case)
    t_ref = time.perf_counter() - t0
    log(f"references for {plural(len(chosen), 'case')} in {t_ref:.1f} s; {plural(len(tols), 'tolerance')}, peers "
        f"{', '.join(peers)}, {plural(repeats, 'round')}")
    rows = _part(done, "work-precision", lambda: measure(configurations(chosen, tols, peers, sweep_n), repeats, log),
                 log, fatal=True)
    verdicts = report.speedup_verdicts(rows)
    thr = _part(done, "sweep() throughput", lambda: throughput(cases or (1000 if quick else 10_000), log=log), log,
                fatal=True)
    flat = flat_cost(rows)
    first_calls = _part(done, "first call in a fresh process", cold_start, log, fatal=True)
    parts = {"speedup": verdicts, "auto": auto_comparisons(rows)}
    _say(log, targets.speedup_rows(verdicts) + targets.auto_rows(parts["auto"]))
    for name, measure_part in _parts(quick, log).items():
        if name not in skip:
            parts[name] = _part(done, name, measure_part, log)
            _say(log, targets.ROWS[name](parts[name], "failed"))
    info = machine(load_before, os.getloadavg())
    if parts.get("sweeps") and "versions" in parts["sweeps"]["diffrax"]:
        info |= parts["sweeps"]["diffrax"]["versions"]
    why = {name: "left out of this run" for name in PARTS} | {
        p["part"]: f"failed: {p['error']}" for p in done if p["error"]}
    rows_of_targets = targets.all_rows(parts, why)
    write_atomic(out / "targets.csv", pd.DataFrame(rows_of_targets).to_csv(index=False))
    write_atomic(out / "runs.csv", pd.DataFrame(rows).to_csv(index=False))
    write_atomic(out / "verdicts.csv", pd.DataFrame(verdicts).to_csv(index=False))
    note = report.machine_note(info)
    report.plot(rows, out / "work-precision.png", note)
    plots = report.plot_per_case(rows, out, note)
    refs = [{"case": c.name, "scene": c.scene, "params": dict(c.params), "v1(0)": c.v0, "t_end": c.t_end,
             "m1": c.m1, "S1_max": reference(c).S1, "v1_end": reference(c).v_end, "x1_end": reference(c).x_end,
             "events": ", ".join(f"{k} {t:.12g}" for k, t in reference(c).events) or "none"} for c in chosen]
    generation, empty, ends = parts.get("generate") or {}, parts.get("empty cache"), parts.get("sweeps")
    details = {"fixed_cost": parts.get("fixed cost"), "auto": parts["auto"], "generate": generation.get("runs"),
               "events": generation.get("events"), "chain": _chain_table(parts.get("chain")), "parts": done,
               "plots": plots}
    md = _markdown(info, refs, t_ref, rows, verdicts, thr, flat, first_calls, empty, tols, repeats, sweep_n,
                   time.perf_counter() - start, ends, rows_of_targets, details)
    write_atomic(out / "work-precision.md", md)
    write_atomic(out / "bench.json", json.dumps({"machine": info, "targets": rows_of_targets, "references": refs,
                                                 "verdicts": verdicts, "throughput": thr, "flat_cost": flat,
                                                 "cold_start": first_calls, "empty_cache": empty,
                                                 "sweeps_end_to_end": ends, **details},
                                                indent=2, default=str))
    log(md[md.index("## Targets"):md.index("### simulate() with default output")])
    log(f"wrote {out / 'work-precision.md'}, targets.csv, runs.csv, verdicts.csv, bench.json, work-precision.png "
        f"and {plural(len(plots), 'plot')} per case")
    return 0


def _say(log, rows) -> None:
    """Target rows as log lines, as soon as their part has ended (a run stopped later has printed them)."""
    for r in rows:
        log(f"  {r['figure']}: {r['measured']} (target {r['target']}): {r['verdict']}")


def _parts(quick: bool, log) -> dict:
    """PARTS' measurements as calls, with ``quick``'s smaller counts."""
    from tswm_runtime.bench import chain, generation, sweeps, targets

    def sweeps_end_to_end():
        return {"processes": sweeps.processes(repeats=1 if quick else 3, log=log, fraction=0.1 if quick else 1.0),
                "diffrax": sweeps.versus_diffrax(cases=1000 if quick else 10_000, repeats=1 if quick else 3, log=log)}

    def generate():
        return {"runs": generation.generate_runs(scenes=generation.SLOWEST_SCENES if quick else None,
                                                 sizes=targets.SCHEDULE_BREAKPOINTS,
                                                 shapes=generation.SHAPES[:1] if quick else generation.SHAPES, log=log),
                "events": generation.event_runs(targets.SCHEDULE_BREAKPOINTS, log)}
    return {"fixed cost": lambda: [fixed_cost(CASES[n], 300 if quick else 2000) for n in targets.TARGET_CASES],
            "sweeps": sweeps_end_to_end, "generate": generate,
            "empty cache": lambda: empty_cache(log, FORCED_COMPILE if quick else None),
            "chain": lambda: chain.run(1 if quick else 3, chain.TOLS[::2] if quick else chain.TOLS, log)}


def _chain_table(result) -> list[dict] | None:
    """The chain part's runs as rows: solver, rtol, error, median seconds."""
    if result is None:
        return None
    return [{"solver": solver, "rtol": rtol, "err": err, "t_med": result["median_s"].get((solver, rtol), math.nan)}
            for (solver, rtol), err in result["errors"].items()]


def _end_to_end(log) -> dict:
    """``sweeps``: the whole ``tswm sweep`` processes and the diffrax comparison."""
    from tswm_runtime.bench import sweeps

    return {"processes": sweeps.processes(log=log), "diffrax": sweeps.versus_diffrax(log=log)}


def _end_to_end_markdown(ends) -> list[str]:
    from tswm_runtime.bench import sweeps

    head = "### Sweeps end to end: `tswm sweep` as whole processes, and against a vmapped diffrax batch"
    if ends is None:
        return [head, "", "not measured (left out of this run, or failed: see the parts)", ""]
    dx = ends["diffrax"]
    md = [head, "", f"Whole processes (warm numba cache, tables written with -o; targets: "
          f"{', '.join(f'{n} cases >= {t:g} cases/s' for n, t in sweeps.PROCESS_TARGETS.items())}, start-up "
          f"<= {sweeps.STARTUP_TARGET_S:g} s); wall from the parent, cpu of the process, the 1-minute load before "
          "each run:", "",
          report.md_table(ends["processes"], list(ends["processes"][0]),
                          {k: "{:.3f}" for k in ("wall_s_median", "wall_s_min", "wall_s_max", "cpu_s_median")}
                          | {"cases_per_s": "{:.0f}"}), ""]
    md += [f"tswm `sweep()` against the vmapped diffrax Dopri5 batch (`tswm_runtime/bench/diffrax_peer.py`; "
           f"target >= {sweeps.DIFFRAX_TARGET:g}x at equal accuracy; diffrax run {dx['diffrax']}). Largest errors "
           f"on {len(sweeps.ACCURACY_CASES)} cases against the quadrature reference: tswm at rtol "
           f"{dx['tswm_rtol']:g}: " + ", ".join(f"{k} {v:.2e}" for k, v in dx["tswm_errors"].items()), ""]
    if "diffrax_levels" not in dx:
        return md + [f"diffrax not measured: {dx['diffrax']}", ""]
    md += [report.md_table(dx["diffrax_levels"], ["rtol", "err_S1", "err_v1", "err_x1"],
                           {k: "{:.2e}" for k in ("err_S1", "err_v1", "err_x1")} | {"rtol": "{:.0e}"}), "",
           f"{dx['cases']} cases: tswm `sweep()` {dx['tswm_s_median']:.3f} s wall, {dx['tswm_cpu_s_median']:.3f} s CPU "
           f"on {dx['tswm_threads']} threads ({dx['tswm_cases_per_s']:.0f} cases/s), medians; diffrax (as jax runs "
           "it: the vmapped loop on one thread; CPU seconds to compare work):", "",
           report.md_table(dx["timings"], list(dx["timings"][0]),
                           {"diffrax_rtol": "{:.0e}", "diffrax_s_median": "{:.3f}", "diffrax_cpu_s_median": "{:.3f}",
                            "diffrax_cases_per_s": "{:.0f}",
                            "tswm_over_diffrax": "{:.2f}", "tswm_over_diffrax_cpu": "{:.2f}"}), "",
           "Versions: " + ", ".join(f"{k} {v}" for k, v in dx["versions"].items()) + "; load "
           + ", ".join(f"{x:.1f}" for x in dx["load_1min"]) + ".", ""]
    return md


def _details_markdown(details) -> list[str]:
    """The fixed cost, method auto, tswm generate and the chain, as measured (their targets' rows come first)."""
    us = {k: "{:.1f}" for k in ("whole_us", "cpu_us", "kernel_us", "fixed_us", "fixed_p90_us")}
    seconds = {k: "{:.3e}" for k in ("auto_s", "peer_s", "t_med")} | {"error": "{:.0e}", "rtol": "{:.0e}",
                                                                     "err": "{:.2e}"}
    md = ["### The fixed cost of a simulate() call", ""]
    md += [("Back-to-back whole calls to t_end = "
            f"{FIXED_COST_T_END:g} s (one step) that read the status, the maxima and the final state, a new m2 on "
            "every call; the kernel timed where simulate() calls it; fixed = whole - kernel, medians (us):\n\n"
            + report.md_table(details["fixed_cost"], list(details["fixed_cost"][0]), us))
           if details["fixed_cost"] else "not measured", ""]
    md += ["### Method auto against the fastest peer at equal error, every case", "",
           report.md_table(details["auto"], list(details["auto"][0]), seconds) if details["auto"] else "no rows", ""]
    md += ["### `tswm generate` from empty caches, and a schedule's events", ""]
    if details["generate"]:
        md += ["A fresh process each, writing no bytecode, no stored derivation (`tswm_runtime/bench/generation.py`):",
               "", report.md_table(details["generate"], list(details["generate"][0]),
                                   {"wall_s": "{:.2f}", "cpu_s": "{:.2f}", "load_1min": "{:.1f}"}), ""]
    if details["events"]:
        md += ["A frictionless wedge whose drive steps N times in 1 s (compiled, warm, best of 3 runs), and one call "
               "of its guards() from compiled code:", "",
               report.md_table(details["events"], list(details["events"][0]),
                               {"run_s": "{:.4f}", "events_per_s": "{:.0f}", "guards_call_s": "{:.3e}",
                                "load_1min": "{:.1f}"}), ""]
    md += ["### Two-stage drive train (`tswm_runtime/bench/chain.py`): errors against the DOP853 reference at rtol "
           "1e-13, median seconds of whole calls", "",
           report.md_table(details["chain"], list(details["chain"][0]), seconds) if details["chain"] else
           "not measured", ""]
    return md


def _markdown(info, refs, t_ref, rows, verdicts, thr, flat, cold, empty, tols, repeats, sweep_n, total,
              ends, rows_of_targets, details) -> str:
    fmt = {"rtol": "{:.0e}", "atol": "{:.0e}"} | {k: "{:.2e}" for k in ("err_S1", "err_v1", "err_x1", "err_t", "err")} \
        | {k: "{:.3e}" for k in ("t_med", "t_min", "t_max")}
    vfmt = {"error": "{:.0e}", "tswm_s": "{:.3e}", "peer_s": "{:.3e}", "target_allows_s": "{:.3e}",
            "fixed_cost_s": "{:.3e}"}
    without_floor = [k for k in verdicts[0] if k not in ("target_allows_s", "fixed_cost_s", "floor")]
    n_met = sum(v["verdict"].startswith("met") for v in verdicts)
    md = ["# tswm work-precision benchmark", "",
          "Machine: " + ", ".join(f"{k} {v}" for k, v in info.items()), "",
          "## How it was measured", "",
          f"Every call timed whole in this process, with new parameters (m2 changed by k x 2^-52 relative on "
          f"the k-th call, new to every cache, the same problem to 1e-11): `simulate()` with its default output "
          f"(1001 points) and the scene's method, with each other method (`tswm simulate rosenbrock23`), and "
          f"with `points=2`; `sweep()` over {sweep_n} identical cases on all cores, divided by "
          f"{sweep_n} (not comparable with one-thread calls: it uses {info['numba_threads']} threads); "
          f"peers as a careful user writes them (`tswm_runtime/bench/peers.py`: span split at load times, "
          f"directed terminal events, restart with the new flank, phi event armed only where phi can "
          f"vanish). One untimed warm-up call per configuration, then {plural(repeats, 'round')} over all "
          f"configurations, each in its own shuffled order (seeded; no configuration always follows the same "
          f"one, so none always finds the caches warm from a relative); median (min, max) seconds per call. Tolerances "
          f"{', '.join(f'{t:g}' for t in tols)}; atol = rtol x {ATOL_PER_RTOL:g} for every solver.", "",
          "Errors against the independent quadrature reference (`tswm_runtime/reference/quadrature.py`, 34 "
          f"digits, {t_ref:.1f} s for all cases): err_S1 relative error of max |S1|; err_v1 error of "
          "v1(t_end) relative to max(|v1_ref|, 1 m/s); err_x1 relative error of x1(t_end) (it integrates the "
          "whole transient, while max |S1| and v1(t_end) can sit on equilibria that implicit methods hit to "
          "rounding); err_t largest absolute error of the event times [s] (inf: other events than the "
          "reference's; NaN: the sweep reports no event times); err the largest of them.", "",
          report.md_table(refs, list(refs[0]), {"S1_max": "{:.12g}", "v1_end": "{:.12g}", "x1_end": "{:.12g}"}), "",
          "## Targets (reported, not asserted)", "",
          f"### Every figure beside its target: {sum(r['verdict'] == 'met' for r in rows_of_targets)} met, "
          f"{sum(r['verdict'] == 'missed' for r in rows_of_targets)} missed, "
          f"{sum(r['verdict'] == 'not measured' for r in rows_of_targets)} not measured", "",
          "For a miss, `remaining` is the measured cost that stands between the figure and its target.", "",
          report.md_table(rows_of_targets, ["item", "figure", "measured", "target", "verdict", "remaining"]), "",
          "The parts of this run, with the 1-minute load before and after each:", "",
          report.md_table(details["parts"], ["part", "seconds", "load_before", "load_after", "error"],
                          {"seconds": "{:.1f}", "load_before": "{:.1f}", "load_after": "{:.1f}"}), "",
          f"### simulate() with default output vs the fastest peer at equal error: {n_met} of "
          f"{len(verdicts)} met", "",
          "Time to reach the error: log-log interpolation on each solver's work-precision front "
          "(`bench_report.cost_at`), never extrapolated.", "",
          report.md_table(verdicts, list(verdicts[0]), vfmt), "",
          f"The target is {report.SPEEDUP_TARGET:g}x, the long-term goal {report.SPEEDUP_GOAL:g}x. "
          f"target_allows_s is the fastest peer's time over {report.SPEEDUP_TARGET:g}; fixed_cost_s the median "
          f"of the case's `simulate()` call (its scene, parameters, v1(0), default output) run to t_end = "
          f"{FIXED_COST_T_END:g} s at rtol {THROUGHPUT_RTOL:g} (`bench_cases.run_fixed_cost`, in the same shuffled "
          "rounds, shown for both error levels): input checks, one step and the Result (its rows are not read), no "
          "integration. Where it exceeds target_allows_s, no integrator, however fast, meets the target in "
          "this protocol (each call finds the caches as the configuration before it in the shuffled order "
          "left them).", "",
          "For information, the same with `simulate(..., points=2)` (not the target's configuration):", "",
          report.md_table(report.speedup_verdicts(rows, tswm="tswm simulate points=2"), without_floor, vfmt),
          "", f"### Sweep throughput at rtol {THROUGHPUT_RTOL:g} (target {report.SWEEP_TARGET:g} cases/s)", "",
          report.md_table([thr], list(thr), {"cases_per_s": "{:.0f}", "s_median": "{:.3f}", "s_min": "{:.3f}",
                                            "s_max": "{:.3f}"}), "",
          *_end_to_end_markdown(ends),
          *_details_markdown(details),
          f"### Cost on an equilibrium tail: T = 100 s over T = 1 s (target ratio <= {report.FLAT_TARGET:g})", "",
          report.md_table(flat, list(flat[0])) if flat else "not measured (needs both run-up cases at rtol 1e-6)", "",
          "### First call in a fresh process (imports, numba cache, first result)", "",
          report.md_table(cold, list(cold[0])), "",
          f"### First run with an empty numba cache (targets: a message within {MESSAGE_TARGET_S:g} s, "
          f"the first result within {COLD_TARGET_S:g} s)", "",
          ("Each command in a fresh process with a fresh, empty NUMBA_CACHE_DIR; seconds from the "
           "process start (interpreter start-up included) to its message on stderr and to the first "
           "result line; one run each. TSWM_COLD_START=background (the default): the command runs "
           "interpreted while a background process compiles the kernels; cache_filled_s is when that "
           "compile has finished (from the command's start), next_run_s the same command run again "
           "then. foreground: compile first, then run.\n\n"
           + report.md_table([{k: v for k, v in r.items() if k != "message"} for r in empty],
                             [k for k in empty[0] if k != "message"],
                             {"message_s": "{:.2f}", "first_result_s": "{:.1f}", "over_target_s": "{:.1f}",
                              "process_s": "{:.1f}", "cache_filled_s": "{:.1f}", "next_run_s": "{:.2f}"})
           + "\n\nThe messages: " + "; ".join(f"`` {r['message']} `` ({mode})" for mode, r in
                                                {r["TSWM_COLD_START"]: r for r in reversed(empty)}.items())) if empty
          else "not measured (--quick; the full bench measures it)", "",
          "## All runs", "",
          report.md_table(rows, ["case", "solver", "rtol", "err_S1", "err_v1", "err_x1", "err_t", "err", "t_med",
                                 "t_min", "t_max", "events", "nfev", "status"], fmt), "",
          "Plot: work-precision.png (error vs median time per call, log-log, one panel per case, one curve per "
          "tswm method and per peer; its title names the machine and the load), and one per case: "
          + ", ".join(details["plots"]) + ".",
          f"Total bench time {total:.1f} s."]
    return "\n".join(md) + "\n"
