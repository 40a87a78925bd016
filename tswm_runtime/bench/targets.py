"""Every speed figure of the bench beside its target: one row each (item, figure, measured, target,
verdict, what remains for a miss), built from the parts' results; a part that was not run gives its
rows with the verdict "not measured".

Items: 1 the fixed cost of a simulate() call and the factor over the fastest careful peer at equal
error; 2 method auto against the fastest peer on every bench case; 3 ``tswm sweep`` as whole
processes and against a vmapped diffrax batch; 4 ``tswm generate``: shipped scenes, a 999-breakpoint
schedule, the cost of its events; 5 the first run on an empty cache; 6 the two-stage drive train.
"""
from __future__ import annotations

import math

from tswm_runtime.bench import report
from tswm_runtime.common.words import plural

FIXED_COST_TARGET_US = 60.0
TARGET_CASES = ("run-up then load", "decelerate-and-stick", "stiff drive m1=0.05")
GENERATE_TARGET_S = 5.0
SCHEDULE_TARGET_S = 30.0
SCHEDULE_BREAKPOINTS = (3, 999)
EVENT_COST_SAME = 1.25  # a 999-breakpoint schedule's guards() call at most this over a 3-breakpoint one's
MESSAGE_TARGET_S = 1.0
CHAIN_TARGET = 20.0
MET, MISSED, NOT_MEASURED = "met", "missed", "not measured"


def row(item: str, figure: str, target: str, measured: str | None, met: bool = False,
        remaining: str = "") -> dict:
    """One row; ``measured`` None: not measured (``remaining`` says why)."""
    verdict = NOT_MEASURED if measured is None else (MET if met else MISSED)
    return {"item": item, "figure": figure, "measured": measured or "", "target": target, "verdict": verdict,
            "remaining": "" if verdict == MET else remaining}


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.4g} us"


def fixed_cost_rows(fixed: list[dict] | None, why: str = "") -> list[dict]:
    """Item 1: the fixed cost (whole call - kernel) of each target case's simulate() call."""
    target = f"<= {FIXED_COST_TARGET_US:g} us"
    if not fixed:
        return [row("1", f"fixed cost of simulate(), {c}", target, None, remaining=why) for c in TARGET_CASES]
    out = []
    for f in fixed:
        measured = (f"{f['fixed_us']:.4g} us (whole call {f['whole_us']:.4g} us, kernel {f['kernel_us']:.4g} us, "
                    f"{plural(f['steps'], 'step')}, median of {f['calls']} calls; 90th percentile {f['fixed_p90_us']:.4g} us)")
        out.append(row("1", f"fixed cost of simulate() reading status, maxima, final state: {f['case']}", target,
                       measured, f["fixed_us"] <= FIXED_COST_TARGET_US,
                       f"{f['fixed_us'] - FIXED_COST_TARGET_US:.3g} us of Python around the kernel over the target"))
    return out


def speedup_rows(verdicts: list[dict] | None, why: str = "") -> list[dict]:
    """Item 1: simulate() (default output) against the fastest peer at equal error on the target cases."""
    target = f">= {report.SPEEDUP_TARGET:g}x the fastest peer (long-term {report.SPEEDUP_GOAL:g}x)"
    if not verdicts:
        return [row("1", f"simulate() vs fastest peer at error {level:g}, {c}", target, None, remaining=why)
                for c in TARGET_CASES for level in report.SPEEDUP_LEVELS]
    out = []
    for v in (v for v in verdicts if v["case"] in TARGET_CASES):
        figure = f"simulate() vs fastest peer at error {v['error']:g}, {v['case']}"
        if math.isnan(v["factor"]):
            out.append(row("1", figure, target, v["verdict"], False, "no factor: " + v["verdict"]))
            continue
        goal = "; goal met" if v["factor"] >= report.SPEEDUP_GOAL else ""
        measured = f"{v['factor']:.3g}x (tswm {_us(v['tswm_s'])}, {v['fastest_peer']} {_us(v['peer_s'])}{goal})"
        remaining = (f"a call must take {_us(v['target_allows_s'])}, takes {_us(v['tswm_s'])}: "
                     f"{_us(v['tswm_s'] - v['target_allows_s'])} to lose; {v['floor']}")
        out.append(row("1", figure, target, measured, v["factor"] >= report.SPEEDUP_TARGET, remaining))
    return out


def auto_rows(comparisons: list[dict] | None, why: str = "") -> list[dict]:
    """Item 2: method auto's time at equal error against the fastest peer's, every case and level
    (``report.versus_peers`` rows with an ``auto_s``)."""
    target = "<= the fastest peer's time"
    if not comparisons:
        return [row("2", "method auto vs fastest peer, every bench case", target, None, remaining=why)]
    out = []
    for c in comparisons:
        figure = f"method auto vs fastest peer at error {c['error']:g}, {c['case']}"
        auto, peer = c["auto_s"], c["peer_s"]
        if math.isnan(peer):
            out.append(row("2", figure, target, f"auto {_us(auto)}; no peer reaches this error", True))
        elif math.isnan(auto):
            out.append(row("2", figure, target, f"auto does not reach this error; {c['fastest_peer']} {_us(peer)}",
                           False, "auto's tightest tolerance run does not reach the error"))
        else:
            out.append(row("2", figure, target, f"auto {_us(auto)}, {c['fastest_peer']} {_us(peer)} "
                                                f"({peer / auto:.3g}x)", auto <= peer,
                           f"{_us(auto - peer)} slower ({auto / peer:.3g}x the peer's time)"))
    return out


