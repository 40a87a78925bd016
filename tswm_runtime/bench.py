"""Work-precision benchmark: tswm against scipy's solve_ivp and SUNDIALS CVODE.

For each scene: a reference (tswm dopri5 at rtol 1e-12 with its exactly located
switches), checked against a second method (DOP853 at rtol 1e-12 on hand-written
formulas, the peer runner below); then every integrator at several tolerances, with
errors

    err_S   relative error of the largest |S1| (value at its maximum)
    err_v   relative error of v1 at t_end
    err_t   absolute error of the first event time (n/a when the scene has none)

and the median wall time per scene. tswm's time is the in-numba batch call per case
(N identical cases in one batch, one thread, divided by N), so that Python's call
overhead (~115 us per call for the function-typed arguments) is not what is measured;
the simulate() time (validation, 1001 output points, Result) is reported beside it.

The peer runner is written as a user would: the forward-sliding ODE from hand
formulas (``paper_gear``), solve_ivp with terminal
events for phi = 0 (flank switch) and v1 = 0 (rest), restarted after each event;
at rest a stick test with the static friction cone; a known load step splits the
time span. max |S1| is taken over the accepted steps and refined on the dense
output around the largest one.

Run: ``tswm bench [--quick] [-o DIR]`` or ``python tools/bench_work_precision.py``.
"""
from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from tswm_runtime import provenance
from tswm_runtime.paper_gear import GAMMA, accel, cones, kloss, phi, reactions, rho


def S1(v, flank, F2, m2):
    return reactions(v, flank, F2, m2)[0]


def sticks(F2):
    """At rest against F2: inside the forward static friction cone."""
    return cones(kloss(0.0), F2, GAMMA, rho(0.0))[0] >= 0.0


MAX_PEER_EVENTS = 100  # restarts after which a peer run is given up (spurious phi crossings)


class PeerGaveUp(RuntimeError):
    """More than MAX_PEER_EVENTS events: the peer chatters on spurious crossings."""


def peer_run(method, rtol, atol, m2, loads, v0, t_end=1.0, phi_events=True):
    """A user's solve_ivp (or CVODE) run. loads: [(t_from, F2), ...] piecewise-constant F2.
    Returns (S1 max (signed), v1(t_end), first event time or nan, events, rhs calls).
    phi_events=False drops the flank-switch event (for the reference check only, where
    phi > 0 provably: F2 <= 0 below V0)."""
    from scipy.integrate import solve_ivp

    best, first, n_events, nfev = (0.0, 0.0), math.nan, 0, 0
    t, v, flank, stuck = 0.0, v0, 0, False
    bounds = [tf for tf, _ in loads[1:]] + [t_end]
    for (t_from, F2), t_to in zip(loads, bounds):
        if t_from > 0.0:  # the load step: a known time, the user splits the span there
            first = t_from if math.isnan(first) else first
            n_events += 1
        t = t_from
        stuck = stuck and v == 0.0 and sticks(F2)
        while t < t_to:
            if v == 0.0:
                if sticks(F2):
                    stuck = True
                    s1 = kloss(0.0)
                    best = max(best, (abs(s1), s1))
                    break
            flank = 1 if phi(v, F2, m2) > 0 else -1
            f = flank

            def rhs(_t, y, f=f, F2=F2):
                return [accel(y[0], f, F2, m2)]

            def ev_phi(_t, y, F2=F2):
                return phi(y[0], F2, m2)

            def ev_v(_t, y):
                return y[0]
            ev_phi.terminal = ev_v.terminal = True
            if not phi_events:
                def ev_phi(_t, y):  # never fires
                    return 1.0
                ev_phi.terminal = True
            ev_v.direction = -1
            ev_phi.direction = -1 if flank > 0 else 1
            if method == "CVODE":
                from sksundae.cvode import CVODE

                frhs, fev = _cvode_functions(f, F2, m2)
                fev.terminal = [True, True]
                fev.direction = [ev_phi.direction, -1]
                sol = CVODE(frhs, rtol=rtol, atol=atol, method="BDF", eventsfn=fev, num_events=2,
                            max_num_steps=1_000_000).solve([t, t_to], [v])
                ts, vs = np.asarray(sol.t), np.asarray(sol.y)[:, 0]
                nfev += int(sol.nfev)
                hit = sol.status == 2 and len(sol.t_events) > 0
                t_hit = float(sol.t_events[0]) if hit else None
                which = int(np.argmax(np.abs(np.asarray(sol.i_events)[0]))) if hit else -1
                dense = None
            else:
                sol = solve_ivp(rhs, (t, t_to), [v], method=method, rtol=rtol, atol=atol,
                                events=[ev_phi, ev_v], dense_output=True)
                ts, vs = sol.t, sol.y[0]
                nfev += sol.nfev
                hit = sol.status == 1
                which = 0 if hit and len(sol.t_events[0]) else 1
                t_hit = float(sol.t_events[which][0]) if hit else None
                dense = sol.sol
            vals = [abs(S1(x, flank, F2, m2)) for x in vs]
            k = int(np.argmax(vals))
            cand = [(vals[k], S1(vs[k], flank, F2, m2))]
            if dense is not None and ts.size > 2:  # refine on the dense output around the max
                lo, hi = ts[max(k - 1, 0)], ts[min(k + 1, ts.size - 1)]
                for tt in np.linspace(lo, hi, 21):
                    s = S1(float(dense(tt)[0]), flank, F2, m2)
                    cand.append((abs(s), s))
            best = max([best, *cand])
            if not hit:
                t, v = t_to, float(vs[-1])
                break
            n_events += 1
            if n_events > MAX_PEER_EVENTS:
                raise PeerGaveUp(f"more than {MAX_PEER_EVENTS} events by t = {t_hit:.9g} s "
                                 f"(spurious phi crossings)")
            first = t_hit if math.isnan(first) else first
            t = t_hit
            v = 0.0 if which == 1 else float(vs[-1])
            if which == 1 and sticks(F2):
                stuck = True
                break
        if stuck:
            v = 0.0
    return best[1], v, first, n_events, nfev


