"""The paper report's fourth reading: lost motion, its size L fitted to Table 3.

Scene ``paper-lostmotion``: the paper's gear whose valve load acts only from the travel
x2 = L on (the drive nut turns freely over L before it picks up the stem: the "hammer
blow" of motor-operated valves). The paper states no such travel, so L is the unknown:
``tswm fit`` (``tswm_runtime.fitting.fit.fit``) chooses the one L that brings the peaks S1m
and S2m of Table 3's six tests closest to the printed ones. The reading's cells are then
``simulate()`` runs at that L, like the other readings' cells. A fitted parameter makes
the model match the table by construction: a fit, not a reproduction.

Which columns: S1m and S2m, the measured peaks. KD1 and KD2 are those peaks divided by
the fixed Ft1 and Ft2 (eq. 10): fitting them as well would count each peak twice, and the
printed KD2 of test 5 (1.36) contradicts its own S2m (12100 / 8303.7 = 1.46). The KD
columns are still computed and shown with their residuals.

Bounds: L in [L_MIN, L_MAX] of x2, the wheel's pitch-line travel (R2 = d2/2 = 80 mm, so
1 mm of x2 is 0.716 deg of wheel rotation; the stem's own travel would need the stem
thread's lead, which the paper does not give). L -> 0 is reading (a), the load from rest;
the free run-up of the paper's drive reaches the motor's no-load speed at x2 of about
30 mm, and from there on every L is reading (c), run up then load. The bounds span both
ends and the physically plausible free turn of a drive sleeve, a fraction of a turn
(0.5 mm to 50 mm of x2 = 0.36 to 36 deg).
"""
from __future__ import annotations

import base64
import csv
import io
import math
from pathlib import Path

import numpy as np

from tswm_runtime.paper.data import TABLE3_PRINTED
from tswm_runtime.paper.plan import SCENES
from tswm_common.files import write_atomic

SCENE = SCENES["lostmotion"]
FREE = "load_at1"             # the scene's name for L
L_MIN, L_MAX = 0.5e-3, 50e-3  # m of x2 (see the module docstring)
FITTED = ("S1m", "S2m")       # the columns the fit compares (see the module docstring)
STARTS = 4                    # multi-start of least_squares (Sobol, seed SEED)
SEED = 0
GRID = 199                    # misfit grid points over the bounds (plus the optimum)
PROFILE = 41                  # profile points over the bounds (plus the optimum; ends bisected)
CONFIDENCE = 0.95
FLAT = 1e-3                   # "flat": the cost within 0.1 % of its minimum
R2 = 0.080                    # m, d2 / 2 (paper: d2 = 160 mm)
DIRECTORY = "lostmotion"      # the fit's own report, beside the paper report
TITLE = ("consistent derivation with lost motion: F2 acts from x2 = L on, one L for all tests fitted to "
         "Table 3's S1m and S2m")


def params(L: float):
    """The scene's free values for a case (m2, F2) at lost motion L (F2_1: the load once picked up)."""
    return lambda m2, F2: {"m2": m2, "F2_1": F2, FREE: L}


