"""Calibration: identify free parameters of a scene from measured peaks or time histories.

``fit(scene, measured, free)`` fits the free parameters named in ``free`` to a measured
table with scipy.optimize.least_squares (trust region reflective, inside bounds), from
several starts (Sobol or Latin hypercube points of scipy.stats.qmc inside the bounds).

The measured table (CSV or Parquet, ``read_measured``) comes in one of two forms:

peaks     one row per measured case: columns naming free parameters *known* per case
          (e.g. m2, F2_after), an optional ``case`` label, and measured quantities among
          S1m, S2m, KD1, KD2 as the sweep reports them (S1m, S2m signed: the value of S1
          (S2) where |S1| (|S2|) is largest; KD >= 0). ``magnitude=True`` compares |S1m|,
          |S2m| instead. The model runs on the jitted batch (``sweep.run_cases``: all
          cases of all evaluation points in one parallel call).
history   a column ``t`` [s]: one row per sample, an optional ``case`` label (rows of one
          case share it, and its known parameters must be equal), measured quantities
          among S1, S2 [N] and v1 [m/s]. The model is ``simulate()`` per case, read at
          those times: v1 by the Result's Hermite interpolation (``Result.sol``), S1 and
          S2 linearly between output points within a phase (never across an event).

Residuals are scaled per quantity: r = (model - measured) / scale_q with scale_q the
root mean square of the measured values of q (1 where they are all 0), so quantities of
different units weigh alike; the cost is 0.5 sum r^2 (scipy's). A case whose run does not
finish (status other than 'finished', or a non-finite value) contributes the finite
penalty PENALTY to each of its residuals and is listed as failed; it is never compared.

At the best start: the Jacobian J of the scaled residuals by central differences (one
batch call), s^2 = sum r^2 / (m - n), covariance s^2 (J^T J)^-1, standard errors,
confidence intervals with Student's t (m - n degrees of freedom) and the correlation
matrix. Identifiability notes: J^T J rank-deficient or ill-conditioned (singular values of
J with columns scaled to the bound widths), a confidence interval covering the whole
bound range, |correlation| > 0.99, starts that end at different values with equal cost.
"""
from __future__ import annotations

import hashlib
import io
import json
import math
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from tswm_runtime.model import checks

PEAK_QUANTITIES = ("S1m", "S2m", "KD1", "KD2")
HISTORY_QUANTITIES = ("S1", "S2", "v1")
UNITS = {"S1m": "N", "S2m": "N", "KD1": "", "KD2": "", "S1": "N", "S2": "N", "v1": "m/s"}
CASE, TIME = "case", "t"
# Size bounds (docs/promises.md): the measured file is untrusted input.
MAX_FILE_BYTES = 64 * 2**20
MAX_UNPACKED_BYTES = 256 * 2**20  # Parquet: uncompressed size from its metadata
MAX_COLUMNS = 64
MAX_NAME = 64  # characters of a column name
MAX_CASES = 10_000  # peak cases (every evaluation runs all of them)
MAX_HISTORY_ROWS = 100_000
MAX_HISTORY_CASES = 200
MAX_FREE = 8
MAX_STARTS = 64
MAX_GRID = 201  # misfit plot: points per axis
MAX_GRID_RUNS = 200_000  # misfit plot: grid points x cases
MAX_NFEV = 200  # residual evaluations per start (finite-difference Jacobians included)
PENALTY = 10.0  # scaled residual of a failed case (10 x the quantity's RMS)
CASE_ID = re.compile(r"[A-Za-z0-9_.+\-]{1,40}")
# Run settings a fit uses unless told otherwise: tighter than a scene's, so that finite
# differences of the peaks measure the model and not the step-size control's noise.
FIT_RUN = {"rtol": 1e-9, "atol": 1e-12}
DIFF_STEP = 1e-5  # finite-difference step of the optimiser, as a fraction of the bound width
JAC_STEP = 1e-4  # step of the final (central) Jacobian, as a fraction of the bound width
ILL_CONDITIONED = 1e6  # condition number of the bound-scaled J above which a note is given
RANK_TOL = 1e-9  # singular values below RANK_TOL x the largest count as zero
EQUAL_COST = 1e-3  # starts within this relative cost of the best count as equal ...
DISTINCT = 1e-2  # ... and as a different optimum when this fraction of a bound width apart


class FitInputError(ValueError):
    """A fit input that cannot be used; the message names it (exit status 2)."""


