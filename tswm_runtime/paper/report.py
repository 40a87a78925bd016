"""`tswm paper`: the paper's Table 3 and Figure 2 against what tswm computes, as a report.

Every number in the report comes from ``simulate`` on the shipped generated modules
(``paper``, ``paper-literal``, ``paper-runup``, ``paper-lostmotion``) or from those modules'
own functions; the paper's printed numbers come from ``paper_data``. Readings (a) to (c)
take nothing from Table 3; reading (d) has one number, the lost motion L, fitted to it by
``tswm fit`` (``paper_lostmotion``), and its cells are ``simulate`` runs at that L.
This module does not import SymPy; the derivation document is written by ``background``.
"""
from __future__ import annotations

import base64
import json
import math
import re
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import jinja2
import markupsafe
import numpy as np

from tswm_runtime.model.contract import load_module
from tswm_runtime.results.export import jsonable
from tswm_common.files import write_atomic
from tswm_runtime.paper.data import F2_LISTED, FIGURE2, M2_LISTED, SOURCE, TABLE3_PRINTED, printed
from tswm_runtime.reference.paper_gear import cones
from tswm_runtime.paper import lostmotion
from tswm_runtime.paper.plan import DOCUMENT, FIGURES, FIT, RUNS, SCENES, WRITE
from tswm_runtime.common.progress import Stages
from tswm_runtime.common.provenance import machine, package_versions
from tswm_runtime.common.words import difference, differences, plural
from tswm_runtime.results.result import Result
from tswm_runtime.simulation.simulate import simulate

TOLERANCE = 0.05   # a computed value "agrees" with a printed one within 5 % and with the same sign
NOISE = 1e-6      # a dissipation rate counts as negative below -NOISE * max |input power| of the run
QUANTITIES = (("S1m", "S1_max", "N"), ("KD1", "KD1", ""), ("S2m", "S2_max", "N"), ("KD2", "KD2", ""))
VERSIONED = ("tswm", "numpy", "scipy", "numba", "sympy", "jinja2", "matplotlib", "pandas")
FILES = {"md": "paper-report.md", "html": "paper-report.html", "json": "paper-report.json"}



@dataclass(frozen=True)
class Reading:
    """One way of reading the paper's scene: a shipped scene and how a case sets it."""

    key: str
    label: str
    scene: str
    title: str
    params: Callable[[float, float], dict]
    settings: tuple = ()   # run settings other than the scene's, as (name, value) pairs


READINGS = (
    Reading("consistent", "(a)", SCENES["consistent"], "consistent derivation, load from t = 0 (the scene as printed)",
            lambda m2, F2: {"m2": m2, "F2": F2}),
    Reading("literal", "(b)", SCENES["literal"], "the paper's equations (6), (7), (9) as printed, load from t = 0",
            lambda m2, F2: {"m2": m2, "F2": F2}),
    Reading("runup", "(c)", SCENES["runup"], "consistent derivation, free run-up, then F2 from t_step = 0.3 s",
            lambda m2, F2: {"m2": m2, "F2_after": F2}),
)


def lostmotion_reading(L: float, settings: dict | None = None) -> Reading:
    """Reading (d): scene ``paper-lostmotion`` at lost motion L (fitted to Table 3), run with the
    fit's tolerances (``settings``: rtol, atol), so that its cells are the model the fit saw."""
    return Reading("lostmotion", "(d)", lostmotion.SCENE, lostmotion.TITLE, lostmotion.params(L),
                   tuple(sorted((settings or {}).items())))


def all_cases() -> list[tuple[float, float]]:
    """The (m2, F2) inputs the paper lists: Table 3's six and the untabulated m2 = 300 kg."""
    return [(m2, F2) for m2 in M2_LISTED for F2 in F2_LISTED]


def run(reading: Reading, m2: float, F2: float) -> Result:
    """The run behind one cell of the report (the tests call exactly this)."""
    return simulate(reading.scene, reading.params(m2, F2), **dict(reading.settings))


# ---------------------------------------------------------------- words and numbers

def drive_word(result: Result) -> str:
    """Whether the drive starts, stalls or self-locks, read from the run's phases and status."""
    if result.status != "finished":
        return f"stopped early: {result.status}"
    phases = result.phases
    if not phases:
        return "no phases"
    if all(ph.regime == "stick" for ph in phases):
        return "does not start (self-locked)"
    if phases[-1].regime == "stick":
        return f"stalls (self-locks at t = {phases[-1].t_start:.4g} s)"
    return "runs"


def regime_text(result: Result) -> str:
    """The phases with their switch times: 'tractive 0-0.0232 s -> inverse-tractive 0.0232-1 s'."""
    return " → ".join(f"{ph.regime} {ph.t_start:.4g}–{ph.t_end:.4g} s" for ph in result.phases)


def fmt(value: float | None) -> str:
    """A number for a table: whole newtons above 1000, else 4 significant digits."""
    if value is None:
        return "–"
    if not math.isfinite(value):
        return str(value)
    return f"{value:.0f}" if abs(value) >= 1000 else f"{value:.4g}"


def agrees(computed: float | None, paper: float) -> bool:
    """Same sign and within TOLERANCE of the printed value."""
    return computed is not None and computed * paper > 0 and abs(computed - paper) <= TOLERANCE * abs(paper)