def measured_csv() -> str:
    """Table 3's six tests as the fit's measured table: case, known m2 and F2_1, S1m, S2m."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["case", "m2", "F2_1", *FITTED])
    for c in TABLE3_PRINTED:
        w.writerow([f"test{c.test}", repr(c.m2), repr(c.F2), *(repr(getattr(c, q)) for q in FITTED)])
    return out.getvalue()


def profile_interval(res) -> dict:
    """The fit's profile of L (``tswm_runtime.fitting.profile``: the cost over L on PROFILE points
    plus bisection at the ends, threshold = minimum + noise estimated from the residuals, C_min
    F_{1,dof}(C) / dof, + the numerical floor) in the terms the report reads, with the misfit
    grid's flat range (cost within FLAT of its minimum) beside it."""
    p = res.profiles[FREE]
    L, cost = np.asarray(p["values"], dtype=float), np.asarray(p["cost"], dtype=float)
    grid_L = np.asarray(res.misfit["axes"][0], dtype=float)
    grid_cost = np.asarray(res.misfit["cost"], dtype=float)
    best = min(p["cost_min"], float(grid_cost.min()))
    flat = grid_L[grid_cost <= best * (1 + FLAT)]
    lower, upper, edge = p["lower"], p["upper"], p["minimum_on_edge"]
    k = int(np.argmin(grid_cost))
    return {"confidence": p["confidence"], "dof": res.dof, "cost_min": p["cost_min"], "noise": p["statistical"],
            "numerical_floor": p["numerical"]["floor"], "threshold": p["threshold"], "lo": p["lo"], "hi": p["hi"],
            "verdict": p["verdict"], "contiguous": p["contiguous"], "points": len(L),
            "minimum_on_edge": edge is not None, "edge_changes": edge["changes"] if edge else [],
            "below": lower["outside"] if lower else None, "cost_below": lower["cost_outside"] if lower else None,
            "above": upper["outside"] if upper else None, "cost_above": upper["cost_outside"] if upper else None,
            "flat_within": FLAT, "flat_lo": float(flat.min()), "flat_hi": float(flat.max()),
            "cost_at_L_max": float(cost[-1]), "cost_at_L_min": float(cost[0]),
            "fit_cost": float(res.cost), "grid_best_cost": float(min(grid_cost[k], cost.min())),
            "grid_best_L": float(grid_L[k] if grid_cost[k] <= cost.min() else L[int(cost.argmin())])}


