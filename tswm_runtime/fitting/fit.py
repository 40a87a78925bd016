"""Calibration: identify free parameters of a scene from measured peaks or time histories.

``fit(scene, measured, free)`` fits the free parameters named in ``free`` to a measured
table with scipy.optimize.least_squares (trust region reflective, inside bounds), from
several starts (Sobol or Latin hypercube points of scipy.stats.qmc inside the bounds).
The measured table and the bounds are read and checked by ``tswm_runtime.fitting.inputs``
(``read_measured``, ``parse_free``, ``FitInputError``, re-exported here); the model against
the table, its scaled residuals and the penalty of a failed case are
``tswm_runtime.fitting.problem``; the report, the misfit plot and fit.json are written by
``tswm_runtime.fitting.report``.

At the best start: the Jacobian J of the scaled residuals by central differences (one
batch call), s^2 = sum r^2 / (m - n), covariance s^2 (J^T J)^-1, standard errors,
confidence intervals with Student's t (m - n degrees of freedom) and the correlation
matrix. Identifiability notes: J^T J rank-deficient or ill-conditioned (singular values of
J with columns scaled to the bound widths), a confidence interval covering the whole
bound range, |correlation| > 0.99, starts that end at different values with equal cost.
These linearised intervals are kept as ``ci_linear``; the reported intervals ``ci`` are
profile-likelihood intervals above the noise floor of the misfit
(``tswm_runtime.fitting.profile``), which also decide whether the data determine a
parameter at all and whether the minimum sits on a jump of the cost.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from tswm_runtime.common.words import plural
from tswm_runtime.fitting import profile
from tswm_runtime.fitting.inputs import FitInputError, Measured, default_bounds, parse_free, parse_noise, read_measured
from tswm_runtime.fitting.problem import PENALTY, Problem

__all__ = ["FitInputError", "FitResult", "Measured", "PENALTY", "Start", "fit", "parse_free", "read_measured"]

MAX_STARTS = 64
MAX_GRID = 201  # misfit plot: points per axis
MAX_GRID_RUNS = 200_000  # misfit plot: grid points x cases
MAX_NFEV = 200  # residual evaluations per start (finite-difference Jacobians included)
# Run settings a fit uses unless told otherwise: tighter than a scene's, so that finite
# differences of the peaks measure the model and not the step-size control's noise.
FIT_RUN = {"rtol": 1e-9, "atol": 1e-12}
DIFF_STEP = 1e-5  # finite-difference step of the optimiser, as a fraction of the bound width
JAC_STEP = 1e-4  # step of the final (central) Jacobian, as a fraction of the bound width
ILL_CONDITIONED = 1e6  # condition number of the bound-scaled J above which a note is given
RANK_TOL = 1e-9  # singular values below RANK_TOL x the largest count as zero
EQUAL_COST = 1e-3  # starts within this relative cost of the best count as equal ...
DISTINCT = 1e-2  # ... and as a different optimum when this fraction of a bound width apart


@dataclass
class Start:
    x0: list[float]
    x: list[float]
    cost: float
    status: int
    message: str
    nfev: int
    failed_cases: int


@dataclass
class FitResult:
    """What ``fit`` found; ``to_dict`` holds every number (fit.json)."""

    scene: str
    names: list[str]
    units: list[str]
    bounds: dict
    bound_source: dict
    estimate: dict
    stderr: dict
    ci: dict  # name -> (lo, hi), the profile interval; (-inf, inf) where not determined by the data
    confidence: float
    covariance: list
    correlation: list
    cost: float
    dof: int
    s2: float
    singular_values: list
    condition: float
    rank: int
    jacobian: list
    notes: list[str]
    starts: list[Start]
    best_start: int
    cases: list[dict]
    failed: list[dict]
    measured: dict
    settings: dict
    fit_settings: dict
    provenance: dict
    misfit: dict = field(default_factory=dict)
    ci_linear: dict = field(default_factory=dict)  # name -> (lo, hi) from s^2 (J^T J)^-1; NaN where m = n
    profiles: dict = field(default_factory=dict)  # name -> profile.profile(): points, threshold, verdict
    noise: dict = field(default_factory=dict)  # stated measurement noise per quantity (SI), empty if estimated
    seconds: float = 0.0

    @property
    def success(self) -> bool:
        """A fit was found and every case ran at it."""
        return not self.failed and self.starts[self.best_start].status > 0

    def to_dict(self) -> dict:
        from dataclasses import asdict

        return _plain({**asdict(self), "success": self.success})


def _plain(obj):
    """JSON-safe: numpy to Python, non-finite floats to None (JSON has no inf/NaN)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def start_points(bounds_lo, bounds_hi, starts: int, sampler: str, seed: int) -> np.ndarray:
    """``starts`` points inside the bounds from scipy.stats.qmc (scrambled Sobol or LHS)."""
    from scipy.stats import qmc

    d = len(bounds_lo)
    if sampler == "sobol":
        engine = qmc.Sobol(d, scramble=True, seed=seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # balance warning for counts that are no power of 2
            u = engine.random(starts)
    elif sampler == "lhs":
        u = qmc.LatinHypercube(d, seed=seed).random(starts)
    else:
        raise FitInputError(f"--sampler {sampler!r}: expected sobol or lhs")
    return qmc.scale(u, bounds_lo, bounds_hi)


def _jacobian(problem: Problem, x: np.ndarray, r0: np.ndarray):
    """Central differences (second-order one-sided at a bound) of the scaled residuals, in the
    parameters' units: all points in one evaluation. Returns J (m x n), the step per parameter."""
    n = x.size
    h = JAC_STEP * problem.width
    points, plan = [], []
    for j in range(n):
        if x[j] - h[j] >= problem.lo[j] and x[j] + h[j] <= problem.hi[j]:
            offsets = (-1, 1)
        elif x[j] + 2 * h[j] <= problem.hi[j]:
            offsets = (1, 2)
        else:
            offsets = (-1, -2)
        plan.append(offsets)
        for o in offsets:
            p = x.copy()
            p[j] = x[j] + o * h[j]
            points.append(p)
    R, _, _ = problem.residuals(np.array(points))
    J = np.empty((r0.size, n))
    for j, offsets in enumerate(plan):
        a, b = R[2 * j], R[2 * j + 1]
        if offsets == (-1, 1):
            J[:, j] = (b - a) / (2 * h[j])
        else:
            sign = offsets[0]
            J[:, j] = sign * (-3 * r0 + 4 * a - b) / (2 * h[j])
    return J, h


def _statistics(problem: Problem, x: np.ndarray, r: np.ndarray, J: np.ndarray, confidence: float, stated: bool):
    """Linearised statistics; with stated noise the residuals are already in units of sigma (s^2 = 1)."""
    from scipy import stats

    m, n = J.shape
    dof = m - n
    ssr = float(r @ r)
    s2 = 1.0 if stated else ssr / dof if dof > 0 else math.nan
    Js = J * problem.width  # columns per bound width: conditioning independent of units
    U, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    smax = float(sv[0]) if sv.size else 0.0
    keep = sv > RANK_TOL * smax if smax > 0 else np.zeros_like(sv, dtype=bool)
    rank = int(keep.sum())
    cond = float(smax / sv[-1]) if sv.size and sv[-1] > 0 else math.inf
    # pseudo-inverse of Js^T Js on its range, back to the parameters' units
    inv = (Vt[keep].T / sv[keep] ** 2) @ Vt[keep]
    cov = s2 * inv * np.outer(problem.width, problem.width)
    null = Vt[~keep]
    unidentified = [problem.names[j] for j in range(n) if null.size and np.max(np.abs(null[:, j])) > 0.1]
    se = np.sqrt(np.clip(np.diag(cov), 0, None)) if dof > 0 or stated else np.full(n, math.nan)
    tq = (float(stats.norm.ppf((1 + confidence) / 2)) if stated
          else float(stats.t.ppf((1 + confidence) / 2, dof)) if dof > 0 else math.nan)
    ci = {}
    for j, name in enumerate(problem.names):
        if name in unidentified:
            se[j] = math.inf
            ci[name] = (-math.inf, math.inf)
        else:
            ci[name] = (float(x[j] - tq * se[j]), float(x[j] + tq * se[j]))
    with np.errstate(all="ignore"):
        corr = cov / np.outer(se, se)
    for j, name in enumerate(problem.names):
        if name in unidentified:
            corr[j, :] = corr[:, j] = math.nan
        corr[j, j] = 1.0
    return dict(dof=dof, s2=s2, sv=sv, rank=rank, cond=cond, cov=cov, se=se, ci=ci, corr=corr, tq=tq,
                unidentified=unidentified, null=null)


def _notes(problem, st, starts: list[Start], best: int, cases_failed) -> list[str]:
    names, n = problem.names, len(problem.names)
    notes = []
    if st["unidentified"]:
        notes.append(f"not identifiable: J^T J is rank-deficient (rank {st['rank']} of {n}); the measured "
                     f"quantities do not change with {', '.join(st['unidentified'])} near the optimum; their "
                     "confidence intervals are unbounded")
    elif st["cond"] > ILL_CONDITIONED:
        notes.append(f"poorly identifiable: J^T J is ill-conditioned (condition number of J scaled to the "
                     f"bounds {st['cond']:.3g} > {ILL_CONDITIONED:.0e}); the parameters are nearly "
                     "interchangeable in these data")
    for j, name in enumerate(names):
        lo, hi = st["ci"][name]
        if name not in st["unidentified"] and lo <= problem.lo[j] and hi >= problem.hi[j]:
            notes.append(f"not identifiable: the linearised {st.get('confidence', 0.95):.0%} interval of {name} "
                         f"[{lo:.6g}, {hi:.6g}] covers its whole bound range [{problem.lo[j]:g}, {problem.hi[j]:g}]")
    for i in range(n):
        for j in range(i + 1, n):
            c = st["corr"][i, j]
            if math.isfinite(c) and abs(c) > 0.99:
                notes.append(f"{names[i]} and {names[j]} are correlated {c:+.4f}: only a combination of them is "
                             "determined well")
    best_cost = starts[best].cost
    tol = EQUAL_COST * best_cost + 1e-12 * problem.n_residuals
    bx = np.array(starts[best].x)
    others = [k for k, s in enumerate(starts) if k != best and s.status > 0 and abs(s.cost - best_cost) <= tol
              and np.max(np.abs(np.array(s.x) - bx) / problem.width) > DISTINCT]
    if others:
        where = "; ".join(", ".join(f"{nm} = {v:.6g}" for nm, v in zip(names, starts[k].x)) for k in others[:4])
        numbers = ", ".join(str(k + 1) for k in others)
        notes.append(f"not identifiable: {'start' if len(others) == 1 else 'starts'} {numbers} "
                     f"{'ends' if len(others) == 1 else 'end'} at different values "
                     f"({where}) with the same cost as the best ({best_cost:.6g})")
    if st["dof"] <= 0 and not math.isfinite(st["s2"]):
        notes.append("as many residuals as free parameters and no stated noise: no estimate of the noise; the "
                     "intervals rest on the numerical noise floor alone")
    if cases_failed:
        notes.append(f"{plural(len(cases_failed), 'case')} did not finish at the optimum (penalty {PENALTY:g} per "
                     "residual): "
                     + "; ".join(f"{c['case']} ({c['status']})" for c in cases_failed[:5]))
    return notes


def fit(model: str | ModuleType, measured: str | Path | Measured, free: dict | list, *,
        overrides: dict | None = None, starts: int = 4, sampler: str = "sobol", seed: int = 0,
        magnitude: bool = False, confidence: float = 0.95, grid_points: int | None = None,
        progress: bool = False, misfit: bool = True, noise: dict | list | None = None,
        profile_points: int | None = None) -> FitResult:
    """Fit the free parameters ``free`` ({name: (lo, hi)} or a list of ``NAME[=LO:HI]``) of
    ``model`` to the measured table (a CSV/Parquet path or a ``Measured``).

    overrides: run settings (t_end, rtol, atol, method, max_steps, max_events; history
    also points); FIT_RUN's tolerances unless given. starts: multi-start count (qmc
    ``sampler`` 'sobol' or 'lhs', ``seed``). magnitude: compare |S1m|, |S2m|.
    grid_points: misfit grid per axis (default 41 for one parameter, 15 for two); misfit=False
    skips the grid. noise: the measurement noise per measured quantity ({quantity: sigma} in SI
    or a list of ``QUANTITY=SIGMA``; every quantity, or none and the noise is estimated from
    the residuals). profile_points: grid of each parameter's profile (default profile.POINTS). Raises FitInputError for
    inputs that cannot be used."""
    from scipy.optimize import least_squares

    from tswm_runtime.common.provenance import TSWM_VERSION as __version__
    from tswm_runtime.sweeps import chunks
    from tswm_runtime.simulation.simulate import SimulationInputError, settings
    from tswm_runtime.common import provenance
    from tswm_runtime.model.contract import load_module

    begin = time.perf_counter()
    module = model if isinstance(model, ModuleType) else load_module(model)
    if isinstance(free, (list, tuple)):
        free = parse_free(list(free), module)
    else:
        free = dict(free)
        parse_free([f"{name}=0:1" for name in free], module)  # names known (bounds checked next)
        for name, (lo, hi) in free.items():
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise FitInputError(f"--free {name}={lo}:{hi}: need finite LO < HI")
    if not 1 <= starts <= MAX_STARTS:
        raise FitInputError(f"--starts {starts}: must be in [1, {MAX_STARTS}]")
    if not 0 <= seed <= 2**63 - 1:
        raise FitInputError(f"--seed {seed}: must be an integer in [0, 2^63 - 1]")
    if not 0.5 <= confidence < 1:
        raise FitInputError(f"--confidence {confidence}: must be in [0.5, 1)")
    if sampler not in ("sobol", "lhs"):
        raise FitInputError(f"--sampler {sampler!r}: expected sobol or lhs")
    if grid_points is not None and not 2 <= grid_points <= MAX_GRID:
        raise FitInputError(f"--grid-points {grid_points}: must be in [2, {MAX_GRID}]")
    profile_points = profile.POINTS if profile_points is None else profile_points
    if not 5 <= profile_points <= MAX_GRID:
        raise FitInputError(f"--profile-points {profile_points}: must be in [5, {MAX_GRID}]")
    given = {k: v for k, v in (overrides or {}).items() if v is not None}
    try:
        run = settings(module, {**FIT_RUN, **given})
    except SimulationInputError as error:
        raise FitInputError(str(error)) from None
    if not isinstance(measured, Measured):
        measured = read_measured(measured, module, list(free), run)
    problem = Problem(module, measured, free, run, magnitude)
    sigma = parse_noise(noise, measured.quantities) if noise else {}
    if sigma:
        problem.scale = np.array([sigma[q] for q in measured.quantities])
    if problem.n_residuals < len(problem.names):
        raise FitInputError(f"--measured: {problem.n_residuals} measured values for {len(problem.names)} free "
                            "parameters; need at least as many values as parameters")
    problem.check_rules()

    X0 = start_points(problem.lo, problem.hi, starts, sampler, seed)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=starts, unit="start", desc=f"fit {module.SCENE}", leave=False)
    results: list[Start] = []
    try:
        for x0 in X0:
            u0 = (x0 - problem.lo) / problem.width

            def fun(u):
                r, _, _ = problem.residuals(problem.lo + np.clip(u, 0, 1) * problem.width)
                if bar:
                    bar.set_postfix(evaluations=problem.evaluations, refresh=False)
                return r[0]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                sol = least_squares(fun, u0, bounds=(0.0, 1.0), method="trf", diff_step=DIFF_STEP,
                                    x_scale=1.0, ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=MAX_NFEV)
            x = problem.lo + np.clip(sol.x, 0, 1) * problem.width
            r, _, status = problem.residuals(x)
            results.append(Start(x0.tolist(), x.tolist(), 0.5 * float(r[0] @ r[0]), int(sol.status),
                                 str(sol.message), int(sol.nfev), int(np.sum(status[0] != "finished"))))
            if bar:
                bar.update()
    finally:
        if bar:
            bar.close()
    ok = [k for k, s in enumerate(results) if s.status > 0] or list(range(len(results)))
    best = min(ok, key=lambda k: (results[k].failed_cases, results[k].cost))
    x = np.array(results[best].x)
    R, values, status = problem.residuals(x)
    r = R[0]
    J, h = _jacobian(problem, x, r)
    st = _statistics(problem, x, r, J, confidence, bool(sigma))
    st["confidence"] = confidence
    cases, failed = _case_table(problem, values[0], status[0])
    notes = _notes(problem, st, results, best, failed)
    profiles = {name: profile.profile(problem, x, j, points=profile_points, confidence=confidence, dof=st["dof"],
                                      stated=bool(sigma), cost_best=0.5 * float(r @ r))
                for j, name in enumerate(problem.names)}
    notes = profile.notes(profiles, st["ci"], problem.names) + notes
    units = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS))
    res = FitResult(
        scene=module.SCENE, names=problem.names, units=[units[n] for n in problem.names],
        bounds={n: (float(a), float(b)) for n, a, b in zip(problem.names, problem.lo, problem.hi)},
        bound_source={n: "scene" if default_bounds(module, n) == free[n] else "given" for n in problem.names},
        estimate=dict(zip(problem.names, x.tolist())), stderr=dict(zip(problem.names, st["se"].tolist())),
        ci={n: profile.interval(pr) for n, pr in profiles.items()}, ci_linear=st["ci"], profiles=profiles,
        noise=sigma, confidence=confidence, covariance=st["cov"].tolist(), correlation=st["corr"].tolist(),
        cost=0.5 * float(r @ r), dof=st["dof"], s2=st["s2"], singular_values=st["sv"].tolist(),
        condition=st["cond"], rank=st["rank"], jacobian=J.tolist(), notes=notes, starts=results,
        best_start=best, cases=cases, failed=failed,
        measured={"file": measured.source, "sha256": measured.sha256, "form": measured.kind,
                  "cases": len(measured.cases), "rows": int(measured.values.shape[0]), "known": measured.known,
                  "quantities": measured.quantities, "scale": dict(zip(measured.quantities, problem.scale.tolist())),
                  "compared": "|S1m|, |S2m|" if magnitude else "signed values as the sweep reports them",
                  "fixed": {n: float(v) for n, v in zip(module.PARAM_NAMES, module.PARAM_DEFAULTS)
                            if n not in measured.known and n not in problem.names}},
        settings=dict(problem.run),
        fit_settings={"starts": starts, "sampler": sampler, "seed": seed, "magnitude": magnitude,
                      "confidence": confidence, "t_quantile": st["tq"], "penalty": PENALTY,
                      "profile_points": profile_points, "noise": "stated" if sigma else "estimated",
                      "diff_step": DIFF_STEP, "jacobian_step": dict(zip(problem.names, h.tolist())),
                      "max_nfev": MAX_NFEV, "method": "scipy.optimize.least_squares trf in bounds",
                      "cost": "0.5 sum ((model - measured) / scale)^2"},
        provenance={"scene_digest": getattr(module, "SCENE_DIGEST", None), "model_digest": chunks.model_digest(module),
                    "runtime_version": __version__, "runtime_digest": chunks.runtime_digest(),
                    "versions": provenance.package_versions(("numpy", "scipy", "numba", "pandas", "pyarrow",
                                                             "matplotlib")),
                    "machine": provenance.machine()})
    if misfit:
        res.misfit = misfit_grid(problem, x, grid_points, progress)
    res.fit_settings["model_runs"] = problem.runs
    res.seconds = time.perf_counter() - begin
    return res