def _cvode_functions(flank, F2, m2):
    """rhs and events for CVODE (which counts arguments: no defaults allowed)."""
    def frhs(_t, y, yp):
        yp[0] = accel(y[0], flank, F2, m2)

    def fev(_t, y, e):
        e[0] = phi(y[0], F2, m2)
        e[1] = y[0]
    return frhs, fev


# ---------------------------------------------------------------- scenes
# name: (tswm scene, params, v1(0), peer args (m2, loads, v0), has a meaningful first event)
SCENES = {
    "paper-runup": ("paper-runup", {}, 0.0, (200.0, [(0.0, 0.0), (0.3, -15000.0)], 0.0)),
    "no-load run-up": ("paper", {"F2": 0.0}, 0.0, (200.0, [(0.0, 0.0)], 0.0)),
    "breakaway F2=-1000": ("paper", {"F2": -1000.0}, 0.0, (200.0, [(0.0, -1000.0)], 0.0)),
    "decelerate-and-stick": ("paper", {"F2": -15000.0}, 2.0, (200.0, [(0.0, -15000.0)], 2.0)),
}
PEERS = ("RK45", "DOP853", "Radau", "BDF", "LSODA", "CVODE")


def _tswm_case(scene, params, v1, rtol, method, n_cases, threads=1):
    """(S1max, v1 end, first event t, seconds per case in the batch, simulate() seconds, nfev)."""
    import numba

    from tswm_runtime.contract import load_module
    from tswm_runtime.simulate import settings, simulate
    from tswm_runtime.sweep import run_cases

    module = load_module(scene)
    p = dict(zip(module.PARAM_NAMES, module.PARAM_DEFAULTS)) | params
    overrides = dict(rtol=rtol, atol=rtol * 1e-3, v1=v1, method=method, max_steps=10_000_000)
    r = simulate(module, p, **overrides)
    first = r.events[0].t if r.events else math.nan
    sim_times = []
    for _ in range(3):
        t0 = time.perf_counter()
        simulate(module, p, **overrides)
        sim_times.append(time.perf_counter() - t0)
    run = settings(module, overrides)
    P = np.tile(np.array([p[k] for k in module.PARAM_NAMES]), (n_cases, 1))
    old = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        run_cases(module, P[:1], run)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            run_cases(module, P, run)
            times.append((time.perf_counter() - t0) / n_cases)
    finally:
        numba.set_num_threads(old)
    return r.S1_max, float(r.v1[-1]), first, statistics.median(times), statistics.median(sim_times), r.nfev, r