def statics(module, F2: float) -> dict:
    """The starting force against the static friction cone at v1 = 0, load F2 from t = 0.

    Hand statics: normal force N = F1 sin(gamma) - F2 cos(gamma), tangential T = F1
    cos(gamma) + F2 sin(gamma); stick holds while tan(rho(0)) |N| >= T, so breaking away
    forward needs F1 > tan(gamma + rho(0)) |F2| (F2 < 0). Cross-checked with the generated
    module's ``stick_conditions`` (its cone_forward margin at F1(0))."""
    y = np.zeros(1)
    p = np.array([FIGURE2["m2"], F2])
    gamma = float(module.FIXED["gamma"])
    F1_0 = float(module.drive_force(0.0, y, p))
    rho0 = float(module.friction_angle(0.0, y, p))
    margin_hand = cones(F1_0, F2, gamma, rho0)[0]
    margin_module = float(module.stick_conditions(0.0, y, p)[0])
    return {"F2": F2, "F1_0": F1_0, "rho0_deg": math.degrees(rho0), "gamma_deg": math.degrees(gamma),
            "breakaway_F1": math.tan(gamma + rho0) * abs(F2), "cone_margin_hand": margin_hand,
            "cone_margin_module": margin_module, "sticks": margin_module >= 0.0}


def energy_balance(result: Result, module) -> dict:
    """Work and kinetic energy along a run, from the Result's arrays with numpy.

    KE = m1 v1^2/2 + m2 v2^2/2, input power P = F1 v1 + F2 v2; friction dissipates
    P - dKE/dt (pointwise with a2 = a1 tan(gamma)); integrated by the trapezoid rule,
    E_diss = W_in - (KE(end) - KE(0)). A negative dissipation is non-physical."""
    m1, m2 = float(module.FIXED["m1"]), float(result.params["m2"])
    slope = math.tan(float(module.FIXED["gamma"]))
    t, v1, v2 = result.t, result.v1, result.v2
    ke = 0.5 * m1 * v1**2 + 0.5 * m2 * v2**2
    power = result.F1 * v1 + result.F2 * v2
    rate = power - (m1 * v1 * result.a1 + m2 * v2 * result.a1 * slope)
    work = float(np.trapezoid(power, t))
    dke = float(ke[-1] - ke[0])
    tolerance = NOISE * max(1.0, float(np.max(np.abs(power))))
    negative = rate < -tolerance
    return {"tolerance_W": tolerance, "W_in": work, "dKE": dke, "E_diss": work - dke, "E_diss_pointwise": float(np.trapezoid(rate, t)),
            "min_rate": float(rate.min()), "t_min_rate": float(t[int(rate.argmin())]),
            "negative_fraction": float(np.mean(negative)), "v1_end": float(v1[-1]), "a1_0": float(result.a1[0])}


# ---------------------------------------------------------------- the report

def _statements(rows: list[dict], checks: dict, cases_printed: int, readings: tuple = READINGS,
                lost: dict | None = None) -> list[dict]:
    """Which columns agree with the paper and why, each backed by the numbers of this run."""
    out = []
    counts = []
    for reading in readings:
        parts = []
        for q, _, _ in QUANTITIES:
            n = sum(1 for r in rows if r["printed"] and r[reading.key]["agree"][q])
            parts.append(f"{q} {n}/{cases_printed}")
        counts.append(f"{reading.label} {reading.scene}: " + ", ".join(parts))
    out.append({"title": f"Agreement with the printed Table 3 (same sign, within {TOLERANCE:.0%})",
                "text": "; ".join(counts) + "."})

    st = checks["statics"]
    words = sorted({r["consistent"]["drive"] for r in rows})
    brk = ", ".join(f"{s['breakaway_F1']:.0f} N (F2 = {s['F2']:.0f} N)" for s in st)
    diff = max(abs(s["cone_margin_hand"] - s["cone_margin_module"]) for s in st)
    all_stick = all(s["sticks"] for s in st)
    out.append({"title": "(a) consistent, load from t = 0",
                "text": f"At standstill the motor gives F1(0) = {st[0]['F1_0']:.1f} N; with rho(0) = "
                        f"{st[0]['rho0_deg']:.2f} deg > gamma = {st[0]['gamma_deg']:.2f} deg the gear is "
                        f"self-locking, and breaking away against the load needs F1 > tan(gamma + rho(0)) |F2| = "
                        f"{brk} (hand statics: N = F1 sin(gamma) - F2 cos(gamma), T = F1 cos(gamma) + F2 "
                        f"sin(gamma), stick while tan(rho(0)) |N| >= T; its cone margin and the generated module's "
                        f"stick_conditions {difference(diff, 'N')}). "
                        + ("So F1(0) lies inside the static friction cone in every case: "
                           if all_stick else "F1(0) leaves the cone in some cases: ")
                        + f"the runs say {' / '.join(words)}. S1 = F1(0) and S2 = F2 are static values; the "
                        "paper's dynamic maxima (S1m up to " + fmt(max((c.S1m for c in TABLE3_PRINTED), default=0)) +
                        " N, |S2m| above |F2|) cannot come from this reading."})

    lit = checks["energy"]["literal"]
    first_switch = [r["literal"]["phases"][1]["t_start"] for r in rows if len(r["literal"]["phases"]) > 1]
    s1 = [r["literal"]["values"]["S1m"] for r in rows]
    out.append({"title": "(b) the printed equations",
                "text": f"Taken as printed, eqs. (6), (7), (9) switch from tractive to inverse-tractive at t = "
                        f"{min(first_switch, default=float('nan')):.3g}-{max(first_switch, default=float('nan')):.3g} s "
                        f"and stay there; S1 is negative from t = 0, because eq. (6) as printed lets the resisting "
                        f"load accelerate the worm (a1(0) = {lit['a1_0']:.4g} m/s^2, F1(0) = {st[0]['F1_0']:.1f} N, "
                        f"m1 = 11.8 kg): S1m = {fmt(min(s1))} to {fmt(max(s1))} N where the "
                        "paper prints S1m > 0 and concludes the drive stays tractive. Energy balance along the run "
                        f"of the Figure 2 case (m2 = {lit['m2']:.0f} kg, F2 = {lit['F2']:.0f} N): input work "
                        f"W = integral(F1 v1 + F2 v2) dt = {lit['W_in']:.4g} J, kinetic energy change "
                        f"{lit['dKE']:.4g} J, so friction would have to dissipate W - dKE = {lit['E_diss']:.4g} J; "
                        f"the dissipation rate P - dKE/dt is negative in {lit['negative_fraction']:.1%} of the output "
                        f"points (minimum {lit['min_rate']:.4g} W at t = {lit['t_min_rate']:.3g} s). "
                        + ("Negative dissipation means friction supplies energy: the printed equations are "
                           "non-physical." if lit["E_diss"] < 0 or lit["min_rate"] < 0 else
                           "The dissipation stays non-negative along this run.")})

    run = checks["energy"]["runup"]
    over = [abs(r["runup"]["values"]["S2m"]) - abs(r["F2"]) for r in rows]
    ratios_c = [r["runup"]["values"]["S2m"] / r["runup"]["values"]["S1m"] for r in rows]
    ratios_p = [r["printed"]["S2m"] / r["printed"]["S1m"] for r in rows if r["printed"]]
    over_p = [abs(r["printed"]["S2m"]) - abs(r["F2"]) for r in rows if r["printed"]]
    words = sorted({r["runup"]["drive"] for r in rows})
    near = [f"test {r['test']} {q}" for r in rows if r["printed"] for q, _, _ in QUANTITIES if r["runup"]["agree"][q]]
    regimes = sorted({"/".join(ph["regime"] for ph in r["runup"]["phases"]) for r in rows})
    out.append({"title": "(c) run up, then load",
                "text": f"The drive {' / '.join(words)} with regimes {', '.join(regimes)}: tractive throughout, as "
                        f"the paper concludes. But the load comes on quasi-statically: |S2m| - |F2| is only "
                        f"{min(over):.3g} to {max(over):.3g} N"
                        + (f", where the paper prints |S2m| {min(over_p):.0f}-{max(over_p):.0f} N above |F2|; "
                           if over_p else "; ")
                        + 
                        f"S2m/S1m is {min(ratios_c):.3g} to {max(ratios_c):.3g} here, "
                        + (f"{min(ratios_p):.3g} to {max(ratios_p):.3g} printed. " if ratios_p else "")
                        + f"Friction dissipates {run['E_diss']:.4g} J in the Figure 2 case (minimum rate "
                        f"{run['min_rate']:.4g} W)"
                        + (": energy balances with non-negative dissipation." if run["E_diss"] >= 0
                           and run["negative_fraction"] == 0 else ": negative dissipation, check the run.")
                        + (f" Cells within {TOLERANCE:.0%} of the paper: {', '.join(near)}." if near else
                           f" No cell is within {TOLERANCE:.0%} of the paper.")})
    out.append({"title": "(d) lost motion, L fitted to Table 3", "text": lostmotion_statement(rows, checks, lost)})
    return out


