"""A drive train's sizing table: a chain scene over a grid of its motor's voltage (``voltage``, U / U_n)
and its stages' friction coefficients (``mu_1`` .. ``mu_N``), one row of answers per case.

The cases of one module run in compiled code, many per call (``chains/batch.py``: a prange over cases,
the answers taken from each run's record there), in chunks that are written and reused as the scene
sweeps' are (``sweep.in_chunks``, ``chunks.py``: a chunk's key holds the module's file digest, the
runtime's, the settings and its rows; it is reused only when its file proves it holds them). The
voltage is a slot of the module's p, so the cases of one friction set share a module; each distinct set
of friction coefficients is its own module, derived and compiled on first use and cached
(model.scenes.load_chain_variant). A case that fails (a value refused, a run that stops) is recorded
with its status and the sweep goes on. The columns are explained in docs/drive-trains.md.
"""
from __future__ import annotations

import hashlib
import itertools
import re
from pathlib import Path
from types import ModuleType

import numpy as np
import pyarrow as pa

from tswm_runtime.chains.batch import run_cases
from tswm_runtime.chains.run import latches
from tswm_runtime.model.scenes import load_chain_variant
from tswm_runtime.simulation.chain import settings
from tswm_runtime.simulation.drive_train import UNITS, stall_margin
from tswm_runtime.simulation.simulate import SimulationInputError
from tswm_runtime.sweeps import CHAIN_CHUNK, chunks, columns
from tswm_runtime.sweeps.grid import GridError, parse_items
from tswm_runtime.sweeps.sweep import SweepOutcome, check_size, in_chunks, write_tables

NAME = re.compile(r"voltage|mu_[1-9]")
SOURCES = ("chains/batch.py", "chains/run.py", "simulation/chain.py", "simulation/drive_train.py", "sweeps/chain.py")


class ChainSweepError(ValueError):
    """A bad --grid for a chain sweep; the message names it."""


def parse_grid(specs: list[str], stages: int) -> dict[str, list[float]]:
    """The --grid items over voltage and mu_1 .. mu_N (sweeps/grid.py: ranges, lists or one value; plain
    numbers, both being dimensionless)."""
    def unknown(name: str) -> str | None:
        known = NAME.fullmatch(name) and (name == "voltage" or int(name[3:]) <= stages)
        return None if known else f"a chain sweeps voltage and mu_1 .. mu_{stages}"
    try:
        grid = parse_items(specs, _plain, unknown, "mu_2=0.1:0.2:3")
    except GridError as error:
        raise ChainSweepError(str(error)) from None
    if not grid:
        raise ChainSweepError("--grid: give voltage=... and/or mu_k=... for a chain")
    return {name: values.tolist() for name, values in grid.items()}