def _case_table(problem: Problem, values: np.ndarray, status: np.ndarray):
    """Per case: parameters, status, per quantity measured, model, absolute and relative residual
    (history: RMS over the case's samples)."""
    m = problem.measured
    cases, failed = [], []
    for c, label in enumerate(m.cases):
        rows = np.flatnonzero(m.row_case == c)
        entry = {"case": label, "status": str(status[c]), "known": dict(zip(m.known, m.params[c].tolist())),
                 "samples": int(rows.size), "quantities": {}}
        for j, q in enumerate(m.quantities):
            meas, mod = m.values[rows, j], values[rows, j]
            if m.kind == "peaks":
                d = float(mod[0] - meas[0])
                entry["quantities"][q] = {"measured": float(meas[0]), "model": float(mod[0]), "residual": d,
                                          "relative": d / abs(meas[0]) if meas[0] != 0 else math.nan}
            else:
                d = mod - meas
                rms = float(np.sqrt(np.mean(d ** 2)))
                ref = float(np.sqrt(np.mean(meas ** 2)))
                entry["quantities"][q] = {"rms_measured": ref, "rms_residual": rms,
                                          "max_residual": float(np.max(np.abs(d))),
                                          "relative": rms / ref if ref > 0 else math.nan}
        cases.append(entry)
        if status[c] != "finished":
            failed.append({"case": label, "status": str(status[c])})
    return cases, failed