def lostmotion_statement(rows: list[dict], checks: dict, lost: dict) -> str:
    """What reading (d) does at the fitted L and why, with the numbers of this run."""
    cells = [r["lostmotion"] for r in rows if r["printed"] and r["lostmotion"]["drive"] == "runs"] or \
        [r["lostmotion"] for r in rows if r["lostmotion"]["drive"] == "runs"]
    stalled = [f"m2 = {r['m2']:g} kg, F2 = {r['F2']:g} N" + (f" (test {r['test']})" if r["test"] else "")
               for r in rows if r["lostmotion"]["drive"] != "runs"]
    pick = [c["pickup"] for c in cells if c["pickup"]]
    printed_rows = [r for r in rows if r["printed"] and r["lostmotion"]["values"]["S2m"] is not None]
    over = [abs(r["lostmotion"]["values"]["S2m"]) - abs(r["F2"]) for r in printed_rows]
    over_p = [abs(r["printed"]["S2m"]) - abs(r["F2"]) for r in printed_rows]
    vmax = lost["Vmax"]
    text = (f"At L = {lost['L_mm']:.2f} mm the load is picked up at t = "
            + (f"{min(p['t'] for p in pick):.3g}-{max(p['t'] for p in pick):.3g} s, v1 = "
               f"{min(p['v1'] for p in pick):.3g}-{max(p['v1'] for p in pick):.3g} m/s" if pick else "(no pickup)")
            + f", before the motor reaches its breakdown speed Vmax = {vmax:g} m/s: it goes on accelerating "
            f"against the load, and the peaks come as it passes Vmax, where F1 is largest (v1 at the S2 peak: "
            + (f"{min(c['v1_at_S2m'] for c in cells):.3g}-{max(c['v1_at_S2m'] for c in cells):.3g} m/s" if cells else "–")
            + "). So S1 and S2 exceed their static values: ")
    if printed_rows:
        text += (f"|S2m| - |F2| = {min(over):.0f} to {max(over):.0f} N in the tabulated tests, where the paper prints "
                 f"{min(over_p):.0f} to {max(over_p):.0f} N. ")
    prof = lost["profile"]
    if lost.get("stall_below"):
        text += (f"A shorter lost motion picks the load up at a lower speed, where the friction angle is larger: at "
                 f"L = {prof['below'] * 1e3:.4f} mm (just below the edge the profile's bisection found) "
                 + ", ".join(lost["stall_below"]) + (" stall and self-lock" if len(lost["stall_below"]) > 1 else
                                                     " stalls and self-locks") + ", and the cost jumps from "
                 f"{prof['cost_min']:.4g} to {prof['cost_below']:.4g}. ")
    text += (f"A longer one picks it up nearer the no-load speed, where F1 is small, and the peaks fall towards "
             f"reading (c)'s (cost {prof['cost_at_L_max']:.4g} at L = {lost['bounds'][1] * 1e3:g} mm). ")
    if stalled:
        text += f"At the fitted L the drive stalls in {plural(len(stalled), 'case')}: {'; '.join(stalled)}. "
    e = checks["energy"].get("lostmotion")
    if e:
        text += (f"Energy in the Figure 2 case: input work {e['W_in']:.4g} J, kinetic energy change {e['dKE']:.4g} J, "
                 f"friction dissipates {e['E_diss']:.4g} J (minimum rate {e['min_rate']:.4g} W)"
                 + (": non-negative, as in (c)." if e["E_diss"] >= 0 and e["negative_fraction"] == 0 else
                    ": negative dissipation, check the run."))
    return text