def sweep_rows(ends: dict | None, why: str = "") -> list[dict]:
    """Item 3: ``tswm sweep`` as whole processes (start-up, 10,000 and 100,000 cases) and against the
    vmapped diffrax batch at equal accuracy."""
    from tswm_runtime.bench import sweeps

    startup = f"<= {sweeps.STARTUP_TARGET_S:g} s"
    figures = [("warm start-up of tswm sweep (1 case, whole process)", startup)]
    figures += [(f"tswm sweep {n} cases, whole process", f">= {t:g} cases/s")
                for n, t in sweeps.PROCESS_TARGETS.items()]
    diffrax_target = f">= {sweeps.DIFFRAX_TARGET:g}x a vmapped diffrax batch at equal accuracy"
    if ends is None:
        return [row("3", f, t, None, remaining=why) for f, t in figures] + [
            row("3", "tswm sweep() vs vmapped diffrax", diffrax_target, None, remaining=why)]
    out = []
    for p in ends["processes"]:
        wall, cpu = p["wall_s_median"], p["cpu_s_median"]
        if p["cases"] == 1 and p["target_cases"] == 1:
            out.append(row("3", figures[0][0], startup, f"{wall:.3g} s wall, {cpu:.3g} s CPU (load {p['load_1min']})",
                           wall <= sweeps.STARTUP_TARGET_S,
                           f"{wall - sweeps.STARTUP_TARGET_S:.3g} s over; CPU alone {cpu:.3g} s"))
            continue
        n, goal = p["target_cases"], sweeps.PROCESS_TARGETS[p["target_cases"]]
        scaled = "" if p["cases"] == n else f" (measured on {p['cases']} cases)"
        out.append(row("3", f"tswm sweep {n} cases, whole process{scaled}", f">= {goal:g} cases/s",
                       f"{p['cases_per_s']:.4g} cases/s ({wall:.3g} s wall, {cpu:.3g} s CPU; load {p['load_1min']})",
                       p["cases_per_s"] >= goal,
                       f"{wall / p['cases'] * 1e6:.3g} us wall a case, the target allows {1e6 / goal:.3g} us "
                       f"({cpu / p['cases'] * 1e6:.3g} us CPU a case)"))
    dx = ends["diffrax"]
    if "timings" not in dx:
        return out + [row("3", "tswm sweep() vs vmapped diffrax", diffrax_target, None, remaining=dx["diffrax"])]
    for t in dx["timings"]:
        out.append(row("3", f"tswm sweep() vs vmapped diffrax at rtol {t['diffrax_rtol']:g} (matches tswm on "
                            f"{t['matches_tswm_on']}), {dx['cases']} cases", diffrax_target,
                       f"{t['tswm_over_diffrax']:.3g}x in wall time ({dx['tswm_cases_per_s']:.4g} against "
                       f"{t['diffrax_cases_per_s']:.4g} cases/s), {t['tswm_over_diffrax_cpu']:.3g}x in CPU",
                       t["tswm_over_diffrax"] >= sweeps.DIFFRAX_TARGET,
                       f"tswm's sweep must be {sweeps.DIFFRAX_TARGET / t['tswm_over_diffrax']:.3g}x faster"))
    return out


