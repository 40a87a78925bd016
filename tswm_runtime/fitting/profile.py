"""Profile-likelihood intervals of ``tswm fit`` and the noise floor of its misfit.

The profile of a parameter is the cost on a grid over its bounds with the other free
parameters re-optimised at each point (least_squares from the neighbouring point's optimum,
walking outward from the estimate). A point lies inside the interval when its cost is within
``threshold`` of the smallest cost found, with threshold = statistical part + noise floor:

- statistical part, from the data's noise: stated (the residuals are then scaled by the stated
  sigma, so the cost is chi^2 / 2) -> chi2_1(C) / 2; estimated (s^2 = 2 C_min / dof) ->
  C_min F_{1,dof}(C) / dof (Beale's region); without either (m = n) none;
- numerical floor, from the model's own error at the fit's tolerances: every profile point is
  run again at TIGHTER times tighter rtol and atol (no tighter than simulate accepts),
  e = r - r_tight, and a cost difference up to SAFETY x max(|r| |e| + |e|^2 / 2) over the
  points may be the integrator's (points where the two runs take different mode sequences or
  end with different statuses are left out of the maximum and counted).

Each end of the interval is refined by bisection between the last grid point inside and the
first outside. Verdicts: 'determined' (the interval ends inside the bounds on both sides),
'reaches a bound', 'not determined' (every grid point within the threshold: the data do not
say where in its bounds the parameter lies). An end where a case's mode sequence differs on
the two sides of the bisection is an edge (the cost jumps there); an estimate at such an
edge is a minimum on a discontinuity, not of a smooth cost.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from tswm_runtime.fitting.problem import Problem

POINTS = 21          # profile grid points per parameter (plus the estimate)
TIGHTER = 100.0      # the noise floor's reference run: rtol and atol divided by this
SAFETY = 10.0        # the floor: SAFETY x the error bound of the cost estimated from the tighter run
BISECT = 12          # bisection steps at each end of the interval
INNER_NFEV = 60      # evaluations of each re-optimisation of the other parameters
INNER_STEP = 1e-5    # its finite-difference step, as a fraction of the bound width


def statistical_delta(cost_min: float, dof: int, confidence: float, stated: bool) -> tuple[float, str]:
    """The cost rise that the data's noise allows at this confidence, and where the noise comes from."""
    from scipy import stats

    if stated:
        return 0.5 * float(stats.chi2.ppf(confidence, 1)), "stated"
    if dof > 0:
        return cost_min * float(stats.f.ppf(confidence, 1, dof)) / dof, "estimated from the residuals"
    return 0.0, "none (as many values as parameters)"