def wall_time_text(timing: dict) -> str:
    """The run's wall time in one sentence; the report and the CLI both print exactly this."""
    return (f"wall time {timing['wall_s']:.2f} s from the start of `tswm paper` to the report "
            f"(start-up: imports and numba's compiled code {timing['startup_s']:.2f} s; runs, checks, "
            f"figures and derivation {timing['work_s']:.2f} s)")


def deviation(computed: float | None, paper: float) -> float:
    """|computed - printed| / |printed| (a wrong sign counts as at least 100 %)."""
    return math.inf if computed is None or not math.isfinite(computed) else abs(computed - paper) / abs(paper)


def verdict(rows: list[dict], checks: dict, readings: tuple = READINGS, lost: dict | None = None) -> dict:
    """The answer first: which reading agrees with Table 3, in which columns, and why.

    The readings that take nothing from the table ((a) to (c)) are ranked by the number of
    printed cells they match (same sign, within TOLERANCE), then by their mean deviation
    from the printed numbers over all cells. Reading (d), whose L is fitted to the table, is
    scored alike but not ranked with them: its agreement is what the fit was made to get."""
    printed_rows = [r for r in rows if r["printed"]]
    scores = {}
    for reading in readings:
        cells = [(q, r[reading.key]["values"][q], r["printed"][q]) for r in printed_rows for q, _, _ in QUANTITIES]
        columns = {q: {"agree": sum(1 for r in printed_rows if r[reading.key]["agree"][q]),
                       "mean_deviation": float(np.mean([deviation(r[reading.key]["values"][q], r["printed"][q])
                                                        for r in printed_rows])) if printed_rows else math.nan,
                       "signs": sum(1 for r in printed_rows
                                    if (r[reading.key]["values"][q] or 0.0) * r["printed"][q] > 0)}
                   for q, _, _ in QUANTITIES}
        scores[reading.key] = {
            "agree": sum(1 for q, c, p in cells if agrees(c, p)), "cells": len(cells),
            "mean_deviation": float(np.mean([deviation(c, p) for _, c, p in cells])) if cells else math.nan,
            "columns": columns,
            "tractive": all(ph["regime"] == "tractive" for r in rows for ph in r[reading.key]["phases"]),
            "drive": sorted({r[reading.key]["drive"] for r in rows})}
    best = min(READINGS, key=lambda r: (-scores[r.key]["agree"], scores[r.key]["mean_deviation"]))
    st, lit = checks["statics"], checks["energy"].get("literal", {})
    cols = scores[best.key]["columns"]
    over = [abs(r[best.key]["values"]["S2m"]) - abs(r["F2"]) for r in printed_rows]
    over_p = [abs(r["printed"]["S2m"]) - abs(r["F2"]) for r in printed_rows]
    n = scores[best.key]["cells"]
    fitted = next((r for r in readings if r.key == "lostmotion"), None)
    headline = (f"No reading reproduces the printed numbers: of the {plural(n, 'printed cell')} (S1m, KD1, S2m, KD2 "
                f"of {plural(len(printed_rows), 'test')}), "
                + ", ".join(f"{r.label} {r.scene} matches {scores[r.key]['agree']}"
                                                           for r in READINGS)
                + (f", and {fitted.label} {fitted.scene}, whose lost motion L is fitted to this table, "
                   f"{scores[fitted.key]['agree']}" if fitted else "")
                + f" within {TOLERANCE:.0%}. Closest is {best.label} `{best.scene}` ({best.title}), with a mean "
                f"deviation of {scores[best.key]['mean_deviation']:.0%} from the printed values"
                + ("; it also agrees with the paper in kind: tractive throughout, S1 > 0 and S2 < 0, as the paper "
                   "concludes." if scores[best.key]["tractive"] else ".")
                + (f" The fitted reading {fitted.label} comes to {scores[fitted.key]['mean_deviation']:.0%}, and that is "
                   "a fit, not a reproduction." if fitted else ""))
    points = [f"Columns of {best.label}: " + "; ".join(
        f"{q} {cols[q]['agree']}/{len(printed_rows)} within {TOLERANCE:.0%} (mean deviation "
        f"{cols[q]['mean_deviation']:.0%})" for q, _, _ in QUANTITIES) + "."
        + (f" Its |S2m| - |F2| is only {min(over):.2g} to {max(over):.2g} N: the load comes on after the run-up "
           f"and is carried quasi-statically, where the paper's peaks lie {min(over_p):.0f}-{max(over_p):.0f} N "
           "above |F2| (a dynamic overshoot)."
           if printed_rows and max(over) < min(over_p) else "")]
    if not printed_rows:
        headline = "None of the cases run here has a row in the paper's Table 3: there is nothing to compare."
        points = []
    if st:
        a = READINGS[0]
        rho0, gamma = st[0]["rho0_deg"], st[0]["gamma_deg"]
        points.append(
            f"{a.label} `{a.scene}` {' / '.join(scores[a.key]['drive'])}: the starting force F1(0) = "
            f"{st[0]['F1_0']:.1f} N lies " + ("inside" if all(s["sticks"] for s in st) else "partly outside")
            + f" the static friction cone (rho(0) = {rho0:.2f} deg {'>' if rho0 > gamma else '<='} gamma = "
            f"{gamma:.2f} deg); breaking away against the load needs F1 > "
            + ", ".join(f"{s['breakaway_F1']:.0f} N (F2 = {s['F2']:.0f} N)" for s in st)
            + ". So S1 and S2 are static values, F1(0) and F2, not the paper's dynamic peaks.")
    if lit:
        b = READINGS[1]
        s1 = [r[b.key]["values"]["S1m"] for r in rows]
        inverse = sum(1 for r in rows if any(ph["regime"] == "inverse-tractive" for ph in r[b.key]["phases"]))
        points.append(
            f"{b.label} `{b.scene}`: S1m is " + ("negative in every case" if max(s1) < 0 else
                                                f"between {fmt(min(s1))} and {fmt(max(s1))} N")
            + f"; {inverse} of {plural(len(rows), 'run')} {'turns' if inverse == 1 else 'turn'} inverse-tractive, "
            "where the paper prints S1m > 0 and "
            f"a tractive drive. Its energy balance (m2 = {lit['m2']:g} kg, F2 = {lit['F2']:g} N): input work {lit['W_in']:.0f} J, kinetic "
            f"energy change {lit['dKE']:.0f} J, so friction would dissipate {lit['E_diss']:.0f} J"
            + (": friction would supply energy, the printed equations are not physical." if lit["E_diss"] < 0
               else "."))
    if fitted and printed_rows:
        points.append(lostmotion_point(printed_rows, scores[fitted.key], scores[best.key], best, fitted, lost))
    return {"best": best.key, "headline": headline, "points": points, "scores": scores,
            "fitted": fitted.key if fitted else None,
            "lostmotion_explains": bool(fitted and printed_rows and scores[fitted.key]["agree"]
                                        == scores[fitted.key]["cells"])}