def _plain(name: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{name} = {text!r}: expected a plain number (dimensionless)") from None


def columns_of(module: ModuleType, swept: list[str]) -> list[str]:
    """The sizing table's columns, units in their names (the last body's and body 0's)."""
    thrust, torque = UNITS[module.BODY_MOTIONS[-1]], UNITS[module.BODY_MOTIONS[0]]
    travel = "m" if module.BODY_MOTIONS[-1] == "translation" else "rad"
    return [*swept, "status", "t_trip [s]", f"thrust at trip [{thrust}]", f"drive at trip [{torque}]",
            f"travel at trip [{travel}]", f"peak after trip [{thrust}]", "t_peak [s]", f"extra travel [{travel}]",
            "holds", "stall margin", "t_stop [s]", "events", "steps"]


def sizing(module: ModuleType, grid: dict[str, list[float]], overrides: dict, *, scene: str | Path | None = None,
           output: str | Path | None = None, chunk_size: int = CHAIN_CHUNK, progress: bool = False, prune: bool = False,
           notice=None) -> SweepOutcome:
    """The sizing table (``SweepOutcome.rows``, a pyarrow Table) of ``module`` over the grid's combinations,
    one row per case, voltage varying fastest; a grid over mu_k takes the variants of ``scene``.
    ``overrides``: run settings (t_end, rtol, atol, method, max_steps, max_events); ``output``: a directory
    for chunks/ and SCENE-sizing.parquet/.csv/.json (None: in memory only)."""
    if "voltage" in grid and not hasattr(module, "MOTOR_VOLTAGE"):
        raise ChainSweepError(f"--grid voltage: chain {module.SCENE} has no motor on body 0")
    names = [n for n in grid if n.startswith("mu_")]
    check_size(int(np.prod([len(v) for v in grid.values()])), chunk_size, large=True)
    swept = [*names, *(["voltage"] if "voltage" in grid else [])]
    voltages = np.asarray(grid.get("voltage", [getattr(module, "MOTOR_VOLTAGE", 1.0)]), dtype=float)
    run = {k: v for k, v in overrides.items() if k != "method"}
    method = overrides.get("method", 0)
    out = Path(output) if output is not None else None
    groups, keys, bounds, rows = [], [], [], []
    runtime = _runtime_digest()
    for mus in itertools.product(*(grid[n] for n in names)):
        variant, failure = module, None
        if names:
            try:
                variant = load_chain_variant(scene, {int(n[3:]): value for n, value in zip(names, mus)})
            except ValueError as error:          # SceneError: the variant jams or mu is out of range
                variant, failure = None, f"error: {error}"
        values = np.column_stack([np.full((voltages.size, len(mus)), mus), voltages])[:, :len(swept)]
        start = sum(len(r) for r in rows)
        rows.append(values)
        if failure is not None:
            groups.append((None, failure, start, values))
            continue
        settled = settings(variant, run)
        groups.append((variant, settled, start, values))
        for a in range(0, voltages.size, chunk_size):
            b = min(a + chunk_size, voltages.size)
            keys.append(chunks.chunk_key(variant, {**settled, "method": method}, values[a:b], len(keys), runtime,
                                         tuple(swept)))
            bounds.append((start + a, start + b, len(groups) - 1))
    P = np.concatenate(rows) if rows else np.empty((0, len(swept)))
    names_out = columns_of(module, swept)

    def compute(todo, finish, bar):
        for i in todo:
            a, b, g = bounds[i]
            variant, settled, start, _ = groups[g]
            finish(i, _table(variant, settled, method, P[a:b], voltages[a - start:b - start], names_out))
            if bar:
                bar.update()

    tables, outcome = in_chunks(keys, P, [(a, b) for a, b, _ in bounds], names_out, out, compute,
                                desc=module.SCENE, progress=progress, prune=prune, notice=notice)
    failed = {start: _failed(values, failure, names_out) for variant, failure, start, values in groups
              if variant is None}
    done = {bounds[i][0]: table for i, table in enumerate(tables)}
    outcome.rows = pa.concat_tables([part for _, part in sorted({**done, **failed}.items())])
    if out is not None:
        outcome.parquet, outcome.csv = write_tables(out / f"{module.SCENE}-sizing", outcome.rows, {
            "scene": module.SCENE, "runtime_digest": runtime, "settings": {**run, "method": method},
            "grid": grid, "cases": int(P.shape[0]), "chunk_size": chunk_size,
            "chunks": [chunks.chunk_name(key) for key in keys],
            "models": sorted({key["model_digest"] for key in keys})})
    return outcome


def _runtime_digest() -> str:
    """The scene sweeps' runtime digest and the chain sweep's own sources: a changed answer never reuses
    old rows."""
    h = hashlib.sha256(chunks.runtime_digest().encode())
    here = Path(__file__).parents[1]   # tswm_runtime/
    for name in SOURCES:
        h.update(name.encode() + (here / name).read_bytes())
    return h.hexdigest()


def _table(module: ModuleType, run: dict, method: int, values: np.ndarray, voltages: np.ndarray, names: list[str]):
    """The chunk's rows: its cases run in one batch; a voltage the run settings refuse is recorded with
    the refusal (not run)."""
    refused = _refusals(module, run, voltages)
    ok = ~np.isin(voltages, list(refused))
    P = np.tile(latches(module, np.array([0.0, run["v0"]])), (int(ok.sum()), 1))
    P[:, module.P_VOLTAGE] = voltages[ok]
    a = run_cases(module, P, t_end=run["t_end"], v0=run["v0"], rtol=run["rtol"], atol=run["atol"],
                  t_out=np.linspace(0.0, run["t_end"], run["points"]), method=method, max_steps=run["max_steps"],
                  max_events=run["max_events"])
    status = np.empty(voltages.size, np.int64)
    status[ok] = a.status
    status[~ok] = len(a.status_words) + np.searchsorted(list(refused), voltages[~ok])

    def spread(x, fill=np.nan):
        full = np.full(voltages.size, fill, dtype=np.asarray(x).dtype)
        full[ok] = x
        return full

    verdict = spread(a.verdict, len(a.verdict_words))
    numbers = [a.t_trip, a.thrust, a.drive, a.travel, a.peak, a.t_peak, a.extra_travel]
    margin = stall_margin(module, spread(a.thrust), voltages)
    cells = [*(columns.numbers(np.ascontiguousarray(values[:, k])) for k in range(values.shape[1])),
             columns.texts([*a.status_words, *refused.values()], status), *(columns.numbers(spread(x)) for x in numbers),
             columns.texts([*a.verdict_words, "-"], verdict), columns.numbers(margin), columns.numbers(spread(a.t_stop)),
             columns.numbers(spread(a.events, 0)), columns.numbers(spread(a.steps, 0))]
    return columns.table(dict(zip(names, cells)))


def _refusals(module: ModuleType, run: dict, voltages: np.ndarray) -> dict[float, str]:
    """The voltages the run settings refuse (the grid's distinct values outside (0, 2], in order), each with
    its status: "error: " and why (the check itself: simulation.chain.settings)."""
    refused = {}
    for v in np.unique(voltages[~((voltages > 0.0) & (voltages <= 2.0))]).tolist():
        try:
            settings(module, {**run, "voltage": v})
        except SimulationInputError as error:
            refused[v] = f"error: {error}"
    return refused


def _failed(values: np.ndarray, status: str, names: list[str]):
    """Rows of cases not run (their module refused): their values, the status, NaN or - elsewhere."""
    n, k = values.shape
    cells = [columns.numbers(np.ascontiguousarray(values[:, j])) for j in range(k)]
    cells.append(columns.texts([status], np.zeros(n)))
    for name in names[k + 1:]:
        if name == "holds":
            cells.append(columns.texts(["-"], np.zeros(n)))
        elif name in ("events", "steps"):
            cells.append(columns.numbers(np.zeros(n, np.int64)))
        else:
            cells.append(columns.numbers(np.full(n, np.nan)))
    return columns.table(dict(zip(names, cells)))