def misfit_grid(problem: Problem, x: np.ndarray, points: int | None, progress: bool = False) -> dict:
    """The cost over one parameter (its bounds; others at the optimum) or over the first two
    (a grid over their bounds): axes, cost (NaN never: failed cases carry the penalty)."""
    n = min(len(problem.names), 2)
    points = points or (41 if n == 1 else 15)
    runs_per_point = len(problem.measured.cases)
    while points > 2 and points ** n * runs_per_point > MAX_GRID_RUNS:
        points -= 1
    axes = [np.linspace(problem.lo[j], problem.hi[j], points) for j in range(n)]
    if n == 1:  # the optimum itself on the curve
        axes[0] = np.unique(np.append(axes[0], x[0]))
    mesh = np.meshgrid(*axes, indexing="ij")
    X = np.tile(x, (mesh[0].size, 1))
    for j in range(n):
        X[:, j] = mesh[j].ravel()
    chunk = max(1, 4096 // max(runs_per_point, 1)) if problem.measured.kind == "peaks" else 1
    cost = np.empty(X.shape[0])
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=X.shape[0], unit="point", desc="misfit grid", leave=False)
    try:
        for a in range(0, X.shape[0], chunk):
            R, _, _ = problem.residuals(X[a:a + chunk])
            cost[a:a + chunk] = 0.5 * np.sum(R ** 2, axis=1)
            if bar:
                bar.update(min(chunk, X.shape[0] - a))
    finally:
        if bar:
            bar.close()
    return {"names": problem.names[:n], "axes": [a.tolist() for a in axes],
            "cost": cost.reshape(mesh[0].shape).tolist(), "at": x.tolist(),
            "others_at_optimum": problem.names[n:]}
