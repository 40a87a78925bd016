"""Parameter sweeps: one scene over a grid or random samples of its free parameters.

The cases are split into chunks; each chunk is one call of the parallel numba batch
(``batch.run_batch``, prange over cases on all cores) and is written atomically to
``DIR/chunks/chunk-NNNNN-HASH.parquet`` with its key inside (``chunks.py``: a sha256 of the
model module's file, the runtime's version and digest, the settings, the rows) and a checksum
of its columns. A rerun reuses a chunk only when the file proves it holds exactly those rows;
a truncated, altered, foreign or stale one is recomputed with a warning, and files no chunk expects are reported (and
removed with ``prune``). An interrupted sweep leaves only complete chunks and resumes
without recomputing them. With a dask.distributed ``Client`` the chunks run as tasks on
its workers instead (``cluster.py``: every worker checked first, the model shipped with the
work). The rows of a chunk come from ``rows.case_table``, as Arrow columns, and every table is
written by pyarrow (parquet, and CSV by ``pyarrow.csv``); pandas is imported only for a caller
that reads ``SweepOutcome.table``. ``rows`` (and with it the batch kernel) is imported by ``sweep``
when it runs, not with this module: the chain sweep (``chain.py``) uses ``in_chunks`` and the size
checks here and never the scene batch.

One row per case: the free parameters, then

    status    'finished' or why the run stopped (result.STATUS_NAMES); 'invalid-parameter'
              for a row that breaks the scene file's rules for its parameters (not run)
    problem   '' or, for an invalid row, which rule it breaks; for a not-finite one, which
              column is inf or NaN and the likely cause
    t_stop    where the run ended [s]
    S1m, tS1m, S2m, tS2m   the value of S1 (S2) where |S1| (|S2|) is largest, and its time
    KD1, KD2  eq. (10) from S1m, S2m when the scene gives Ft1, Ft2 (else NaN)
    x1, v1    the state at t_stop (NaN when the run stopped inside a step)
    regimes   the regime code: one letter per phase, in order (REGIME_LETTERS: T tractive,
              I inverse-tractive, S stick, A/B backward on flank a/b, F sliding along
              phi = 0, G free flight across the clearance); e.g. 'ST' = stuck, then broke away
              into tractive sliding
    modes     the same phases as mode indices into the module's MODES, space separated
    n_events, steps, rejected, nfev, njev   events logged, accepted and rejected steps,
              rhs and Jacobian calls
    n_switches   method auto's switches between its explicit and its stiff method (0 for the others)
    impacts, impact_energy   impacts with a normal impulse (scenes with a clearance and
              rigid flanks) and the kinetic energy they took [J]

The table in memory (``SweepOutcome.rows``, a pyarrow Table; ``SweepOutcome.table``, the same
as a pandas DataFrame) has these names; the written SCENE-sweep.parquet
and .csv carry the unit in the name where there is one (``written_names``: 'm2 [kg]',
'S1m [N]', 'tS1m [s]', 'v1 [m/s]'; 'KD1', 'status' as they are), and ``read_table`` reads
them back without it. ``tswm fit --measured`` reads them as written.
"""
from __future__ import annotations

import functools
import io
import json
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from tswm_runtime.common.provenance import TSWM_VERSION as __version__
from tswm_runtime.sweeps import DEFAULT_CHUNK, DEFAULT_WAIT_FOR_WORKERS
from tswm_runtime.common.words import plural
from tswm_runtime.jit import coldstart
from tswm_runtime.model.scenes import load_model
from tswm_runtime.model.values import ValueInputError, si_value
from tswm_common.files import write_atomic
from tswm_runtime.simulation.simulate import settings, unknown_parameter
from tswm_runtime.sweeps import chunks, cluster, columns
from tswm_runtime.sweeps.grid import MAX_CASES, GridError, parse_items