def _errors(S, v, t_first, ref):
    eS = abs(S - ref["S"]) / abs(ref["S"])
    ev = abs(v - ref["v"]) / max(abs(ref["v"]), 1e-300) if ref["v"] != 0 else abs(v)
    et = abs(t_first - ref["t"]) if not math.isnan(ref["t"]) else (math.nan if math.isnan(t_first) else math.inf)
    return eS, ev, et


def _peer_time(method, rtol, args, repeats):
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = peer_run(method, rtol, rtol * 1e-3, *args)
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def machine() -> dict:
    """The machine, the versions of the packages measured, numba's threading layer (set later)."""
    return {**provenance.machine(), **provenance.package_versions(("numpy", "scipy", "numba", "scikit-sundae")),
            "numba_threading_layer": None}


def work_precision(scenes, tswm_tols, peer_tols, peers, n_cases, repeats, log=print):
    rows, checks = [], []
    for name in scenes:
        scene, params, v1, peer_args = SCENES[name]
        S, v, t1, *_ = _tswm_case(scene, params, v1, 1e-12, "dopri5", 1)
        ref = {"S": S, "v": v, "t": t1}
        no_switch = all(F2 <= 0.0 for _, F2 in peer_args[1])
        S2, v2, t2, _, _ = peer_run("DOP853", 1e-12, 1e-14, *peer_args, phi_events=not no_switch)
        check = {"scene": name, "S1max": S, "v1_end": v, "t_first": t1,
                 "DOP853_S1max_rel": abs(S2 - S) / abs(S), "DOP853_v1_rel": abs(v2 - v) / max(abs(v), 1e-300)
                 if v else abs(v2), "DOP853_t_first_abs": abs(t2 - t1) if not math.isnan(t1) else math.nan}
        checks.append(check)
        log(f"reference {name}: S1max {S:.10g}, v1 {v:.10g}, t_first {t1:.10g}; DOP853 hand formulas "
            f"differ by {check['DOP853_S1max_rel']:.2e}, {check['DOP853_v1_rel']:.2e}, {check['DOP853_t_first_abs']:.2e}")
        for method in ("dopri5", "rosenbrock23"):
            for rtol in tswm_tols[method]:
                S_, v_, t_, per_case, t_sim, nfev, r = _tswm_case(scene, params, v1, rtol, method, n_cases)
                eS, ev, et = _errors(S_, v_, t_, ref)
                rows.append(dict(scene=name, solver=f"tswm {method}", rtol=rtol, time_s=per_case,
                                 simulate_s=t_sim, err_S1max=eS, err_v1=ev, err_t_first=et,
                                 events=len(r.events), nfev=nfev, status=r.status))
        for method in peers:
            for rtol in peer_tols:
                try:
                    (S_, v_, t_, n_ev, nfev), dt = _peer_time(method, rtol, peer_args, repeats)
                except Exception as error:  # noqa: BLE001 - a failing peer is reported, not fatal
                    log(f"  {method} rtol {rtol:g} on {name} failed: {error}")
                    rows.append(dict(scene=name, solver=method, rtol=rtol, time_s=math.nan,
                                     simulate_s=math.nan, err_S1max=math.nan, err_v1=math.nan,
                                     err_t_first=math.nan, events=-1, nfev=-1,
                                     status=f"failed: {error}"))
                    continue
                eS, ev, et = _errors(S_, v_, t_, ref)
                rows.append(dict(scene=name, solver=method, rtol=rtol, time_s=dt, simulate_s=math.nan,
                                 err_S1max=eS, err_v1=ev, err_t_first=et, events=n_ev, nfev=nfev,
                                 status="finished"))
            log(f"  {name}: {method} done")
    return rows, checks


