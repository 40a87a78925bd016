"""The inputs of ``tswm fit``: the measured table (``read_measured``) and the ``--free``
bounds (``parse_free``), read as untrusted data and checked before any model runs.

The measured table (CSV or Parquet) comes in one of two forms:

peaks     one row per measured case: columns naming free parameters *known* per case
          (e.g. m2, F2_after), an optional ``case`` label, and measured quantities among
          S1m, S2m, KD1, KD2 as the sweep reports them (S1m, S2m signed: the value of S1
          (S2) where |S1| (|S2|) is largest; KD >= 0).
history   a column ``t`` [s]: one row per sample, an optional ``case`` label (rows of one
          case share it, and its known parameters must be equal), measured quantities
          among S1, S2 [N] and v1 [m/s].

A column name may carry its unit, ``NAME [UNIT]`` ('S1 [N]', 'S1 [kN]', 'm2 [kg]'): a unit of
the column's quantity (tswm_common.units), converted to SI. The tables tswm writes are read as
written. ``tswm sweep -o``'s (peaks; it has the columns status and regimes): its other result
columns and the columns of the parameters being fitted are skipped (refused if the sweep ran
several values of one), rows that did not finish are refused. ``tswm simulate -o``'s CSV (a
history; it has the columns mode and regime): t, S1, S2 and v1 are read, its other series
skipped, and the run's other parameter values taken from the SCENE-summary.json written
beside it (the scene's values without one).

How the model is compared with either form: ``tswm_runtime.fitting.problem``.
"""
from __future__ import annotations

import hashlib
import io
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

from tswm_common import units

PEAK_QUANTITIES = ("S1m", "S2m", "KD1", "KD2")
HISTORY_QUANTITIES = ("S1", "S2", "v1")
CASE, TIME = "case", "t"
QUANTITY = {"S1m": "force", "S2m": "force", "KD1": "dimensionless", "KD2": "dimensionless", "t": "time",
            "S1": "force", "S2": "force", "v1": "velocity"}  # tswm_common.units quantities
SWEEP_TABLE = ("status", "regimes")   # columns that mark a table written by tswm sweep -o
SIMULATE_TABLE = ("mode", "regime")   # ... and a CSV written by tswm simulate -o
FINISHED = "finished"
UNIT = re.compile(r"(.*?)\s*\[([^\[\]]*)\]")
# Size bounds (docs/promises.md): the measured file is untrusted input.
MAX_FILE_BYTES = 64 * 2**20
MAX_UNPACKED_BYTES = 256 * 2**20  # Parquet: uncompressed size from its metadata
MAX_COLUMNS = 64
MAX_NAME = 64  # characters of a column name
MAX_CASES = 10_000  # peak cases (every evaluation runs all of them)
MAX_HISTORY_ROWS = 100_000
MAX_HISTORY_CASES = 200
MAX_FREE = 8
CASE_ID = re.compile(r"[A-Za-z0-9_.+\-]{1,40}")


class FitInputError(ValueError):
    """A fit input that cannot be used; the message names it (exit status 2)."""


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


def _quantity(module: ModuleType, name: str) -> str | None:
    """The units quantity of column ``name`` (a measured quantity or a free parameter), or None."""
    if name in QUANTITY:
        return QUANTITY[name]
    si = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS)).get(name)
    return None if si is None else {units.si_unit(q): q for q in units.UNITS}.get(si, si)


def _factor(module: ModuleType, header: str, name: str, unit: str | None, where: str) -> float:
    """What converts column ``header`` (``name [unit]``) to SI: 1 without a unit."""
    if unit is None:
        return 1.0
    quantity = _quantity(module, name)
    if quantity is None:  # the case label, or a column refused by its name later
        if name == CASE:
            raise FitInputError(f"{where}: column {_show(header)}: {CASE!r} takes no unit")
        return 1.0
    known = units.UNITS.get(quantity, {quantity: 1.0})
    if unit not in known:
        kind = f"{units.article(quantity)} {quantity}" if quantity in units.UNITS else "this parameter"
        raise FitInputError(f"{where}: column {_show(header)}: {unit!r} is not a unit of {kind} "
                            f"({', '.join(repr(u) for u in known)})")
    return known[unit]