LOG = logging.getLogger("tswm_runtime.sweep")
# Size bounds (docs/promises.md): above LARGE_SWEEP cases a sweep states its size and needs --large;
# MAX_SWEEP_CASES is refused outright, and so is a sweep that would write more than MAX_CHUNKS chunk files.
LARGE_SWEEP = 10**6
MAX_SWEEP_CASES = MAX_CASES
MAX_CHUNK_SIZE = 10**6
MAX_CHUNKS = 10**5
MAX_SEED = 2**63 - 1
ROW_BYTES = 220   # bytes per case in chunks + parquet + CSV: 214 measured on a 2000-case paper grid
RESULT_COLUMNS = ("status", "problem", "t_stop", "S1m", "tS1m", "S2m", "tS2m", "KD1", "KD2", "x1", "v1",
                  "regimes", "modes", "n_events", "steps", "rejected", "nfev", "njev", "n_switches", "impacts",
                  "impact_energy")
# Units of the result columns in the written tables ('S1m [N]'); the parameters carry PARAM_UNITS.
RESULT_UNITS = {"t_stop": "s", "S1m": "N", "tS1m": "s", "S2m": "N", "tS2m": "s", "x1": "m", "v1": "m/s",
                "impact_energy": "J"}
TEXT_COLUMNS = ("status", "problem", "regimes", "modes")
COUNT_COLUMNS = ("n_events", "steps", "rejected", "nfev", "njev", "n_switches", "impacts")   # int64; the rest float64
UNIT_SUFFIX = re.compile(r"\s*\[([^\[\]]*)\]$")


def written_names(module: ModuleType) -> dict[str, str]:
    """Column name in a sweep's table -> its name in the written parquet and CSV: 'NAME [UNIT]'
    where it has a unit ('m2 [kg]', 'S1m [N]', 'tS1m [s]'), else NAME ('KD1', 'status')."""
    units = {**dict(zip(module.PARAM_NAMES, module.PARAM_UNITS)), **RESULT_UNITS}
    return {name: f"{name} [{units[name]}]" if units.get(name) else name
            for name in (*module.PARAM_NAMES, *RESULT_COLUMNS)}


def read_table(path: str | Path):
    """A written sweep table (.parquet or .csv) as ``sweep`` returned it: columns without units."""
    import pandas as pd

    path = Path(path)
    if path.suffix != ".csv":
        return pd.read_parquet(path).rename(columns=lambda name: UNIT_SUFFIX.sub("", name))
    # CSV holds no types: 200.0 reads as an integer, empty text as missing
    names = [UNIT_SUFFIX.sub("", name) for name in pd.read_csv(path, nrows=0).columns]
    table = pd.read_csv(path, header=0, names=names, dtype={
        name: "str" if name in TEXT_COLUMNS else "int64" if name in COUNT_COLUMNS else "float64" for name in names})
    table[list(TEXT_COLUMNS)] = table[list(TEXT_COLUMNS)].fillna("")
    return table


class SweepInputError(ValueError):
    """A sweep input that cannot be used; the message names it."""


def _free(module: ModuleType, name: str, option: str) -> None:
    if name not in module.PARAM_NAMES:
        raise SweepInputError(f"{option} {name!r}: {unknown_parameter(module, name)}")


def _number(module: ModuleType, name: str, text: str, what: str) -> float:
    """``text`` as free parameter ``name``'s value in SI: a number, or a number with a unit of its
    quantity ("-5 kN")."""
    try:
        value = float(si_value(module, name, text))
    except ValueInputError as error:
        raise SweepInputError(f"{what}: {error}") from None
    if not math.isfinite(value):
        raise SweepInputError(f"{what}: {text!r} is not finite")
    return value