def lostmotion_point(printed_rows: list[dict], score: dict, best_score: dict, best: Reading, fitted: Reading,
                     lost: dict) -> str:
    """The verdict on reading (d): the fitted L, its intervals, and whether it explains the table."""
    prof = lost["profile"]
    lo, hi = lost["bounds"]
    rel = {q: [(r["printed"][q] - r[fitted.key]["values"][q]) / abs(r["printed"][q]) for r in printed_rows
               if r[fitted.key]["values"][q] is not None] for q, _, _ in QUANTITIES}
    short = [f"{q} {min(v):+.1%} to {max(v):+.1%}" for q, v in rel.items() if v]
    text = (f"{fitted.label} `{fitted.scene}`, lost motion fitted to Table 3: L = {lost['L_mm']:.2f} mm of x2 (the "
            f"wheel turns {lost['wheel_deg']:.1f} deg freely before it picks up the load), "
            f"{prof['confidence']:.0%} profile interval {prof['lo'] * 1e3:.2f}-{prof['hi'] * 1e3:.2f} mm, within the "
            f"bounds {lo * 1e3:g}-{hi * 1e3:g} mm that span the physically plausible lost motions (see below)"
            + ("; the fitted L is an edge, not a minimum: just below it a test stalls and the cost jumps. "
               if prof["minimum_on_edge"] else ". ")
            + f"At that L it matches {score['agree']} of {score['cells']} printed cells within {TOLERANCE:.0%}, mean "
            f"deviation {score['mean_deviation']:.0%} (against {best_score['mean_deviation']:.0%} for {best.label}). "
            "A fitted parameter is a fit, not a reproduction: L was chosen to make S1m and S2m come as close to this "
            "table as they can, so the agreement it buys is no evidence that the paper modelled lost motion. ")
    if score["agree"] == score["cells"]:
        text += "With it every printed cell lies within the tolerance."
    else:
        text += ("Even so no plausible L explains the table: the printed values minus the computed ones are "
                 + "; ".join(short) + " of the printed values, and "
                 + (f"no L in the bounds does better (the lowest cost of the misfit grid and the profile over "
                    f"{lo * 1e3:g}-{hi * 1e3:g} mm, "
                    f"{prof['grid_best_cost']:.4g}, is not below the fit's {prof['fit_cost']:.4g})."
                    if prof["grid_best_cost"] >= prof["fit_cost"] * (1 - 1e-6) else
                    f"the misfit grid or the profile finds a lower cost ({prof['grid_best_cost']:.4g} at L = "
                    f"{prof['grid_best_L'] * 1e3:.2f} mm) than the fit's {prof['fit_cost']:.4g}: the starts missed it."))
    return text


def _figure(result: Result, module, reading: Reading, m2: float, F2: float) -> bytes:
    from tswm_runtime.results.plot import png_bytes

    heading = (f"{reading.label} {reading.scene}: {reading.title}\n"
               f"m2 = {m2:g} kg, F2 = {F2:g} N; {drive_word(result)}")
    return png_bytes(result, module, dpi=200, heading=heading, event_labels=True)


def _code_html(text: str) -> markupsafe.Markup:
    """Text with `code` spans, escaped for HTML and the spans set as <code>."""
    return markupsafe.Markup(re.sub(r"`([^`]*)`", r"<code>\1</code>", str(markupsafe.escape(text))))


def _environment() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.PackageLoader("tswm_runtime.paper", "templates"),
                             autoescape=jinja2.select_autoescape(["html.j2"]), keep_trailing_newline=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    env.filters["code_html"] = _code_html
    env.filters["plural"] = plural
    return env