def jump(res) -> dict:
    """Whether the fit's Jacobian is dominated by one residual (a jump across the difference
    step) rather than the smooth slope of the data: the largest |J| entry against the others."""
    J = np.abs(np.asarray(res.jacobian, dtype=float)[:, 0])
    quantities = res.measured["quantities"]
    k = int(np.argmax(J))
    top_case = k // len(quantities)
    others = [J[i] for i in range(J.size) if i // len(quantities) != top_case]
    top, rest = float(J[k]), float(max(others, default=0.0))
    case = res.cases[top_case]["case"]
    return {"largest": top, "second": rest, "ratio": top / rest if rest > 0 else math.inf,
            "case": case, "quantity": quantities[k % len(quantities)],
            "step": res.fit_settings["jacobian_step"][FREE], "dominated": bool(rest == 0 or top > 100 * rest)}


def free_runup(masses=(100.0, 200.0)) -> list[dict]:
    """Where the unloaded run-up passes the motor's breakdown speed Vmax and reaches 99 % of its
    no-load speed V0, in x2 and t (simulate with the load beyond reach): the scale of L."""
    from tswm_runtime.simulation.simulate import simulate
    from tswm_runtime.model.contract import load_module

    fixed = load_module(SCENE).FIXED
    vmax, v0 = float(fixed["Vmax"]), float(fixed["V0"])
    out = []
    for m2 in masses:
        r = simulate(SCENE, {"m2": m2, "F2_1": 0.0, FREE: 10.0}, t_end=0.3, points=30001)
        row = {"m2": m2}
        for key, v in (("Vmax", vmax), ("V0_99", 0.99 * v0)):
            k = int(np.argmax(r.v1 >= v))
            row[key] = {"v1": v, "t": float(r.t[k]), "x2": float(r.x2[k])}
        out.append(row)
    return out


def notes(lost: dict) -> list[str]:
    """What the fit says about how well Table 3 determines L, with its numbers: the verdict first."""
    prof, jp, mm = lost["profile"], lost["jump"], 1e3
    lo, hi = lost["ci_linear"]
    out = []
    level = f"{prof['confidence']:.0%}"
    interval = f"{prof['lo'] * mm:.2f}-{prof['hi'] * mm:.2f} mm"
    if prof["minimum_on_edge"]:
        change = "; ".join(f"{c['case']} goes from {c['inside']} to {c['outside']}" for c in prof["edge_changes"])
        out.append(f"Verdict: the fitted L = {lost['L_mm']:.3f} mm is an edge, not a minimum: just below it "
                   f"({prof['below'] * mm:.4f} mm) the mode sequence changes ({change}) and the cost jumps from "
                   f"{prof['cost_min']:.4g} to {prof['cost_below']:.4g}. Table 3 puts L in the {level} profile "
                   f"interval {interval}, whose lower end is that edge.")
    elif prof["verdict"] == "not determined":
        out.append(f"Verdict: Table 3 does not determine L: its profile stays within the noise over the whole "
                   f"bounds {lost['bounds'][0] * mm:g}-{lost['bounds'][1] * mm:g} mm.")
    else:
        out.append(f"Verdict: L = {lost['L_mm']:.3f} mm, {level} profile interval {interval} ({prof['verdict']}).")
    out.append(f"Profile interval ({level}): the L whose cost stays below the threshold {prof['threshold']:.4g} = "
               f"minimum {prof['cost_min']:.4g} + noise {prof['noise']:.4g} (estimated from the residuals: cost_min "
               f"F(1, {prof['dof']}) / {prof['dof']}) + numerical floor {prof['numerical_floor']:.3g} (the "
               f"integrator's error at the fit's tolerances), on {prof['points']} profile points with both ends "
               "bisected" + ("" if prof["contiguous"] else "; not contiguous: the cost comes below the threshold "
                             "again away from the interval") + "; the profile is shown in lostmotion/profile.png.")
    if jp["dominated"]:
        out.append(f"The fit's linearised {level} interval, {lo * mm:.4f}-{hi * mm:.4f} mm "
                   f"(standard error {lost['stderr'] * 1e6:.3g} µm), is no measure of precision here: its Jacobian is "
                   f"dominated by one case, {jp['case']} ({jp['quantity']}: {jp['largest']:.3g} per m of L against "
                   f"at most {jp['second']:.3g} for the other cases), which jumps across the difference step "
                   f"({jp['step'] * 1e6:.3g} µm) because L sits where that case stops stalling.")
    else:
        out.append(f"The fit's linearised {level} interval: {lo * mm:.4f}-{hi * mm:.4f} mm "
                   f"(standard error {lost['stderr'] * mm:.3g} mm).")
    out.append(f"The cost stays within {prof['flat_within']:.1%} of its minimum from {prof['flat_lo'] * mm:.2f} to "
               f"{prof['flat_hi'] * mm:.2f} mm (misfit grid): there the load is picked up before the motor reaches "
               "its breakdown speed in every test and the peaks hardly change with L, so Table 3 bounds L to an "
               "interval rather than determining it.")
    out.append(f"At the bounds the cost is {prof['cost_at_L_min']:.4g} (L = {lost['bounds'][0] * mm:g} mm, close to "
               f"reading (a): the load almost from rest) and {prof['cost_at_L_max']:.4g} (L = "
               f"{lost['bounds'][1] * mm:g} mm, past the free run-up: reading (c)).")
    out += [f"tswm fit: {n}" for n in lost["fit"]["notes"]]
    return out


def fit_table3(out_dir: Path, progress: bool = False) -> dict:
    """Fit L to Table 3 with ``tswm fit`` on the batch kernel; write the fit's own report into
    out_dir/lostmotion (measured table, fit-report.md, fit.json, misfit.png, profile.png). Returns the fit's
    numbers for the paper report (``fit``: FitResult.to_dict(), every number)."""
    from tswm_runtime.fitting.fit import fit
    from tswm_runtime.fitting.report import write_outputs

    directory = Path(out_dir) / DIRECTORY
    table = write_atomic(directory / "table3-measured.csv", measured_csv())
    res = fit(SCENE, table, {FREE: (L_MIN, L_MAX)}, starts=STARTS, seed=SEED, confidence=CONFIDENCE,
              grid_points=GRID, profile_points=PROFILE, progress=progress)
    files = write_outputs(res, directory)
    L = float(res.estimate[FREE])
    png = (directory / "profile.png").read_bytes() if (directory / "profile.png").exists() else None
    out = {
        "scene": SCENE, "free": FREE, "L": L, "L_mm": L * 1e3, "wheel_deg": math.degrees(L / R2),
        "bounds": [L_MIN, L_MAX], "fitted_columns": list(FITTED), "starts": STARTS, "seed": SEED,
        "ci_linear": list(res.ci_linear[FREE]), "stderr": res.stderr[FREE], "cost": res.cost, "dof": res.dof,
        "success": res.success, "seconds": res.seconds,
        "profile": profile_interval(res), "jump": jump(res),
        "files": [str(Path(DIRECTORY) / p.name) for p in [table, *files]],
        "profile_png": None if png is None else base64.b64encode(png).decode("ascii"),
        "fit": res.to_dict(),
    }
    out["runup"] = free_runup()
    out["notes"] = notes(out)
    return out