def _skipped(columns: list[str], module: ModuleType, free: list[str]) -> set[str]:
    """Columns of a table tswm wrote that are its record, not measurements or known values."""
    if all(c in columns for c in SWEEP_TABLE):
        from tswm_runtime.sweeps.sweep import RESULT_COLUMNS

        load_factors = ("KD1", "KD2") if module.HAS_LOAD_FACTORS else ()
        return set(RESULT_COLUMNS) - {"S1m", "S2m", *load_factors} | set(free)
    if all(c in columns for c in SIMULATE_TABLE):
        from tswm_runtime.results.result import GAP_SERIES, SERIES, STEM_SERIES

        series = {name for name, _ in SERIES + GAP_SERIES + STEM_SERIES}
        return series - {TIME, *HISTORY_QUANTITIES} | set(SIMULATE_TABLE)
    return set()


def _finished_rows(frame, where: str) -> None:
    """A sweep table's rows must all have run to the end: the others measured nothing."""
    status = frame["status"].astype(str)
    bad = np.flatnonzero(status.to_numpy() != FINISHED)
    if bad.size:
        raise FitInputError(f"{where}: column 'status', data row {bad[0] + 1}: {_show(status.iloc[bad[0]])}: that "
                            f"run did not finish, so its row is no measurement; keep the rows with status "
                            f"{FINISHED!r} ({bad.size} of {len(frame)} are not)")


def _one_value(frame, header: str, name: str, where: str) -> None:
    """A fitted parameter's column in a sweep table: the sweep must have run one value of it."""
    values = frame[header].astype(str).unique()
    if len(values) > 1:
        raise FitInputError(f"{where}: column {_show(header)}: the sweep ran {len(values)} values of {name} "
                            f"({_show(values[0])}, {_show(values[1])}, ...) and the fit estimates one; keep the rows "
                            f"of one {name}, or fit another parameter")


def _named_columns(frame, module: ModuleType, free: list[str], where: str) -> tuple[dict, dict]:
    """{name: header} of the columns to read (units stripped: 'S1 [N]' -> 'S1') and {name: factor to
    SI}; a tswm table's own record is skipped (``_skipped``)."""
    headers = list(frame.columns)
    skipped = _skipped(headers, module, free)
    if "status" in skipped:
        _finished_rows(frame, where)
    column, factor = {}, {}
    for header in headers:
        match = UNIT.fullmatch(header)
        name, unit = (match[1], match[2]) if match else (header, None)
        if name in free and "status" in skipped:
            _one_value(frame, header, name, where)
        if name in skipped:
            continue
        if name in column:
            raise FitInputError(f"{where}: columns {_show(column[name])} and {_show(header)} both give {name!r}")
        column[name], factor[name] = header, _factor(module, header, name, unit, where)
    return column, factor


def _run_parameters(path: str | Path, module: ModuleType, skip, where: str) -> dict[str, float]:
    """The free parameters of the run that wrote a simulate CSV, from the SCENE-summary.json the same
    ``-o`` wrote beside it ({} without one), leaving out the names in ``skip``."""
    summary = Path(path).with_name(f"{Path(path).stem}-summary.json")
    if not summary.is_file():
        return {}
    try:
        if summary.stat().st_size > MAX_FILE_BYTES:
            raise ValueError(f"more than {MAX_FILE_BYTES // 2**20} MiB")
        data = json.loads(summary.read_text(encoding="utf-8"))
        scene, params = data["scene"], data["params"]
        values = {str(name): float(value) for name, value in params.items()}
    except (OSError, ValueError, TypeError, KeyError, AttributeError) as error:
        raise FitInputError(f"{where}: {summary} (the run's summary beside it) is not readable: "
                            f"{str(error)[:200]}; move it away to fit with the scene's parameter values") from None
    if scene != module.SCENE:
        raise FitInputError(f"{where}: {summary} says the CSV is a run of scene {_show(scene)}, not "
                            f"{module.SCENE!r}")
    for name, value in values.items():
        if name not in module.PARAM_NAMES or not math.isfinite(value):
            raise FitInputError(f"{where}: {summary}: parameter {_show(name)} = {value!r} is not a free parameter "
                                f"value of scene {module.SCENE!r}")
    return {name: value for name, value in values.items() if name not in skip}