class _Scan:
    """Profile points of parameter j: the others re-optimised at each value of it."""

    def __init__(self, problem: Problem, j: int):
        self.problem, self.j = problem, j
        self.others = [k for k in range(len(problem.names)) if k != j]

    def optimise(self, value: float, start: np.ndarray) -> np.ndarray:
        x = start.copy()
        x[self.j] = value
        if not self.others:
            return x
        from scipy.optimize import least_squares

        p, o = self.problem, self.others
        lo, w = p.lo[o], p.width[o]

        def fun(u):
            x[o] = lo + np.clip(u, 0, 1) * w
            return p.residuals(x)[0][0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            sol = least_squares(fun, np.clip((start[o] - lo) / w, 0, 1), bounds=(0.0, 1.0), method="trf",
                                diff_step=INNER_STEP, ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=INNER_NFEV)
        x[o] = lo + np.clip(sol.x, 0, 1) * w
        return x.copy()

    def grid(self, x_best: np.ndarray, points: int) -> np.ndarray:
        """The profile's points (rows of all free values), the estimate among them, sorted by value."""
        p, j = self.problem, self.j
        values = np.unique(np.append(np.linspace(p.lo[j], p.hi[j], points), x_best[j]))
        c = int(np.searchsorted(values, x_best[j]))
        X = np.tile(x_best, (values.size, 1))
        X[:, j] = values
        if self.others:
            for side in (range(c + 1, values.size), range(c - 1, -1, -1)):
                start = x_best
                for i in side:
                    X[i] = start = self.optimise(values[i], start)
        return X


def _cost(R: np.ndarray) -> np.ndarray:
    return 0.5 * np.sum(np.atleast_2d(R) ** 2, axis=1)


def numerical_floor(problem: Problem, X: np.ndarray, R: np.ndarray, modes: np.ndarray, status: np.ndarray) -> dict:
    """The noise floor of the cost at points X (residuals R, mode sequences ``modes``, statuses)
    from a rerun at TIGHTER times tighter tolerances."""
    tight = problem.tightened(TIGHTER)
    Rt, _, status_t = tight.residuals(X)
    problem.runs += tight.runs
    same = np.all(tight.last_modes == modes, axis=1) & np.all(status_t == status, axis=1)
    e = np.linalg.norm(R - Rt, axis=1)
    bound = np.linalg.norm(R, axis=1) * e + 0.5 * e ** 2
    kept = bound[same]
    return {"floor": SAFETY * float(kept.max()) if kept.size else 0.0,
            "largest_residual_error": float(e[same].max()) if kept.size else math.nan,
            "points": int(X.shape[0]), "different_modes": int((~same).sum()),
            "rtol": tight.run["rtol"], "atol": tight.run["atol"], "safety": SAFETY}


def profile(problem: Problem, x_best: np.ndarray, j: int, *, points: int, confidence: float, dof: int,
            stated: bool, cost_best: float) -> dict:
    """The profile of parameter j around the estimate x_best: points, costs, threshold, interval, verdict."""
    scan = _Scan(problem, j)
    X = scan.grid(x_best, points)
    R, _, status = problem.residuals(X)
    modes = problem.last_modes.copy()
    cost = _cost(R)
    noise = numerical_floor(problem, X, R, modes, status)
    cost_min = float(min(cost.min(), cost_best))
    delta, source = statistical_delta(cost_min, dof, confidence, stated)
    limit = cost_min + delta + noise["floor"]
    values = X[:, j]
    inside = cost <= limit
    k = int(np.argmin(cost))
    a, b = k, k
    while a > 0 and inside[a - 1]:
        a -= 1
    while b < values.size - 1 and inside[b + 1]:
        b += 1
    lower = _end(scan, X, cost, modes, (a, a - 1), limit) if a > 0 else None
    upper = _end(scan, X, cost, modes, (b, b + 1), limit) if b < values.size - 1 else None
    lo = lower["at"] if lower else float(problem.lo[j])
    hi = upper["at"] if upper else float(problem.hi[j])
    if inside.all():
        verdict = "not determined"
    elif lower and upper:
        verdict = "determined"
    else:
        verdict = "reaches a bound"
    spacing = float(problem.width[j]) / (points - 1)
    at_edge = [e for e in (lower, upper) if e and e["edge"] and abs(e["at"] - x_best[j]) <= spacing]
    return {"values": values.tolist(), "cost": cost.tolist(), "points": X.tolist(), "modes": modes.tolist(),
            "failed": np.sum(status != "finished", axis=1).tolist(), "cost_min": cost_min,
            "at_min": X[k].tolist(), "below_fit": bool(cost[k] < cost_best - max(noise["floor"], 1e-12 * cost_best)),
            "statistical": delta, "noise": source, "numerical": noise,
            "threshold": limit, "confidence": confidence, "lo": lo, "hi": hi, "lower": lower, "upper": upper,
            "verdict": verdict, "range": [float(values[inside].min()), float(values[inside].max())],
            "contiguous": bool(inside[a:b + 1].sum() == inside.sum()),
            "minimum_on_edge": at_edge[0] if at_edge else None}


def _end(scan: _Scan, X: np.ndarray, cost: np.ndarray, modes: np.ndarray, pair: tuple[int, int],
         limit: float) -> dict:
    """Bisect between an inside point and an outside one; the end, its costs and whether a case's
    mode sequence changes across it (an edge of the cost)."""
    problem, j = scan.problem, scan.j
    i_in, i_out = pair
    x_in, x_out = X[i_in].copy(), X[i_out].copy()
    m_in, m_out = modes[i_in], modes[i_out]
    c_in, c_out = float(cost[i_in]), float(cost[i_out])
    for _ in range(BISECT):
        x = scan.optimise(0.5 * (x_in[j] + x_out[j]), x_in)
        R, _, _ = problem.residuals(x)
        c = float(_cost(R)[0])
        if c <= limit:
            x_in, m_in, c_in = x, problem.last_modes[0].copy(), c
        else:
            x_out, m_out, c_out = x, problem.last_modes[0].copy(), c
    changed = [(case, str(a), str(b)) for case, a, b in zip(problem.measured.cases, m_in, m_out) if a != b]
    return {"at": float(0.5 * (x_in[j] + x_out[j])), "inside": float(x_in[j]), "outside": float(x_out[j]),
            "cost_inside": c_in, "cost_outside": c_out, "edge": bool(changed),
            "changes": [{"case": c, "inside": a, "outside": b} for c, a, b in changed]}


def interval(prof: dict) -> tuple[float, float]:
    """The reported interval: the profile's ends, unbounded where the data do not determine it."""
    if prof["verdict"] == "not determined":
        return (-math.inf, math.inf)
    return (prof["lo"], prof["hi"])


def notes(profiles: dict, linear: dict, names: list[str]) -> list[str]:
    """What the profiles say, one note per finding, with their numbers."""
    out = []
    for name in names:
        p = profiles[name]
        level = f"{p['confidence']:.0%}"
        floor = (f"threshold {p['threshold']:.4g} = minimum {p['cost_min']:.4g} + noise {p['statistical']:.3g} "
                 f"({p['noise']}) + numerical floor {p['numerical']['floor']:.3g}")
        if p["below_fit"]:
            out.append(f"{name}: the profile finds a lower cost ({p['cost_min']:.6g} at "
                       f"{', '.join(f'{v:.6g}' for v in p['at_min'])}) than the fit's best start: the starts missed "
                       "it; the interval is taken around it")
        if p["verdict"] == "not determined":
            a, b = linear[name]
            out.append(f"{name} is not determined by these data: its profile stays within the noise floor over its "
                       f"whole bounds ({floor}); it could take any value in [{p['range'][0]:.6g}, "
                       f"{p['range'][1]:.6g}]" + (f"; the linearised interval [{a:.6g}, {b:.6g}] measures the "
                                                 "integrator's noise, not the data" if math.isfinite(a) else ""))
            continue
        if p["verdict"] == "reaches a bound":
            out.append(f"{name}: its {level} profile interval [{p['lo']:.6g}, {p['hi']:.6g}] reaches a bound; the "
                       f"data bound it on one side only ({floor})")
        if not p["contiguous"]:
            out.append(f"{name}: the profile comes within the threshold again away from the interval; the data allow "
                       f"{name} anywhere in [{p['range'][0]:.6g}, {p['range'][1]:.6g}]")
        edge = p["minimum_on_edge"]
        for end in (p["lower"], p["upper"]):
            if not (end and end["edge"]):
                continue
            change = "; ".join(f"case {c['case']}: {c['inside']} -> {c['outside']}" for c in end["changes"][:3])
            what = (f"{name}: the minimum sits on a discontinuity at {name} = {end['at']:.6g}" if end is edge else
                    f"{name}: the interval's end {end['at']:.6g} is a jump of the cost")
            out.append(f"{what}: the mode sequence changes there ({change}), the cost jumps from "
                       f"{end['cost_inside']:.4g} to {end['cost_outside']:.4g}"
                       + ("; the estimate is that edge, not a minimum of a smooth cost, and the linearised interval "
                          "means nothing there" if end is edge else ""))
        if p["numerical"]["different_modes"]:
            out.append(f"{name}: at {p['numerical']['different_modes']} profile point(s) the {TIGHTER:g}x tighter run "
                       "takes another mode sequence or ends otherwise (a switch within the tolerance); they are left "
                       "out of the floor")
    return out