# ----------------------------------------------------------------------------- inputs

@dataclass
class Measured:
    """A measured table, validated. ``params``: cases x known; ``values``: rows x quantities;
    ``row_case``: each row's case index (peaks: row = case); ``t``: sample times (history)."""

    kind: str  # 'peaks' or 'history'
    source: str
    sha256: str
    known: list[str]
    quantities: list[str]
    cases: list[str]
    params: np.ndarray
    values: np.ndarray
    row_case: np.ndarray
    t: np.ndarray | None = None


def _show(name) -> str:
    text = str(name)
    return repr(text if len(text) <= MAX_NAME else text[:MAX_NAME] + "...")


def _read_table(path: str | Path):
    """The file as a DataFrame of strings/numbers, size-checked before it is parsed."""
    import pandas as pd

    p = Path(path)
    where = f"--measured {str(path)[:200]}"
    if not p.is_file():
        raise FitInputError(f"{where}: no such file")
    size = p.stat().st_size
    if size == 0:
        raise FitInputError(f"{where}: the file is empty")
    if size > MAX_FILE_BYTES:
        raise FitInputError(f"{where}: {size / 2**20:.1f} MiB, more than the {MAX_FILE_BYTES // 2**20} MiB "
                            "tswm reads")
    data = p.read_bytes()
    suffix = p.suffix.lower()
    if suffix == ".csv":
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as error:
            raise FitInputError(f"{where}: not UTF-8 text (byte {error.start})") from None
        try:
            frame = pd.read_csv(io.StringIO(text), dtype=str, nrows=MAX_HISTORY_ROWS + 1, engine="c",
                                skipinitialspace=True)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as error:
            raise FitInputError(f"{where}: not a readable CSV table ({str(error).splitlines()[0][:200]})") from None
    elif suffix in (".parquet", ".pq"):
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            meta = pq.ParquetFile(io.BytesIO(data)).metadata
            if meta.num_columns > MAX_COLUMNS:
                raise FitInputError(f"{where}: {meta.num_columns} columns, more than {MAX_COLUMNS}")
            if meta.num_rows > MAX_HISTORY_ROWS:
                raise FitInputError(f"{where}: {meta.num_rows} rows, more than {MAX_HISTORY_ROWS}")
            unpacked = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
            if unpacked > MAX_UNPACKED_BYTES:
                raise FitInputError(f"{where}: {unpacked / 2**20:.0f} MiB uncompressed, more than the "
                                    f"{MAX_UNPACKED_BYTES // 2**20} MiB tswm reads")
            frame = pq.read_table(io.BytesIO(data)).to_pandas()
        except FitInputError:
            raise
        except (pa.ArrowException, OSError, ValueError, TypeError) as error:
            raise FitInputError(f"{where}: not a readable Parquet file ({str(error)[:200]})") from None
    else:
        raise FitInputError(f"{where}: expected a .csv or .parquet file")
    if frame.shape[1] > MAX_COLUMNS:
        raise FitInputError(f"{where}: {frame.shape[1]} columns, more than {MAX_COLUMNS}")
    if len(frame) > MAX_HISTORY_ROWS:
        raise FitInputError(f"{where}: more than {MAX_HISTORY_ROWS} rows")
    names = [c for c in frame.columns]
    for name in names:
        if not isinstance(name, str):
            raise FitInputError(f"{where}: column name {_show(name)} is not text")
    if len(set(names)) != len(names):
        raise FitInputError(f"{where}: a column name appears twice")
    return frame, hashlib.sha256(data).hexdigest()