def read_measured(path: str | Path, module: ModuleType, free: list[str], run: dict | None = None) -> Measured:
    """Read and validate a measured table for ``module`` with ``free`` parameters to fit."""
    frame, digest = _read_table(path)
    where = f"--measured {str(path)[:200]}"
    if len(frame) == 0:
        raise FitInputError(f"{where}: no rows (one row per measured case or sample)")
    column, factor = _named_columns(frame, module, free, where)
    columns = list(column)
    history = TIME in columns
    allowed_q = HISTORY_QUANTITIES if history else PEAK_QUANTITIES
    other_q = PEAK_QUANTITIES if history else HISTORY_QUANTITIES
    known, quantities = [], []

    def numbers(name: str) -> np.ndarray:
        return _numbers(frame, column[name], where) * factor[name]

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
                f"{where}: unknown column {_show(column[name])}: not a free parameter of scene {module.SCENE!r} "
                f"({', '.join(module.PARAM_NAMES) or 'none'}), a measured quantity ({', '.join(allowed_q)}), "
                f"{CASE!r} or {TIME!r}")
    if not quantities:
        raise FitInputError(f"{where}: no measured quantity: give at least one column of {', '.join(allowed_q)}")
    n_rows = len(frame)
    if not history and n_rows > MAX_CASES:
        raise FitInputError(f"{where}: {n_rows} cases, more than the {MAX_CASES} a fit runs per evaluation")
    values = np.column_stack([numbers(q) for q in quantities])
    known_values = (np.column_stack([numbers(k) for k in known]) if known else np.empty((n_rows, 0)))
    if all(c in frame.columns for c in SIMULATE_TABLE):
        of_run = _run_parameters(path, module, {*free, *known}, where)
        known += list(of_run)
        known_values = np.column_stack([known_values, np.tile(list(of_run.values()), (n_rows, 1))])
    if CASE in columns:
        labels = []
        for row, raw in enumerate(frame[column[CASE]].tolist()):
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
    t = numbers(TIME)
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
    from tswm_runtime.simulation.simulate import unknown_parameter
    from tswm_runtime.sweeps.sweep import SweepInputError, parse_ranges

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


def parse_noise(noise: dict | list, quantities: list[str]) -> dict[str, float]:
    """``QUANTITY=SIGMA`` items (or {quantity: sigma}) -> {quantity: sigma in SI}, one per measured quantity."""
    items = noise.items() if isinstance(noise, dict) else [str(i).partition("=")[::2] for i in noise]
    sigma: dict[str, float] = {}
    for q, raw in items:
        q = str(q).strip()
        if q not in quantities:
            raise FitInputError(f"--noise {q}={raw}: {q!r} is not a measured quantity of this file "
                                f"({', '.join(quantities)})")
        try:
            value = float(raw)  # SI
        except (ValueError, TypeError):
            try:
                value = units.to_si(str(raw), QUANTITY[q])  # "50 N"
            except units.UnitError as error:
                raise FitInputError(f"--noise {q}={raw}: {error}") from None
        if not (math.isfinite(value) and value > 0):
            raise FitInputError(f"--noise {q}={raw}: the noise must be a finite number > 0")
        if q in sigma:
            raise FitInputError(f"--noise {q}: given twice")
        sigma[q] = value
    missing = [q for q in quantities if q not in sigma]
    if missing:
        raise FitInputError(f"--noise: give the noise of every measured quantity or of none; missing "
                            f"{', '.join(missing)}")
    return sigma