def spec_items(specs, option: str) -> list[str]:
    """Grid, range or bound specs as the CLI's ``NAME=SPEC`` items: a list of such strings as it
    is, or a dict {name: spec} with a spec string ("-15 kN:-5 kN:11", "100:400"), one number,
    or a (lo, hi) pair of numbers or unit strings."""
    if specs is None:
        return []
    if isinstance(specs, str):
        specs = [specs]
    if not isinstance(specs, dict):
        for item in specs:
            if not isinstance(item, str):
                raise SweepInputError(f"{option} {item!r}: expected a 'NAME=SPEC' string, e.g. 'F2=-15000:0:11'")
        return list(specs)
    items = []
    for name, spec in specs.items():
        if isinstance(spec, (tuple, list)) and len(spec) == 2:
            spec = ":".join(part if isinstance(part, str) else repr(part) for part in spec)
        elif isinstance(spec, (int, float)) and not isinstance(spec, bool):
            spec = repr(spec)
        elif not isinstance(spec, str):
            raise SweepInputError(f"{option} {name}={spec!r}: expected a string ('-15 kN:-5 kN:11', '100:400'), "
                                  "a number or a (lo, hi) pair")
        items.append(f"{name}={spec}")
    return items


def parse_grid(items: list[str], module: ModuleType) -> dict[str, np.ndarray]:
    """The --grid items over the module's free parameters (sweeps/grid.py: ranges, lists or one value;
    numbers in SI or with a unit of the parameter's quantity, "-15 kN")."""
    def unknown(name: str) -> str | None:
        return None if name in module.PARAM_NAMES else unknown_parameter(module, name)
    try:
        return parse_items(items, lambda name, text: si_value(module, name, text), unknown, "F2=-15000:0:11")
    except GridError as error:
        raise SweepInputError(str(error)) from None


def parse_ranges(items: list[str], module: ModuleType) -> dict[str, tuple[float, float]]:
    """``name=lo:hi`` with lo < hi (numbers in SI or with a unit, as for ``parse_grid``)."""
    ranges = {}
    for item in items:
        name, sep, spec = (s.strip() for s in item.partition("="))
        parts = spec.split(":")
        if not sep or not name or len(parts) != 2:
            raise SweepInputError(f"--range {item!r}: expected NAME=LO:HI, e.g. m2=100:400")
        _free(module, name, "--range")
        lo, hi = (_number(module, name, v, f"--range {item!r}") for v in parts)
        if not lo < hi:
            raise SweepInputError(f"--range {item!r}: lo = {lo:g} must be < hi = {hi:g}")
        ranges[name] = (lo, hi)
    return ranges


def grid_size(grid: dict[str, np.ndarray]) -> int:
    """Number of cases of a grid (an exact Python int, computed before anything is allocated)."""
    return math.prod(int(values.size) for values in grid.values())