def _cell(reading: Reading, result: Result, paper) -> dict:
    """One reading's cell of a case: its values, agreement, regimes, events (the JSON's numbers)."""
    values = {q: (None if getattr(result, attr) is None else float(getattr(result, attr))) for q, attr, _ in QUANTITIES}
    cell = {
        "scene": reading.scene, "params": dict(result.params), "status": result.status,
        "message": result.message, "values": values,
        "t_S1m": result.t_S1_max, "t_S2m": result.t_S2_max,
        "agree": {q: bool(paper) and agrees(values[q], getattr(paper, q)) for q, _, _ in QUANTITIES},
        "regimes": regime_text(result), "drive": drive_word(result),
        "phases": [{"regime": ph.regime, "mode": ph.mode, "t_start": ph.t_start, "t_end": ph.t_end}
                   for ph in result.phases],
        "events": [e.to_dict() for e in result.events],
        "v1_end": float(result.v1[-1]),
    }
    if reading.key == "lostmotion":
        # residual = printed - computed, per cell; where the load is picked up; v1 at the peaks
        cell["residual"] = {q: (None if paper is None or values[q] is None else getattr(paper, q) - values[q])
                            for q, _, _ in QUANTITIES}
        pick = next((e for e in result.events if e.guard == lostmotion.FREE), None)
        cell["pickup"] = None if pick is None else {"t": pick.t, "v1": pick.v1, "x1": pick.x1}
        for q, t in (("S1m", result.t_S1_max), ("S2m", result.t_S2_max)):
            cell[f"v1_at_{q}"] = None if t is None else float(np.ravel(result.sol(t)[1])[0])
    return cell


def _fit_vs_simulate(rows: list[dict], lost: dict) -> dict:
    """The fit's own model values (batch kernel, the fit's tolerances) against the report's
    simulate() cells at the same L: the largest absolute difference per quantity."""
    fit_cases = {c["case"]: c for c in lost["fit"]["cases"]}
    diff = {}
    for r in rows:
        c = fit_cases.get(f"test{r['test']}")
        if c is None or r["lostmotion"]["values"]["S1m"] is None:
            continue
        for q, entry in c["quantities"].items():
            d = abs(entry["model"] - r["lostmotion"]["values"][q])
            diff[q] = max(diff.get(q, 0.0), d)
    return {"max_abs_difference": diff, "text": differences(diff, {q: unit for q, _, unit in QUANTITIES}),
            "fit_run": {k: lost["fit"]["settings"][k] for k in ("rtol", "atol")}}