def speedups(rows, levels=(1e-3, 1e-5, 1e-7)):
    """Per scene and error level: the fastest tswm run and the fastest peer run whose
    combined error (max of err_S1max, err_v1, err_t_first) is at or below the level."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for level in levels:
            def fastest(pred):
                ok = [r for r in rows if r["scene"] == scene and pred(r) and _combined(r) <= level]
                return min(ok, key=lambda r: r["time_s"]) if ok else None
            a = fastest(lambda r: r["solver"].startswith("tswm"))
            b = fastest(lambda r: not r["solver"].startswith("tswm"))
            out.append(dict(scene=scene, error_level=level, tswm=a and f"{a['solver']} rtol {a['rtol']:g}",
                            tswm_s=a and a["time_s"], peer=b and f"{b['solver']} rtol {b['rtol']:g}",
                            peer_s=b and b["time_s"], speedup=(b["time_s"] / a["time_s"]) if a and b else None))
    return out


def _combined(r):
    errs = [e for e in (r["err_S1max"], r["err_v1"], r["err_t_first"]) if not math.isnan(e)]
    return max(errs) if errs else math.inf


def throughput(n_cases, peer_method="RK45", peer_cases=40, log=print):
    """Cases per second of a paper-runup sweep (grid m2 x F2_after) at rtol 1e-6 on all
    cores, warm and cold (a fresh process), against a plain loop over solve_ivp."""
    import numba

    from tswm_runtime.contract import load_module
    from tswm_runtime.simulate import settings
    from tswm_runtime.sweep import grid_cases, run_cases

    module = load_module("paper-runup")
    nm = max(int(round(math.sqrt(n_cases / 1.6))), 1)
    nf = max(n_cases // nm, 1)
    P = grid_cases(module, {"m2": np.linspace(100.0, 400.0, nm), "F2_after": np.linspace(-20000.0, 5000.0, nf)})
    run = settings(module, {"rtol": 1e-6, "atol": 1e-9})
    run_cases(module, P[:2], run)
    t0 = time.perf_counter()
    table = run_cases(module, P, run)
    warm = time.perf_counter() - t0
    numba.set_num_threads(1)
    t0 = time.perf_counter()
    run_cases(module, P, run)
    single = time.perf_counter() - t0
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    code = ("import time, numpy as np; t0 = time.perf_counter(); from tswm_runtime.contract import load_module; "
            "from tswm_runtime.simulate import settings; from tswm_runtime.sweep import grid_cases, run_cases; "
            f"m = load_module('paper-runup'); P = grid_cases(m, {{'m2': np.linspace(100.0, 400.0, {nm}), "
            f"'F2_after': np.linspace(-20000.0, 5000.0, {nf})}}); "
            "t1 = time.perf_counter(); run_cases(m, P, settings(m, {'rtol': 1e-6, 'atol': 1e-9})); "
            "print(time.perf_counter() - t0, time.perf_counter() - t1)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    cold_total, cold_first = map(float, out.stdout.split())
    sub = P[np.linspace(0, len(P) - 1, min(peer_cases, len(P))).astype(int)]
    t0 = time.perf_counter()
    peer_failed = 0
    for m2, F2a, t_step in sub:  # LSODA, BDF, DOP853 give up here on spurious phi crossings
        try:
            peer_run(peer_method, 1e-6, 1e-9, m2, [(0.0, 0.0), (t_step, F2a)], 0.0)
        except PeerGaveUp:
            peer_failed += 1
    peer = (time.perf_counter() - t0) / len(sub)
    steps = table["steps"] + table["rejected"]
    result = dict(cases=len(P), grid=f"m2 {nm} x F2_after {nf}", warm_s=warm, warm_cases_per_s=len(P) / warm,
                  single_thread_cases_per_s=len(P) / single, cold_process_s=cold_total,
                  cold_first_batch_s=cold_first, peer=f"{peer_method} loop ({len(sub)} cases, {peer_failed} gave up)", peer_cases_per_s=1 / peer,
                  speedup=peer / (warm / len(P)), mean_rhs_calls=float(table["nfev"].mean()),
                  mean_step_attempts=float(steps.mean()),
                  ns_per_rhs_call_single_thread=single / table["nfev"].sum() * 1e9,
                  statuses=table["status"].value_counts().to_dict(),
                  threads=numba.config.NUMBA_NUM_THREADS)
    log(f"sweep throughput: {result['warm_cases_per_s']:.0f} cases/s warm on {result['threads']} threads "
        f"({result['single_thread_cases_per_s']:.0f} on 1), cold process {cold_total:.2f} s; "
        f"{peer_method} loop {result['peer_cases_per_s']:.1f} cases/s")
    return result


def _plots(rows, out: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
        for ax, key, label in zip(axes, ("err_S1max", "err_v1", "err_t_first"),
                                  ("rel. error of max |S1|", "rel. error of v1(t_end)", "abs. error of first event time [s]")):
            for solver in dict.fromkeys(r["solver"] for r in rows):
                pts = [(r["time_s"], max(r[key], 1e-17)) for r in rows if r["scene"] == scene
                       and r["solver"] == solver and np.isfinite(r[key])]
                if pts:
                    x, y = zip(*pts)
                    ax.loglog(x, y, "o-" if solver.startswith("tswm") else ".--", label=solver)
            ax.set_xlabel("wall time per scene [s]")
            ax.set_ylabel(label)
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"work-precision: {scene}")
        fig.tight_layout()
        path = out / f"work-precision-{scene.replace(' ', '_').replace('=', '')}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


def _md_table(rows, keys, fmt=None):
    fmt = fmt or {}
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        cells = []
        for k in keys:
            v = r.get(k)
            cells.append(fmt.get(k, "{:.3g}").format(v) if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _print(*args):
    print(*args, flush=True)


def main(quick: bool = False, output: str | os.PathLike = "tswm-report/bench", cases: int = 1000,
         log=_print) -> int:
    import pandas as pd

    from tswm_runtime.files import write_atomic

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    if quick:
        scenes, peers = ["decelerate-and-stick"], ("RK45",)
        tswm_tols = {"dopri5": (1e-4, 1e-8), "rosenbrock23": ()}
        peer_tols, n_cases, repeats = (1e-4, 1e-8), 20, 1
    else:
        scenes, peers = list(SCENES), PEERS
        tswm_tols = {"dopri5": (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11),
                     "rosenbrock23": (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)}
        peer_tols, n_cases, repeats = (1e-3, 1e-4, 1e-6, 1e-8, 1e-10), 200, 3
        import importlib.util

        if importlib.util.find_spec("sksundae") is None:
            peers = tuple(p for p in peers if p != "CVODE")
            log("scikit-sundae not installed: CVODE left out (pip install -e '.[bench]')")
    rows, checks = work_precision(scenes, tswm_tols, peer_tols, peers, n_cases, repeats, log)
    speed = speedups(rows)
    thr = None if quick else throughput(cases, log=log)
    info = machine()
    import numba
    info["numba_threading_layer"] = numba.threading_layer() if thr else None
    table = pd.DataFrame(rows)
    write_atomic(out / "work-precision.csv", table.to_csv(index=False))
    write_atomic(out / "speedups.csv", pd.DataFrame(speed).to_csv(index=False))
    plots = [] if quick else _plots(rows, out)
    md = ["# tswm work-precision benchmark", "",
          "Machine and versions: " + ", ".join(f"{k} {v}" for k, v in info.items()), "",
          "Errors against tswm dopri5 at rtol 1e-12 (atol 1e-15) with located switches; the reference "
          "checked against DOP853 rtol 1e-12 on hand formulas:", "",
          _md_table(checks, list(checks[0]), {"S1max": "{:.10g}", "v1_end": "{:.10g}", "t_first": "{:.10g}"}), "",
          "tswm time_s: in-numba batch per case on one thread (N identical cases / N); simulate_s: "
          "one simulate() call from Python (1001 output points). Peers: solve_ivp / CVODE with events "
          "and restarts on hand formulas, median of repeats. atol = rtol * 1e-3 throughout.", "",
          "## Fastest run at or below each combined error level (max of the three errors)", "",
          _md_table(speed, list(speed[0]) if speed else []), "",
          "## All runs", "",
          _md_table(rows, ["scene", "solver", "rtol", "time_s", "simulate_s", "err_S1max", "err_v1",
                           "err_t_first", "events", "nfev", "status"]), ""]
    if thr:
        md += ["## Sweep throughput (paper-runup, rtol 1e-6, t_end 1 s)", "",
               _md_table([thr], list(thr)), ""]
    md += [f"Plots: {', '.join(p.name for p in plots) or 'none (--quick)'}",
           f"Total bench time {time.perf_counter() - start:.1f} s"]
    write_atomic(out / "work-precision.md", "\n".join(md) + "\n")
    write_atomic(out / "bench.json", json.dumps({"machine": info, "reference_checks": checks,
                                                 "speedups": speed, "throughput": thr}, indent=2, default=str))
    log("\n".join(md[md.index("## Fastest run at or below each combined error level (max of the three errors)"):
                     md.index("## All runs")]))
    if thr:
        log(_md_table([thr], list(thr)))
    log(f"wrote {out / 'work-precision.md'}, work-precision.csv, speedups.csv, bench.json"
        + (f" and {len(plots)} plots" if plots else ""))
    return 0