def check_size(cases: int, chunk_size: int, large: bool = False) -> None:
    """Refuse a sweep too large to be right or to fit, stating its size; above LARGE_SWEEP ask for --large."""
    if not 1 <= chunk_size <= MAX_CHUNK_SIZE:
        raise SweepInputError(f"--chunk-size {chunk_size}: must be in [1, {MAX_CHUNK_SIZE:.0e}]")
    files = -(-cases // chunk_size)
    size = (f"{plural(cases, 'case')}, about {cases * ROW_BYTES / 1e6:.3g} MB of parquet and CSV output, "
            f"{plural(files, 'chunk file')} of {chunk_size}")
    if cases > MAX_SWEEP_CASES:
        raise SweepInputError(f"sweep of {size}: more than the {MAX_SWEEP_CASES:.0e} cases tswm runs in one "
                              "sweep; split it (several -o directories) or coarsen the grid")
    if files > MAX_CHUNKS:
        raise SweepInputError(f"sweep of {size}: more than {MAX_CHUNKS:.0e} chunk files; raise --chunk-size to "
                              f"at least {-(-cases // MAX_CHUNKS)}")
    if cases > LARGE_SWEEP and not large:
        raise SweepInputError(f"sweep of {size}: above {LARGE_SWEEP:.0e} cases; pass --large to run it")


def grid_cases(module: ModuleType, grid: dict[str, np.ndarray]) -> np.ndarray:
    """All combinations (the first grid name varies slowest) as rows of the free parameters;
    parameters not in the grid keep the scene's defaults."""
    base = np.array(module.PARAM_DEFAULTS, dtype=np.float64)
    axes = [grid[name] for name in grid]
    mesh = np.meshgrid(*axes, indexing="ij") if axes else []
    n = int(np.prod([a.size for a in axes])) if axes else 1
    P = np.tile(base, (n, 1))
    for name, values in zip(grid, mesh):
        P[:, module.PARAM_NAMES.index(name)] = values.ravel()
    return P


def sweep_cases(module: ModuleType, grid=None, *, samples: int | None = None, ranges=None, seed: int = 0,
                chunk_size: int = DEFAULT_CHUNK, large: bool = False) -> np.ndarray:
    """The parameter rows of a sweep: all combinations of a ``grid``, or ``samples`` seeded random
    rows in ``ranges`` (specs as ``spec_items`` takes them), size-checked before they are built."""
    grid, ranges = spec_items(grid, "--grid"), spec_items(ranges, "--range")
    if grid and samples is not None:
        raise SweepInputError("give either --grid or --samples with --range, not both")
    if ranges and samples is None:
        raise SweepInputError("--range needs --samples N")
    if samples is not None:
        parsed = parse_ranges(ranges, module)
        check_size(max(samples, 1), chunk_size, large)   # before the samples are drawn
        return sample_cases(module, samples, parsed, seed)
    if not grid:
        raise SweepInputError("give --grid NAME=START:STOP:COUNT ... or --samples N --range NAME=LO:HI ...")
    parsed = parse_grid(grid, module)
    check_size(grid_size(parsed), chunk_size, large)   # before the grid is built
    return grid_cases(module, parsed)


def sample_cases(module: ModuleType, samples: int, ranges: dict, seed: int) -> np.ndarray:
    """``samples`` rows, each ranged parameter uniform in [lo, hi) (numpy default_rng(seed))."""
    if not 1 <= samples <= MAX_SWEEP_CASES:
        raise SweepInputError(f"--samples {samples}: must be in [1, {MAX_SWEEP_CASES:.0e}]")
    if not 0 <= seed <= MAX_SEED:
        raise SweepInputError(f"--seed {seed}: must be an integer in [0, 2^63 - 1]")
    if not ranges:
        raise SweepInputError("--samples needs at least one --range NAME=LO:HI")
    rng = np.random.default_rng(seed)
    P = np.tile(np.array(module.PARAM_DEFAULTS, dtype=np.float64), (samples, 1))
    for name, (lo, hi) in ranges.items():
        P[:, module.PARAM_NAMES.index(name)] = rng.uniform(lo, hi, samples)
    return P


@dataclass
class SweepOutcome:
    """What a sweep did: the rows (a pyarrow Table; ``table`` gives them as a pandas DataFrame),
    the files written, chunks computed, reused and rejected (index, why), stale files found (and
    pruned), warnings for the user."""

    rows: object  # pyarrow.Table
    parquet: Path | None
    csv: Path | None
    computed: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    rejected: list[tuple[int, str]] = field(default_factory=list)
    stale: list[Path] = field(default_factory=list)
    pruned: bool = False
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @functools.cached_property
    def table(self):
        """The rows as a pandas DataFrame (pandas is imported here, on first use)."""
        return self.rows.to_pandas()


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; the message says how many chunks are safe and how to resume."""


class SweepClusterLost(RuntimeError):
    """The dask cluster failed the sweep (scheduler or workers lost, a mismatched worker); the
    message names the problem, how many chunks are safe and how to resume."""


def _csv_bytes(table) -> bytes:
    """The table as CSV (pyarrow's writer: header quoted, text quoted, numbers as the shortest text
    that reads back to the same double, NaN as nan)."""
    import pyarrow.csv

    buffer = io.BytesIO()
    pyarrow.csv.write_csv(table, buffer)
    return buffer.getvalue()


def sweep(model: str | ModuleType, P: np.ndarray, overrides: dict | None = None, *,
          output: str | Path | None = None, chunk_size: int = DEFAULT_CHUNK, client=None,
          progress: bool = False, prune: bool = False, wait_for_workers: float = DEFAULT_WAIT_FOR_WORKERS,
          notice=None) -> SweepOutcome:
    """Run the rows of P (free parameters of the scene, in PARAM_NAMES order).

    output: a directory for chunks/ and SCENE-sweep.parquet/.csv (None: in memory only;
    no resume). client: a dask.distributed Client to run the chunks on (``cluster.py``: the
    model's source travels with each chunk, every worker is checked first, ``wait_for_workers``
    seconds without a worker give up, ``notice(text)`` tells of the cluster). prune: delete
    stale files in chunks/ (else they are only reported). Ctrl-C raises SweepInterrupted, a
    lost cluster SweepClusterLost, after the chunks finished so far are on disk.
    """
    import time

    from tswm_runtime.sweeps import rows   # loads (or compiles, saying so first) the batch kernel

    start = time.perf_counter()
    if not isinstance(model, ModuleType):
        coldstart.announce((), model)
    module = load_model(model)
    run = settings(module, overrides or {})
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, len(module.PARAM_NAMES))
    check_size(P.shape[0], chunk_size, large=True)
    bounds = [(a, min(a + chunk_size, P.shape[0])) for a in range(0, P.shape[0], chunk_size)]
    out = Path(output) if output is not None else None
    runtime = chunks.runtime_digest()
    keys = [chunks.chunk_key(module, run, P[a:b], i, runtime) for i, (a, b) in enumerate(bounds)]

    def compute(todo, finish, bar):
        if client is None:
            _run_here(module, P, run, bounds, todo, finish, bar)
        else:
            cluster.run_chunks(client, module, P, run, bounds, todo, finish, wait_for_workers=wait_for_workers,
                               notice=notice, bar=bar)

    frames, outcome = in_chunks(keys, P, bounds, [*module.PARAM_NAMES, *RESULT_COLUMNS], out, compute,
                                desc=module.SCENE, progress=progress, prune=prune, notice=notice)
    outcome.rows = (_concat(frames) if frames else rows.case_table(module, P[:0], run))
    if out is not None:
        with_units = written_names(module)
        written = outcome.rows.rename_columns([with_units[name] for name in outcome.rows.column_names])
        outcome.parquet, outcome.csv = write_tables(out / f"{module.SCENE}-sweep", written, {
            "scene": module.SCENE, "scene_digest": getattr(module, "SCENE_DIGEST", None),
            "model_digest": keys[0]["model_digest"] if keys else chunks.model_digest(module),
            "runtime_version": __version__, "runtime_digest": runtime, "settings": run,
            "cases": int(P.shape[0]), "chunk_size": chunk_size, "chunks": [chunks.chunk_name(key) for key in keys]})
    outcome.seconds = time.perf_counter() - start
    return outcome


def in_chunks(keys: list[dict], P: np.ndarray, bounds: list[tuple[int, int]], column_names: list[str],
              out: Path | None, compute, *, desc: str, progress: bool, prune: bool, notice=None):
    """(the chunks' tables in order, SweepOutcome without rows): each chunk (rows P[a:b] of ``bounds``,
    its key in ``keys``) read from out/chunks when its file proves it holds them (``chunks.read_chunk``),
    the others computed by ``compute(todo, finish, bar)``, which calls ``finish(i, table)`` for each
    (written there atomically at once). Ctrl-C raises SweepInterrupted, a lost cluster
    SweepClusterLost, after the chunks finished so far are on disk."""
    names = [chunks.chunk_name(key) for key in keys]
    tables: dict[int, object] = {}
    outcome = SweepOutcome(rows=None, parquet=None, csv=None)
    todo = []
    for i, name in enumerate(names):
        path = out / "chunks" / name if out is not None else None
        if path is None or not path.exists():
            todo.append(i)
            continue
        table, why = chunks.read_chunk(path, keys[i], P[bounds[i][0]:bounds[i][1]], column_names)
        if table is None:
            outcome.rejected.append((i, why))
            outcome.warnings.append(f"chunk {i} ({path}): {why}; recomputing it")
            todo.append(i)
        else:
            tables[i] = table
            outcome.skipped.append(i)
    if out is not None:
        _report_stale(outcome, out / "chunks", set(names), prune)

    def finish(i, table):
        if out is not None:
            chunks.write_chunk(out / "chunks" / names[i], table, keys[i])
        tables[i] = table
        outcome.computed.append(i)

    if outcome.skipped and todo:
        (notice or LOG.info)(f"resuming: {len(outcome.skipped)} of {len(bounds)} chunks are already complete in "
                             f"{out / 'chunks'}; computing the other {len(todo)}")
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(bounds), initial=len(outcome.skipped), unit="chunk", desc=desc)
    try:
        compute(todo, finish, bar)
    except KeyboardInterrupt:
        raise SweepInterrupted(f"interrupted: {_safe(outcome, len(bounds), out)}") from None
    except cluster.ClusterError as error:
        raise SweepClusterLost(f"{error}\n{_safe(outcome, len(bounds), out)}") from None
    finally:
        if bar:
            bar.close()
    return [tables[i] for i in range(len(bounds))], outcome


def write_tables(stem: Path, written, provenance: dict) -> tuple[Path, Path]:
    """The table (a pyarrow Table, units in its column names) as STEM.parquet and STEM.csv, and what
    produced it (``provenance`` and the columns) as STEM.json, each written atomically."""
    parquet = write_atomic(stem.with_name(stem.name + ".parquet"), columns.parquet(written))
    csv = write_atomic(stem.with_name(stem.name + ".csv"), _csv_bytes(written))
    write_atomic(stem.with_name(stem.name + ".json"), json.dumps({**provenance, "columns": written.column_names},
                                                                 indent=2, default=str))
    return parquet, csv


def _concat(frames: list):
    import pyarrow as pa

    return pa.concat_tables(frames)


def _report_stale(outcome: SweepOutcome, directory: Path, expected: set[str], prune: bool) -> None:
    outcome.stale = chunks.stale_files(directory, expected)
    if not outcome.stale:
        return
    if prune:
        for path in outcome.stale:
            path.unlink(missing_ok=True)
        outcome.pruned = True
        outcome.warnings.append(f"pruned {plural(len(outcome.stale), 'stale file')} from {directory}")
    else:
        verb = "belongs" if len(outcome.stale) == 1 else "belong"
        outcome.warnings.append(f"{plural(len(outcome.stale), 'file')} in {directory} {verb} to no chunk of this sweep "
                                "(another model, runtime, setting or grid, or left by a crash); --prune removes them")


def _safe(outcome: SweepOutcome, total: int, out: Path | None) -> str:
    """How many chunks are safe on disk, and how to resume."""
    done = len(outcome.skipped) + len(outcome.computed)
    return (f"{done} of {plural(total, 'chunk')} {'is' if total == 1 else 'are'} complete in {out / 'chunks'}; rerun the same command to resume from "
            "them" if out is not None else "nothing was saved (no -o DIR)")


def _run_here(module, P, run, bounds, todo, finish, bar) -> None:
    """Compute the chunks ``todo`` in this process on all cores; ``finish`` stores each."""
    from tswm_runtime.sweeps import rows

    for i in todo:
        a, b = bounds[i]
        finish(i, rows.case_table(module, P[a:b], run))
        if bar:
            bar.update()