def build_report(out_dir: str | Path = "tswm-report", cases: list[tuple[float, float]] | None = None, *,
                 document: Callable[[], dict | None] | None = None, stages: Stages | None = None,
                 started: float | None = None) -> dict:
    """Run every reading for every case, write the report files into ``out_dir``; return
    {'paths': {...}, 'data': the JSON sidecar's content}. ``document``: returns the derivation
    document's description once it is written (``background``), None for none. ``stages``:
    the progress bar, with plan's stages FIT to WRITE among its own (None: no bar). ``started`` is the
    ``time.perf_counter()`` at which the command began (the CLI passes it), so that the
    wall time includes the start-up: imports and loading numba's compiled code."""
    start = time.perf_counter()
    started = start if started is None else started
    stages = stages or Stages({}, desc="tswm paper", enabled=False)
    out_dir = Path(out_dir)
    cases = list(cases) if cases is not None else all_cases()
    fig_case = (FIGURE2["m2"], FIGURE2["F2"])
    readings = READINGS + (lostmotion_reading(math.nan),)
    modules = {r.key: load_module(r.scene) for r in readings}

    stages.begin(FIT)
    lost = lostmotion.fit_table3(out_dir)
    lost["Vmax"] = float(modules["lostmotion"].FIXED["Vmax"])
    tolerances = {k: lost["fit"]["settings"][k] for k in ("rtol", "atol")}
    readings = READINGS + (lostmotion_reading(lost["L"], tolerances),)
    stages.begin(RUNS)
    rows, results = [], {}
    for test_index, (m2, F2) in enumerate(cases):
        paper = printed(m2, F2)
        row = {"m2": m2, "F2": F2, "test": paper.test if paper else None,
               "printed": None if paper is None else {q: getattr(paper, q) for q, _, _ in QUANTITIES}}
        for reading in readings:
            result = run(reading, m2, F2)
            results[(reading.key, m2, F2)] = result
            row[reading.key] = _cell(reading, result, paper)
        rows.append(row)
    # the same cells at the scene's own tolerances: does any case change its course?
    own, fitted = lostmotion_reading(lost["L"]), readings[-1]
    lost["scene_tolerances"], lost["table3_cells"] = [], []
    for c in TABLE3_PRINTED:
        r, f = run(own, c.m2, c.F2), run(fitted, c.m2, c.F2)
        lost["table3_cells"].append({"test": c.test, "m2": c.m2, "F2": c.F2,
                                     "printed": {q: getattr(c, q) for q, _, _ in QUANTITIES},
                                     "lostmotion": _cell(fitted, f, c)})
        lost["scene_tolerances"].append({"test": c.test, "rtol": r.settings["rtol"], "atol": r.settings["atol"],
                                         "drive": drive_word(r), "S1m": r.S1_max, "S2m": r.S2_max,
                                         "drive_fit_tolerances": drive_word(f), "S1m_fit_tolerances": f.S1_max,
                                         "S2m_fit_tolerances": f.S2_max})
    changed = [s for s in lost["scene_tolerances"] if s["drive"] != s["drive_fit_tolerances"]]
    if changed:
        lost["notes"].append(
            "The fitted L lies within the integrator's error of that edge: at the scene's own tolerances (rtol "
            f"{changed[0]['rtol']:g}, atol {changed[0]['atol']:g}) instead of the fit's, "
            + "; ".join(f"test {s['test']} {s['drive']} (S1m = {s['S1m']:.0f} N, S2m = {s['S2m']:.0f} N) where at "
                        f"the fit's it {s['drive_fit_tolerances']} (S1m = {s['S1m_fit_tolerances']:.0f} N, "
                        f"S2m = {s['S2m_fit_tolerances']:.0f} N)" for s in changed)
            + ". The cells of (d) are therefore run with the fit's tolerances; any L a little longer, inside the "
            "flat range, gives the same peaks without this sensitivity.")
    if lost["profile"]["below"] is not None:
        below = lostmotion_reading(lost["profile"]["below"], tolerances)
        lost["stall_below"] = [f"test {c.test} (m2 = {c.m2:g} kg, F2 = {c.F2:g} N)" for c in TABLE3_PRINTED
                               if drive_word(run(below, c.m2, c.F2)).startswith(("stalls", "does not start"))]

    consistent = modules["consistent"]
    checks = {"statics": [statics(consistent, F2) for F2 in sorted({F2 for _, F2 in cases}, reverse=True)],
              "energy": {}}
    if fig_case not in cases:
        fig_case = cases[-1]
    energy_rows = []
    for m2, F2 in cases:
        for reading in readings:
            if (reading.key, m2, F2) not in results:
                continue
            e = energy_balance(results[(reading.key, m2, F2)], modules[reading.key])
            e.update(m2=m2, F2=F2)
            energy_rows.append({"reading": f"{reading.label} {reading.scene}", **e})
            if (m2, F2) == fig_case:
                checks["energy"][reading.key] = e
    checks["energy_table"] = energy_rows

    stages.begin(FIGURES)
    figures = []
    for reading in readings:
        if (reading.key, *fig_case) not in results:
            continue
        result = results[(reading.key, *fig_case)]
        png = _figure(result, modules[reading.key], reading, *fig_case)
        name = f"figure2-{reading.key}.png"
        write_atomic(out_dir / name, png)
        figures.append({"file": name, "label": reading.label, "scene": reading.scene, "title": reading.title,
                        "regimes": regime_text(result), "drive": drive_word(result),
                        "data": base64.b64encode(png).decode("ascii")})

    stages.begin(DOCUMENT, waiting=True)
    doc = document() if document is not None else None
    stages.begin(WRITE)

    settings = {}
    for r in readings:
        first = next((results[(r.key, *c)] for c in cases if (r.key, *c) in results), None)
        if first is not None:
            settings[r.scene] = {k: first.settings[k] for k in ("method", "rtol", "atol", "t_end", "points",
                                                                  "max_steps", "max_events")}
    profile_png = lost.pop("profile_png", None)
    lost["fit_vs_simulate"] = _fit_vs_simulate(rows, lost)
    data = {
        "source": SOURCE, "tolerance": TOLERANCE, "figure_case": {"m2": fig_case[0], "F2": fig_case[1]},
        "readings": [{"key": r.key, "label": r.label, "scene": r.scene, "title": r.title} for r in readings],
        "cases": rows, "checks": checks, "lostmotion": lost,
        "settings": settings, "versions": package_versions(VERSIONED), "machine": machine(),
        "command": "tswm paper " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["paper"] else "tswm paper",
        "derivation": doc,
    }
    cases_printed = sum(1 for r in rows if r["printed"])
    data["verdict"] = verdict(rows, checks, readings, lost)
    data["statements"] = _statements(rows, checks, cases_printed, readings, lost)
    now = time.perf_counter()   # before rendering (milliseconds); the CLI prints this same figure
    data["timing"] = {"wall_s": now - started, "startup_s": start - started, "work_s": now - start}
    context = _context(data, figures, readings, profile_png)
    env = _environment()
    paths = {"json": write_atomic(out_dir / FILES["json"], json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n"),
             "md": write_atomic(out_dir / FILES["md"], env.get_template("paper_report.md.j2").render(context)),
             "html": write_atomic(out_dir / FILES["html"], env.get_template("paper_report.html.j2").render(context))}
    paths.update({f["file"]: out_dir / f["file"] for f in figures})
    paths.update({Path(f).name: out_dir / f for f in lost.get("files", [])})
    if doc:
        paths.update({name: out_dir / name for name in doc["files"]})
    stages.end()
    return {"paths": paths, "data": data}


def residual_text(value: float | None, q: str) -> str:
    """A residual (printed - computed) for a table, signed: '+94', '-1221', '+0.097'."""
    if value is None:
        return "–"
    return f"{value:+.0f}" if not q.startswith("KD") and abs(value) >= 10 else f"{value:+.3g}"


def table3_tables(data: dict, readings: tuple = READINGS) -> list[dict]:
    """Table 3 side by side, one table per quantity so that each fits a page: its heading and
    header and rows of strings (agreeing cells marked ✓); with the fitted reading (d), its
    residual per cell (printed - computed) in the last column."""
    fitted = any(r.key == "lostmotion" for r in readings)
    header = ["Test", "m2 [kg]", "F2 [N]", "paper", *(r.label for r in readings)]
    header += ["paper − (d)"] if fitted else []
    tables = []
    for q, _, unit in QUANTITIES:
        rows = []
        for row in data["cases"]:
            cells = [str(row["test"]) if row["test"] else "–", f"{row['m2']:g}", f"{row['F2']:g}"]
            cells.append((f"{row['printed'][q]:.2f}" if q.startswith("KD") else fmt(row["printed"][q]))
                         if row["printed"] else "not printed")
            cells += [fmt(row[r.key]["values"][q]) + (" ✓" if row[r.key]["agree"][q] else "") for r in readings]
            if fitted:
                cells.append(residual_text(row["lostmotion"]["residual"][q], q))
            rows.append(cells)
        tables.append({"quantity": q, "heading": f"{q} [{unit}]" if unit else q, "table": (header, rows)})
    return tables


def lostmotion_tables(data: dict) -> dict:
    """Reading (d)'s own tables: residuals per case and quantity, the fit's starts, the profile."""
    lost = data["lostmotion"]
    fitted = set(lost["fitted_columns"])
    header = ["test", "m2 [kg]", "F2 [N]", "quantity", "fitted", "printed", "computed (d)", "printed − computed",
              "relative", "pickup t [s]", "pickup v1 [m/s]", "v1 at the peak [m/s]"]
    rows = []
    for row in lost["table3_cells"]:
        cell = row["lostmotion"]
        for q, _, _ in QUANTITIES:
            res, val, pr = cell["residual"][q], cell["values"][q], row["printed"][q]
            peak = cell.get("v1_at_S1m" if q in ("S1m", "KD1") else "v1_at_S2m")
            rows.append([str(row["test"]), f"{row['m2']:g}", f"{row['F2']:g}", q, "yes" if q in fitted else "no",
                         f"{pr:.2f}" if q.startswith("KD") else fmt(pr), fmt(val), residual_text(res, q),
                         "–" if res is None else f"{res / abs(pr):+.1%}",
                         "–" if not cell["pickup"] else f"{cell['pickup']['t']:.4f}",
                         "–" if not cell["pickup"] else f"{cell['pickup']['v1']:.3f}",
                         "–" if peak is None else f"{peak:.3f}"])
    starts = [[str(k + 1), f"{s['x0'][0] * 1e3:.3f}", f"{s['x'][0] * 1e3:.4f}", f"{s['cost']:.6g}", str(s["status"]),
               str(s["nfev"]), str(s["failed_cases"])] for k, s in enumerate(lost["fit"]["starts"])]
    return {"residuals": (header, rows),
            "starts": (["start", "from L [mm]", "to L [mm]", "cost", "status", "evaluations", "failed cases"], starts)}


def _context(data: dict, figures: list[dict], readings: tuple = READINGS, profile_png: str | None = None) -> dict:
    regime_header = ["Case (test)", "m2 [kg]", "F2 [N]"] + [f"{r.label} {r.scene}" for r in readings]
    regime_rows = [[str(row["test"]) if row["test"] else "–", f"{row['m2']:g}", f"{row['F2']:g}"]
                   + [f"{row[r.key]['drive']}: {row[r.key]['regimes']}"
                      + ("" if row[r.key]["status"] == "finished" else f" ({row[r.key]['message']})")
                      for r in readings] for row in data["cases"]]
    statics_header = ["F2 [N]", "F1(0) [N]", "rho(0) [deg]", "breakaway F1 [N]", "cone margin, hand [N]",
                      "cone margin, module [N]", "stick holds"]
    statics_rows = [[f"{s['F2']:g}", f"{s['F1_0']:.1f}", f"{s['rho0_deg']:.3f}", f"{s['breakaway_F1']:.1f}",
                     f"{s['cone_margin_hand']:.2f}", f"{s['cone_margin_module']:.2f}", "yes" if s["sticks"] else "no"]
                    for s in data["checks"]["statics"]]
    energy_header = ["reading", "m2 [kg]", "F2 [N]", "W_in [J]", "dKE [J]", "W_in - dKE [J]",
                     "min dissipation rate [W]", "points with negative rate"]
    energy_rows = [[e["reading"], f"{e['m2']:g}", f"{e['F2']:g}", f"{e['W_in']:.4g}", f"{e['dKE']:.4g}",
                    f"{e['E_diss']:.4g}", f"{e['min_rate']:.4g}", f"{e['negative_fraction']:.1%}"]
                   for e in data["checks"]["energy_table"]]
    settings_rows = [[scene, s["method"], f"{s['rtol']:g}", f"{s['atol']:g}", f"{s['t_end']:g} s", str(s["points"]),
                      str(s["max_steps"])] for scene, s in data["settings"].items()]
    lost = data["lostmotion"]
    return {"data": data, "figures": figures, "readings": readings, "lost": lost,
            "lost_tables": lostmotion_tables(data), "profile_png": profile_png,
            "table3": table3_tables(data, readings), "regimes": (regime_header, regime_rows),
            "statics": (statics_header, statics_rows), "energy": (energy_header, energy_rows),
            "settings": (["scene", "integrator", "rtol", "atol", "t_end", "output points", "max steps"],
                         settings_rows),
            "tolerance": f"{TOLERANCE:.0%}", "generated": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
            "wall_time": wall_time_text(data["timing"]),
            "pdflatex": shutil.which("pdflatex") is not None}


def read_markdown_tables(text: str, first_header: str) -> list[list[list[str]]]:
    """Every Markdown table whose first header cell is ``first_header``: its rows, header first."""
    tables, lines = [], text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("|") and (i == 0 or not lines[i - 1].startswith("|")) \
                and [c.strip() for c in line.strip("|").split("|")][0] == first_header:
            table = []
            for row in lines[i:]:
                if not row.startswith("|"):
                    break
                cells = [c.strip() for c in row.strip().strip("|").split("|")]
                if not all(set(c) <= set("-: ") for c in cells):
                    table.append(cells)
            tables.append(table)
    return tables


def read_markdown_table(text: str, first_header: str) -> list[list[str]]:
    """The rows (header first) of the first Markdown table whose first header cell is ``first_header``."""
    tables = read_markdown_tables(text, first_header)
    if not tables:
        raise ValueError(f"no table starting with {first_header!r}")
    return tables[0]