def generate_rows(generation: dict | None, why: str = "") -> list[dict]:
    """Item 4: the slowest shipped scene's ``tswm generate``, the slowest 999-breakpoint schedule's, and
    what a guards() call (made at every event-location sample) costs with 999 breakpoints against 3
    (``generation``: {"runs": ``generation.generate_runs``, "events": ``generation.event_runs``})."""
    generated, events = (generation or {}).get("runs"), (generation or {}).get("events")
    shipped_t, sched_t = f"<= {GENERATE_TARGET_S:g} s from empty caches", f"<= {SCHEDULE_TARGET_S:g} s"
    n_few, n_many = SCHEDULE_BREAKPOINTS
    event_t = f"the same as with {n_few} breakpoints (at most {EVENT_COST_SAME:g}x)"
    out = []
    shipped = [g for g in generated or () if g["kind"] == "shipped"]
    many = [g for g in generated or () if g["kind"] == "schedule" and g["breakpoints"] == n_many]
    from tswm_runtime.bench.generation import shipped_scenes

    every = len(shipped_scenes())
    for rows, figure, target, limit in ((shipped, f"tswm generate of every shipped scene ({len(shipped)} of {every})",
                                         shipped_t, GENERATE_TARGET_S),
                                        (many, f"tswm generate of a {n_many}-breakpoint schedule ({plural(len(many), 'kind')})",
                                         sched_t, SCHEDULE_TARGET_S)):
        if not rows:
            out.append(row("4", figure, target, None, remaining=why))
            continue
        worst = max(rows, key=lambda g: g["wall_s"])
        failed = [g["scene"] for g in rows if g["outcome"] != "ok"]
        measured = (f"slowest {worst['scene']} {worst['wall_s']:.3g} s wall, {worst['cpu_s']:.3g} s CPU (load "
                    f"{worst['load_1min']:.1f})" + (f"; failed: {', '.join(failed)}" if failed else ""))
        out.append(row("4", figure, target, measured, worst["wall_s"] <= limit and not failed,
                       f"{worst['wall_s'] - limit:.3g} s over on {worst['scene']} ({worst['cpu_s']:.3g} s of it CPU)"))
    by_n = {e["breakpoints"]: e for e in events or ()}
    figure = f"cost of each event of a {n_many}-breakpoint schedule (guards() call)"
    if n_few not in by_n or n_many not in by_n:
        return out + [row("4", figure, event_t, None, remaining=why)]
    few, lots = by_n[n_few], by_n[n_many]
    ratio = lots["guards_call_s"] / few["guards_call_s"]
    out.append(row("4", figure, event_t,
                   f"{lots['guards_call_s'] * 1e9:.3g} ns against {few['guards_call_s'] * 1e9:.3g} ns ({ratio:.3g}x); "
                   f"the runs: {lots['events']} events in {lots['run_s'] * 1e3:.3g} ms, {few['events']} in "
                   f"{few['run_s'] * 1e3:.3g} ms", ratio <= EVENT_COST_SAME,
                   f"a guards() call costs {ratio:.3g}x"))
    return out


def cold_rows(empty: list[dict] | None, why: str = "") -> list[dict]:
    """Item 5: a forced compile (TSWM_COLD_START=foreground) on an empty cache leaves a cache that the
    next run finds (it prints nothing on stderr); the cold notice within 1 s (the latest of the runs)."""
    found_f, notice_f = "a forced compile leaves a cache that the next run finds", "the cold notice on an empty cache"
    found_t, notice_t = "the next run silent (nothing compiled)", f"within {MESSAGE_TARGET_S:g} s"
    forced = [e for e in empty or () if e["TSWM_COLD_START"] == "foreground"]
    out = []
    if not forced:
        out.append(row("5", found_f, found_t, None, remaining=why))
    for e in forced:
        silent = e["next_run_silent"] is True
        out.append(row("5", f"{found_f} ({e['command']})", found_t,
                       f"next run {e['next_run_s']:.3g} s, " + ("silent" if silent else "printed on stderr"),
                       silent, "the next run compiled again or said the cache was cold"))
    if not empty:
        return out + [row("5", notice_f, notice_t, None, remaining=why)]
    late = max(empty, key=lambda e: -1.0 if math.isnan(e["message_s"]) else e["message_s"])
    printed = not math.isnan(late["message_s"])
    out.append(row("5", f"{notice_f} (latest of {len(empty)} runs: {late['command']}, {late['TSWM_COLD_START']})",
                   notice_t, f"{late['message_s']:.3g} s" if printed else "none printed",
                   printed and late["message_s"] <= MESSAGE_TARGET_S,
                   f"{late['message_s'] - MESSAGE_TARGET_S:.3g} s late" if printed else "no notice printed"))
    return out


def chain_rows(chain: dict | None, why: str = "") -> list[dict]:
    """The drive-train figure: a two-stage chain's simulate_chain against the fastest scipy peer."""
    from tswm_runtime.bench import chain as bench_chain

    target = f">= {CHAIN_TARGET:g}x the fastest peer"
    if chain is None:
        return [row("6", f"two-stage chain vs fastest peer at error {level:g}", target, None, remaining=why)
                for level in bench_chain.LEVELS]
    out = []
    for v in chain["verdicts"]:
        figure = f"two-stage chain vs fastest peer at error {v['level']:g}"
        if math.isnan(v["factor"]):
            out.append(row("6", figure, target, "no factor: tswm or every peer misses this error", False,
                           f"tswm {_us(v['tswm_s'])}, peer {v['peer']}"))
            continue
        allowed = v["peer_s"] / CHAIN_TARGET
        out.append(row("6", figure, target, f"{v['factor']:.3g}x (tswm {_us(v['tswm_s'])}, {v['peer']} "
                                            f"{_us(v['peer_s'])})", v["factor"] >= CHAIN_TARGET,
                       f"a call must take {_us(allowed)}, takes {_us(v['tswm_s'])}"))
    return out


ROWS = {"fixed cost": fixed_cost_rows, "speedup": speedup_rows, "auto": auto_rows, "sweeps": sweep_rows,
        "generate": generate_rows, "empty cache": cold_rows, "chain": chain_rows}  # part -> its rows


def all_rows(parts: dict, why: dict) -> list[dict]:
    """Every item's rows from ``parts`` (ROWS' names -> result, None or absent where not run; ``why[name]``
    says why)."""
    return [r for name, rows in ROWS.items() for r in rows(parts.get(name), why.get(name, "not run"))]