def _numbers(frame, name: str, where: str) -> np.ndarray:
    """Column ``name`` as finite floats; the first bad cell is named (data row, 1-based)."""
    import pandas as pd

    column = frame[name]
    values = pd.to_numeric(column, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        row = int(bad[0])
        raw = column.iloc[row]
        if raw is None or (isinstance(raw, float) and math.isnan(raw)):
            why = "missing (empty or NaN)"
        elif isinstance(raw, (int, float, np.floating)):
            why = f"{float(raw)!r} is not finite"
        else:
            why = f"{_show(raw)} is not a finite number"
        raise FitInputError(f"{where}: column {name!r}, data row {row + 1}: {why}")
    return values


def read_measured(path: str | Path, module: ModuleType, free: list[str], run: dict | None = None) -> Measured:
    """Read and validate a measured table for ``module`` with ``free`` parameters to fit."""
    frame, digest = _read_table(path)
    where = f"--measured {str(path)[:200]}"
    if len(frame) == 0:
        raise FitInputError(f"{where}: no rows (one row per measured case or sample)")
    columns = list(frame.columns)
    history = TIME in columns
    allowed_q = HISTORY_QUANTITIES if history else PEAK_QUANTITIES
    other_q = PEAK_QUANTITIES if history else HISTORY_QUANTITIES
    known, quantities = [], []
    for name in columns:
        if name in (CASE, TIME):
            continue
        if name in free:
            raise FitInputError(f"{where}: column {name!r} is also given as --free {name}: a parameter is either "
                                "known per case (a column) or fitted (--free), not both")
        if name in module.PARAM_NAMES:
            known.append(name)
        elif name in allowed_q:
            if name.startswith("KD") and not module.HAS_LOAD_FACTORS:
                raise FitInputError(f"{where}: column {name!r}: scene {module.SCENE!r} gives no Ft1, Ft2 "
                                    "([reference]), so the model has no load factors")
            quantities.append(name)
        elif name in other_q:
            form = ("a time history (it has a column 't')" if history else
                    "peaks (no column 't'; a time history needs one)")
            raise FitInputError(f"{where}: column {name!r} does not belong in {form}; measured quantities "
                                f"there: {', '.join(allowed_q)}")
        else:
            raise FitInputError(
                f"{where}: unknown column {_show(name)}: not a free parameter of scene {module.SCENE!r} "
                f"({', '.join(module.PARAM_NAMES) or 'none'}), a measured quantity ({', '.join(allowed_q)}), "
                f"{CASE!r} or {TIME!r}")
    if not quantities:
        raise FitInputError(f"{where}: no measured quantity: give at least one column of {', '.join(allowed_q)}")
    n_rows = len(frame)
    if not history and n_rows > MAX_CASES:
        raise FitInputError(f"{where}: {n_rows} cases, more than the {MAX_CASES} a fit runs per evaluation")
    values = np.column_stack([_numbers(frame, q, where) for q in quantities])
    known_values = (np.column_stack([_numbers(frame, k, where) for k in known]) if known
                    else np.empty((n_rows, 0)))
    if CASE in columns:
        labels = []
        for row, raw in enumerate(frame[CASE].tolist()):
            text = raw if isinstance(raw, str) else ("" if raw is None or (isinstance(raw, float) and math.isnan(raw))
                                                    else (str(int(raw)) if float(raw).is_integer() else str(raw)))
            if not CASE_ID.fullmatch(text):
                raise FitInputError(f"{where}: column 'case', data row {row + 1}: {_show(raw)} is not a case label "
                                    "(1 to 40 of A-Z a-z 0-9 _ . + -)")
            labels.append(text)
    else:
        labels = None
    if not history:
        cases = labels or [str(k + 1) for k in range(n_rows)]
        if len(set(cases)) != len(cases):
            dup = next(c for c in cases if cases.count(c) > 1)
            raise FitInputError(f"{where}: column 'case': label {dup!r} appears twice (one row per case)")
        return Measured("peaks", str(path), digest, known, quantities, cases, known_values, values,
                        np.arange(n_rows), None)
    t = _numbers(frame, TIME, where)
    bad = np.flatnonzero(t < 0)
    if bad.size:
        raise FitInputError(f"{where}: column 't', data row {bad[0] + 1}: t = {t[bad[0]]:g} s is before the start (0)")
    if run is not None:
        bad = np.flatnonzero(t > run["t_end"])
        if bad.size:
            raise FitInputError(f"{where}: column 't', data row {bad[0] + 1}: t = {t[bad[0]]:g} s is after t_end = "
                                f"{run['t_end']:g} s; raise --t-end")
    labels = labels or ["1"] * n_rows
    cases = list(dict.fromkeys(labels))
    if len(cases) > MAX_HISTORY_CASES:
        raise FitInputError(f"{where}: {len(cases)} cases, more than the {MAX_HISTORY_CASES} of a time-history fit")
    index = {c: k for k, c in enumerate(cases)}
    row_case = np.array([index[c] for c in labels])
    params = np.empty((len(cases), len(known)))
    for k in range(len(cases)):
        rows = np.flatnonzero(row_case == k)
        for j, name in enumerate(known):
            col = known_values[rows, j]
            if np.any(col != col[0]):
                raise FitInputError(f"{where}: column {name!r}: case {cases[k]!r} has different values "
                                    f"({col[0]:g} and {col[col != col[0]][0]:g}); a known parameter is one value "
                                    "per case")
            params[k, j] = col[0]
    return Measured("history", str(path), digest, known, quantities, cases, params, values, row_case, t)


def default_bounds(module: ModuleType, name: str) -> tuple[float, float] | None:
    """Bounds from the scene's rules (PARAM_CHECKS) when a 'range' rule bounds ``name`` on both sides."""
    for check in getattr(module, "PARAM_CHECKS", ()):
        if check[0] == "range" and check[1] == name and check[3] is not None and check[4] is not None:
            lo, hi = float(check[3]), float(check[4])
            width = hi - lo
            return (lo if check[5] else lo + 1e-9 * width, hi if check[6] else hi - 1e-9 * width)
    return None


def _rule_text(module: ModuleType, name: str) -> str:
    rules = [c[7] for c in getattr(module, "PARAM_CHECKS", ()) if c[0] == "range" and c[1] == name]
    return f" (the scene's rule only says {name} {rules[0]})" if rules else " (the scene gives no range for it)"


def parse_free(items: list[str], module: ModuleType) -> dict[str, tuple[float, float]]:
    """``NAME`` or ``NAME=LO:HI`` items -> {name: (lo, hi)}; bare names take the scene's range."""
    from tswm_runtime.apps.simulate import unknown_parameter
    from tswm_runtime.apps.sweep import SweepInputError, parse_ranges

    if not items:
        raise FitInputError("give at least one --free NAME[=LO:HI]")
    if len(items) > MAX_FREE:
        raise FitInputError(f"--free: {len(items)} parameters, more than {MAX_FREE}")
    free: dict[str, tuple[float, float]] = {}
    for item in items:
        name = item.partition("=")[0].strip()
        if name not in module.PARAM_NAMES:
            raise FitInputError(f"--free {item!r}: {unknown_parameter(module, name)}")
        if name in free:
            raise FitInputError(f"--free {item!r}: {name} is given twice")
        if "=" in item:
            try:
                free.update(parse_ranges([item], module))
            except SweepInputError as error:
                raise FitInputError(str(error).replace("--range", "--free", 1)) from None
        else:
            bounds = default_bounds(module, name)
            if bounds is None:
                raise FitInputError(f"--free {name}: give bounds as {name}=LO:HI{_rule_text(module, name)}")
            free[name] = bounds
    return free


# ----------------------------------------------------------------------------- the problem

class Problem:
    """The model against the measured table: evaluation points (rows of free values) to
    model values, statuses and scaled residuals."""

    def __init__(self, module: ModuleType, measured: Measured, free: dict, run: dict, magnitude: bool):
        from tswm_runtime.apps.sweep import grid_cases

        self.module, self.measured, self.run, self.magnitude = module, measured, run, magnitude
        self.names = list(free)
        self.lo = np.array([free[n][0] for n in self.names])
        self.hi = np.array([free[n][1] for n in self.names])
        self.width = self.hi - self.lo
        self.free_index = [module.PARAM_NAMES.index(n) for n in self.names]
        self.known_index = [module.PARAM_NAMES.index(n) for n in measured.known]
        base = grid_cases(module, {})  # one row: the scene's defaults (sweep's parameter matrix)
        self.base = np.repeat(base, len(measured.cases), axis=0)
        if self.known_index:
            self.base[:, self.known_index] = measured.params
        rms = np.sqrt(np.mean(measured.values ** 2, axis=0))
        self.scale = np.where(rms > 0, rms, 1.0)
        self.evaluations = 0
        self.runs = 0

    @property
    def n_residuals(self) -> int:
        return self.measured.values.size

    def matrix(self, X: np.ndarray) -> np.ndarray:
        """Rows of all free parameters for evaluation points X (k x free): k blocks of cases."""
        X = np.atleast_2d(X)
        P = np.tile(self.base, (X.shape[0], 1))
        P[:, self.free_index] = np.repeat(X, self.base.shape[0], axis=0)
        return P

    def check_rules(self) -> None:
        """Known values and the bounds against the scene's rules (refused before any run)."""
        cases = self.measured.cases
        mid = (self.lo + self.hi) / 2
        for row, reason in enumerate(checks.violations(self.module, self.matrix(mid))):
            if reason:
                raise FitInputError(f"--measured: case {cases[row]!r}: {reason}")
        for j, name in enumerate(self.names):
            for end, value in (("LO", self.lo[j]), ("HI", self.hi[j])):
                x = mid.copy()
                x[j] = value
                for row, reason in enumerate(checks.violations(self.module, self.matrix(x))):
                    if reason:
                        raise FitInputError(f"--free {name}={self.lo[j]:g}:{self.hi[j]:g}: at {end} "
                                            f"(case {cases[row]!r}): {reason}")

    def evaluate(self, X: np.ndarray):
        """Model values (k x rows x quantities; NaN where failed) and per-case status (k x cases)."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        self.evaluations += X.shape[0]
        self.runs += X.shape[0] * len(self.measured.cases)
        if self.measured.kind == "peaks":
            return self._peaks(X)
        return self._history(X)

    def _peaks(self, X):
        from tswm_runtime.apps.sweep import run_cases

        k, n = X.shape[0], len(self.measured.cases)
        table = run_cases(self.module, self.matrix(X), self.run)
        values = np.array(table[self.measured.quantities].to_numpy(dtype=np.float64)).reshape(k, n, -1)
        if self.magnitude:
            for j, q in enumerate(self.measured.quantities):
                if q in ("S1m", "S2m"):
                    values[:, :, j] = np.abs(values[:, :, j])
        status = np.array(table["status"], dtype=object).reshape(k, n)
        bad = (status != "finished")[:, :, None] | ~np.isfinite(values)
        values = np.where(bad, np.nan, values)
        return values, status

    def _history(self, X):
        from tswm_runtime.apps.simulate import SimulationInputError, simulate

        m = self.measured
        k = X.shape[0]
        values = np.full((k, m.values.shape[0], len(m.quantities)), np.nan)
        status = np.empty((k, len(m.cases)), dtype=object)
        P = self.matrix(X)
        for e in range(k):
            for c in range(len(m.cases)):
                params = dict(zip(self.module.PARAM_NAMES, P[e * len(m.cases) + c].tolist()))
                try:
                    result = simulate(self.module, params, **self.run)
                except SimulationInputError:
                    status[e, c] = "invalid-parameter"
                    continue
                status[e, c] = result.status
                if result.status != "finished":
                    continue
                rows = np.flatnonzero(m.row_case == c)
                values[e, rows] = history_values(result, m.t[rows], m.quantities)
        return values, status

    def residuals(self, X: np.ndarray):
        """Scaled residuals (k x rows*quantities), with PENALTY where a case failed; values; status."""
        values, status = self.evaluate(X)
        r = (values - self.measured.values[None]) / self.scale
        r[~np.isfinite(r)] = PENALTY
        return r.reshape(r.shape[0], -1), values, status


def history_values(result, t: np.ndarray, quantities: list[str]) -> np.ndarray:
    """The Result's quantities at times t: v1 by Result.sol (cubic Hermite), S1 and S2
    linearly between output points within one phase (rows at an event time belong to the
    phase that ends there; a time at an event reads the earlier phase)."""
    out = np.full((t.size, len(quantities)), np.nan)
    cuts = [0.0, *sorted({e.t for e in result.events}), result.t_stop]
    for j, q in enumerate(quantities):
        if q == "v1":
            out[:, j] = result.sol(t)[1]
            continue
        series = getattr(result, q)
        for a, b in zip(cuts[:-1], cuts[1:]):
            rows = (result.t >= a) & (result.t <= b)
            if a > 0.0:
                rows &= result.t > a
            want = (t >= a) & (t <= b) & np.isnan(out[:, j])
            if want.any() and rows.any():
                out[want, j] = np.interp(t[want], result.t[rows], series[rows])
    return out


# ----------------------------------------------------------------------------- the fit

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
    ci: dict  # name -> (lo, hi); (-inf, inf) where not identifiable; NaN where no CI (m = n)
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
    seconds: float = 0.0

    @property
    def identifiable(self) -> bool:
        return not any(n.startswith("not identifiable") or "identif" in n for n in self.notes)

    @property
    def success(self) -> bool:
        """A fit was found and every case ran at it."""
        return not self.failed and self.starts[self.best_start].status > 0

    def to_dict(self) -> dict:
        from dataclasses import asdict

        return _plain({**{k: v for k, v in asdict(self).items()}, "success": self.success})


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


def _statistics(problem: Problem, x: np.ndarray, r: np.ndarray, J: np.ndarray, confidence: float):
    from scipy import stats

    m, n = J.shape
    dof = m - n
    ssr = float(r @ r)
    s2 = ssr / dof if dof > 0 else math.nan
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
    se = np.sqrt(np.clip(np.diag(cov), 0, None)) if dof > 0 else np.full(n, math.nan)
    tq = float(stats.t.ppf((1 + confidence) / 2, dof)) if dof > 0 else math.nan
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
            notes.append(f"not identifiable: the {st.get('confidence', 0.95):.0%} confidence interval of {name} "
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
        notes.append(f"not identifiable: start(s) {', '.join(str(k + 1) for k in others)} end at different values "
                     f"({where}) with the same cost as the best ({best_cost:.6g})")
    if st["dof"] <= 0:
        notes.append("as many residuals as free parameters: no estimate of the noise, no confidence intervals")
    if cases_failed:
        notes.append(f"{len(cases_failed)} case(s) did not finish at the optimum (penalty {PENALTY:g} per residual): "
                     + "; ".join(f"{c['case']} ({c['status']})" for c in cases_failed[:5]))
    return notes


def fit(model: str | ModuleType, measured: str | Path | Measured, free: dict | list, *,
        overrides: dict | None = None, starts: int = 4, sampler: str = "sobol", seed: int = 0,
        magnitude: bool = False, confidence: float = 0.95, grid_points: int | None = None,
        progress: bool = False, misfit: bool = True) -> FitResult:
    """Fit the free parameters ``free`` ({name: (lo, hi)} or a list of ``NAME[=LO:HI]``) of
    ``model`` to the measured table (a CSV/Parquet path or a ``Measured``).

    overrides: run settings (t_end, rtol, atol, method, max_steps, max_events; history
    also points); FIT_RUN's tolerances unless given. starts: multi-start count (qmc
    ``sampler`` 'sobol' or 'lhs', ``seed``). magnitude: compare |S1m|, |S2m|.
    grid_points: misfit grid per axis (default 41 for one parameter, 15 for two); misfit=False
    skips the grid. Raises FitInputError for inputs that cannot be used."""
    from scipy.optimize import least_squares

    from tswm_runtime import __version__
    from tswm_runtime.apps import chunks
    from tswm_runtime.apps.simulate import SimulationInputError, settings
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
    given = {k: v for k, v in (overrides or {}).items() if v is not None}
    try:
        run = settings(module, {**FIT_RUN, **given})
    except SimulationInputError as error:
        raise FitInputError(str(error)) from None
    if not isinstance(measured, Measured):
        measured = read_measured(measured, module, list(free), run)
    problem = Problem(module, measured, free, run, magnitude)
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
    st = _statistics(problem, x, r, J, confidence)
    st["confidence"] = confidence
    cases, failed = _case_table(problem, values[0], status[0])
    notes = _notes(problem, st, results, best, failed)
    units = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS))
    res = FitResult(
        scene=module.SCENE, names=problem.names, units=[units[n] for n in problem.names],
        bounds={n: (float(a), float(b)) for n, a, b in zip(problem.names, problem.lo, problem.hi)},
        bound_source={n: "scene" if default_bounds(module, n) == free[n] else "given" for n in problem.names},
        estimate=dict(zip(problem.names, x.tolist())), stderr=dict(zip(problem.names, st["se"].tolist())),
        ci=st["ci"], confidence=confidence, covariance=st["cov"].tolist(), correlation=st["corr"].tolist(),
        cost=0.5 * float(r @ r), dof=st["dof"], s2=st["s2"], singular_values=st["sv"].tolist(),
        condition=st["cond"], rank=st["rank"], jacobian=J.tolist(), notes=notes, starts=results,
        best_start=best, cases=cases, failed=failed,
        measured={"file": measured.source, "sha256": measured.sha256, "form": measured.kind,
                  "cases": len(measured.cases), "rows": int(measured.values.shape[0]), "known": measured.known,
                  "quantities": measured.quantities, "scale": dict(zip(measured.quantities, problem.scale.tolist())),
                  "compared": "|S1m|, |S2m|" if magnitude else "signed values as the sweep reports them",
                  "fixed": {n: float(v) for n, v in zip(module.PARAM_NAMES, module.PARAM_DEFAULTS)
                            if n not in measured.known and n not in problem.names}},
        settings={k: v for k, v in problem.run.items()},
        fit_settings={"starts": starts, "sampler": sampler, "seed": seed, "magnitude": magnitude,
                      "confidence": confidence, "t_quantile": st["tq"], "penalty": PENALTY,
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


# ----------------------------------------------------------------------------- outputs

def misfit_png(res: FitResult) -> bytes:
    """The misfit plot: cost over one parameter (curve) or two (contour of log10 cost)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    g = res.misfit
    fig = Figure(figsize=(7, 5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    names = g["names"]
    label = [f"{n} [{res.units[res.names.index(n)]}]".replace(" []", "") for n in names]
    ends = np.array([s.x for s in res.starts])
    if len(names) == 1:
        xs, cost = np.array(g["axes"][0]), np.array(g["cost"])
        ax.semilogy(xs, np.maximum(cost, 1e-300), "-", color="C0", label="cost 0.5 sum r^2")
        best = res.estimate[names[0]]
        ax.axvline(best, color="C3", label=f"optimum {names[0]} = {best:.6g}")
        lo, hi = res.ci[names[0]]
        if math.isfinite(lo) and math.isfinite(hi):
            ax.axvspan(max(lo, xs[0]), min(hi, xs[-1]), color="C3", alpha=0.15,
                       label=f"{res.confidence:.0%} confidence interval")
        ax.plot(ends[:, 0], [max(s.cost, 1e-300) for s in res.starts], "kx", label="ends of the starts")
        ax.set_xlabel(label[0])
        ax.set_ylabel("cost (log scale)")
    else:
        xs, ys = (np.array(a) for a in g["axes"])
        cost = np.log10(np.maximum(np.array(g["cost"]), 1e-300))
        cs = ax.contourf(xs, ys, cost.T, levels=20, cmap="viridis")
        fig.colorbar(cs, ax=ax, label="log10 cost")
        ax.plot(ends[:, 0], ends[:, 1], "wx", label="ends of the starts")
        ax.plot([res.estimate[names[0]]], [res.estimate[names[1]]], "r*", ms=14, label="optimum")
        ax.set_xlabel(label[0])
        ax.set_ylabel(label[1])
    extra = f"; {', '.join(g['others_at_optimum'])} at the optimum" if g["others_at_optimum"] else ""
    ax.set_title(f"tswm fit {res.scene}: misfit over the bounds{extra}", fontsize=10)
    ax.legend(fontsize=8)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    return buffer.getvalue()


def _md(text: str) -> str:
    """Escape what Markdown would read as markup (file names are user text)."""
    return re.sub(r"([\\`*_{}\[\]<>()#+!|])", r"\\\1", text)


def report_markdown(res: FitResult) -> str:
    f = res.to_dict()
    L = [f"# tswm fit: scene {res.scene}", ""]
    L.append(f"Measured: {_md(Path(res.measured['file']).name)} ({res.measured['form']}, {res.measured['cases']} "
             f"case(s), {res.measured['rows']} row(s); quantities {', '.join(res.measured['quantities'])}, compared "
             f"as {res.measured['compared']}; known per case: {', '.join(res.measured['known']) or 'none'}).")
    L.append("")
    L.append("| parameter | estimate | std. error | " f"{res.confidence:.0%} CI | bounds |")
    L.append("| --- | --- | --- | --- | --- |")
    for n, u in zip(res.names, res.units):
        lo, hi = res.ci[n]
        ci = "unbounded" if not (math.isfinite(lo) and math.isfinite(hi)) else f"[{lo:.6g}, {hi:.6g}]"
        if math.isnan(lo):
            ci = "none"
        L.append(f"| {n} [{u}] | {res.estimate[n]:.8g} | {res.stderr[n]:.3g} | {ci} | "
                 f"[{res.bounds[n][0]:g}, {res.bounds[n][1]:g}] ({res.bound_source[n]}) |")
    L.append("")
    L.append(f"Cost 0.5 sum r^2 = {res.cost:.6g} over {len(res.jacobian)} scaled residuals, {res.dof} degrees of "
             f"freedom, s^2 = {res.s2:.6g}; singular values of J (columns scaled to the bounds) "
             f"{', '.join(f'{v:.4g}' for v in res.singular_values)}, condition {res.condition:.4g}, rank {res.rank}.")
    L.append("")
    L.append("## Identifiability and warnings")
    L.append("")
    L += [f"- {n}" for n in res.notes] or ["- none: every parameter is determined by the data (full-rank J, finite "
                                           "confidence intervals inside the bounds, starts agree)"]
    L.append("")
    if len(res.names) > 1:
        L.append("## Correlation")
        L.append("")
        L.append("| | " + " | ".join(res.names) + " |")
        L.append("|---" * (len(res.names) + 1) + "|")
        for n, row in zip(res.names, res.correlation):
            L.append(f"| {n} | " + " | ".join("n/a" if not math.isfinite(c) else f"{c:+.4f}" for c in row) + " |")
        L.append("")
    L.append("## Starts")
    L.append("")
    L.append("| start | from | to | cost | status | evaluations | failed cases |")
    L.append("| --- | --- | --- | --- | --- | --- | --- |")
    for k, s in enumerate(res.starts):
        mark = " (best)" if k == res.best_start else ""
        L.append(f"| {k + 1}{mark} | {', '.join(f'{v:.6g}' for v in s.x0)} | {', '.join(f'{v:.8g}' for v in s.x)} | "
                 f"{s.cost:.6g} | {s.status} | {s.nfev} | {s.failed_cases} |")
    L.append("")
    L.append("## Residuals per case")
    L.append("")
    if res.measured["form"] == "peaks":
        L.append("| case | known | status | quantity | measured | model | residual | relative |")
        L.append("| --- | --- | --- | --- | --- | --- | --- | --- |")
        for c in res.cases:
            known = ", ".join(f"{k} = {v:g}" for k, v in c["known"].items())
            for q, d in c["quantities"].items():
                L.append(f"| {c['case']} | {known} | {c['status']} | {q} | {d['measured']:.6g} | {d['model']:.6g} | "
                         f"{d['residual']:.4g} | {d['relative']:.3g} |")
    else:
        L.append("| case | known | status | samples | quantity | RMS measured | RMS residual | max residual "
                 "| relative |")
        L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for c in res.cases:
            known = ", ".join(f"{k} = {v:g}" for k, v in c["known"].items())
            for q, d in c["quantities"].items():
                L.append(f"| {c['case']} | {known} | {c['status']} | {c['samples']} | {q} | {d['rms_measured']:.6g} | "
                         f"{d['rms_residual']:.4g} | {d['max_residual']:.4g} | {d['relative']:.3g} |")
    L.append("")
    L.append("![misfit](misfit.png)" if res.misfit else "")
    L.append("")
    L.append("## Settings and provenance")
    L.append("")
    run = res.settings
    L.append(f"- run: t_end {run['t_end']:g} s, {run['method']}, rtol {run['rtol']:g}, atol {run['atol']:g}, "
             f"max_steps {run['max_steps']}; model runs {res.fit_settings.get('model_runs')}; wall time "
             f"{res.seconds:.3g} s")
    fs = res.fit_settings
    L.append(f"- fit: {fs['method']}, {fs['starts']} start(s) ({fs['sampler']}, seed {fs['seed']}), cost "
             f"{fs['cost']}, scale per quantity " + ", ".join(f"{q} {v:.6g}" for q, v in res.measured["scale"].items())
             + f", penalty {fs['penalty']:g} per residual of a failed case")
    if res.measured["fixed"]:
        L.append("- fixed at the scene's values: "
                 + ", ".join(f"{k} = {v:g}" for k, v in res.measured["fixed"].items()))
    p = res.provenance
    L.append(f"- scene digest {p['scene_digest']}, model {p['model_digest']}, runtime {p['runtime_version']} "
             f"({p['runtime_digest'][:16]}), measured file sha256 {res.measured['sha256'][:16]}")
    L.append("- versions: " + ", ".join(f"{k} {v}" for k, v in f["provenance"]["versions"].items()))
    L.append("")
    L.append("A fitted value is the parameter that makes this model reproduce these numbers; it is a fit, "
             "not a measurement of the parameter.")
    return "\n".join(L) + "\n"


def write_outputs(res: FitResult, directory: str | Path, plot: bool = True) -> list[Path]:
    """DIR/fit-report.md, fit.json and (with a misfit grid) misfit.png, each written atomically."""
    from tswm_runtime.common.files import write_atomic

    directory = Path(directory)
    paths = [write_atomic(directory / "fit.json", json.dumps(res.to_dict(), indent=2, allow_nan=False))]
    if plot and res.misfit:
        paths.append(write_atomic(directory / "misfit.png", misfit_png(res)))
    paths.append(write_atomic(directory / "fit-report.md", report_markdown(res)))
    return paths
