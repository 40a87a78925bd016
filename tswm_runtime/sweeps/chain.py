"""A drive train's sizing table: a chain scene over a grid of any of its values (the module's
PARAM_NAMES: ``mu_1``, ``force_2``, ...) and its motor's voltage (``voltage``, U / U_n), one row of
answers per case.

Every value is a slot of the module's parameter vector p, so all cases run on one module, compiled
once; each case's values are checked as the scene reader would (simulation/chain_values.py) and its p
prepared (``chains.run.latches``: the module's ``prepare`` derives the slopes, friction angles, FTFs).
The cases run in compiled code, many per call (``chains/batch.py``: a prange over cases, the answers
taken from each run's record there), in chunks that are written and reused as the scene sweeps' are
(``sweep.in_chunks``, ``chunks.py``: a chunk's key holds the module's file digest, the runtime's, the
settings and its rows; it is reused only when its file proves it holds them). A case that fails (a
value out of its range, a stage that jams, a run that stops) is recorded with its status and the sweep
goes on. The columns are explained in docs/drive-trains.md.
"""
from __future__ import annotations

import itertools
from pathlib import Path
from types import ModuleType

import numpy as np
import pyarrow as pa

from tswm_runtime.jit import coldstart

coldstart.announce(("integrate", "chain", "chain-batch"))  # before the next import compiles them, if not cached

from tswm_runtime.chains.batch import run_cases  # noqa: E402
from tswm_runtime.chains.run import clearance_stages, latches  # noqa: E402
from tswm_runtime.model.values import ValueInputError, quantities, si_value  # noqa: E402
from tswm_runtime.simulation.chain import settings  # noqa: E402
from tswm_runtime.simulation.chain_values import chain_values, unknown_value  # noqa: E402
from tswm_runtime.simulation.drive_train import UNITS  # noqa: E402
from tswm_runtime.simulation.simulate import SimulationInputError  # noqa: E402
from tswm_runtime.sweeps import CHAIN_CHUNK, chunks, columns  # noqa: E402
from tswm_runtime.sweeps.grid import GridError, parse_items  # noqa: E402
from tswm_runtime.sweeps.sweep import SweepOutcome, check_size, in_chunks, write_tables  # noqa: E402

SOURCES = ("chains/answers.py", "chains/batch.py", "chains/run.py", "simulation/chain.py", "simulation/chain_values.py",
           "simulation/drive_train.py", "sweeps/chain.py")


class ChainSweepError(ValueError):
    """A bad --grid for a chain sweep; the message names it."""


def parse_grid(specs: list[str], module) -> dict[str, list[float]]:
    """The --grid items over the chain's values and voltage (sweeps/grid.py: ranges, lists or one value;
    numbers in SI or with a unit of the value's quantity)."""
    names = {*module.PARAM_NAMES, *(("voltage",) if hasattr(module, "MOTOR_VOLTAGE") else ())}

    def unknown(name: str) -> str | None:
        return None if name in names else unknown_value(module, name).split(": ", 1)[1]

    def value(name: str, text: str) -> float:
        try:
            return float(si_value(module, name, text))
        except ValueInputError as error:
            raise ValueError(str(error)) from None
    try:
        grid = parse_items(specs, value, unknown, "mu_2=0.1:0.2:3")
    except GridError as error:
        raise ChainSweepError(str(error)) from None
    if not grid:
        raise ChainSweepError("--grid: give NAME=... of the chain's values (mu_1=..., voltage=...)")
    return {name: values.tolist() for name, values in grid.items()}


def columns_of(module: ModuleType, swept: list[str]) -> list[str]:
    """The sizing table's columns, units in their names (the swept values' SI units, the last body's and
    body 0's); with a clearance also the stage's impacts and the kinetic energy they lost."""
    thrust, torque = UNITS[module.BODY_MOTIONS[-1]], UNITS[module.BODY_MOTIONS[0]]
    travel = "m" if module.BODY_MOTIONS[-1] == "translation" else "rad"
    si = {name: unit for name, (unit, _) in quantities(module).items()}
    return [*(f"{name} [{si[name]}]" if si.get(name) else name for name in swept), "status", "t_trip [s]",
            f"thrust at trip [{thrust}]", f"drive at trip [{torque}]", f"travel at trip [{travel}]",
            f"peak after trip [{thrust}]", "t_peak [s]", f"extra travel [{travel}]", "holds", "stall margin",
            "t_stop [s]", "events", "steps", *(("impacts", "impact loss [J]") if clearance_stages(module) else ())]


def sizing(module: ModuleType, grid: dict[str, list[float]], overrides: dict, *, output: str | Path | None = None,
           chunk_size: int = CHAIN_CHUNK, progress: bool = False, prune: bool = False, notice=None) -> SweepOutcome:
    """The sizing table (``SweepOutcome.rows``, a pyarrow Table; ``.table`` as pandas) of ``module`` over the
    grid's combinations (values in SI), one row per case, the last name varying fastest. ``overrides``:
    run settings (t_end, rtol, atol, method, max_steps, max_events); ``output``: a directory for chunks/
    and SCENE-sizing.parquet/.csv/.json (None: in memory only)."""
    swept = list(grid)
    check_size(int(np.prod([len(v) for v in grid.values()])), chunk_size, large=True)
    run = settings(module, {k: v for k, v in overrides.items() if k != "method"})
    method = overrides.get("method", 0)
    P = np.array(list(itertools.product(*grid.values())), dtype=float).reshape(-1, len(swept))
    bounds = [(a, min(a + chunk_size, P.shape[0])) for a in range(0, P.shape[0], chunk_size)]
    runtime = chunks.runtime_digest(SOURCES)   # the chain sweep's sources besides the scene sweeps'
    names = columns_of(module, swept)
    keys = [chunks.chunk_key(module, {**run, "method": method}, P[a:b], i, runtime, tuple(names[:len(swept)]))
            for i, (a, b) in enumerate(bounds)]

    def compute(todo, finish, bar):
        for i in todo:
            a, b = bounds[i]
            finish(i, _table(module, run, method, swept, P[a:b], names))
            if bar:
                bar.update()

    tables, outcome = in_chunks(keys, P, bounds, names, Path(output) if output is not None else None, compute,
                                desc=module.SCENE, progress=progress, prune=prune, notice=notice)
    outcome.rows = pa.concat_tables(tables) if tables else _table(module, run, method, swept, P, names)
    if output is not None:
        outcome.parquet, outcome.csv = write_tables(Path(output) / f"{module.SCENE}-sizing", outcome.rows, {
            "scene": module.SCENE, "model_digest": chunks.model_digest(module), "runtime_digest": runtime,
            "settings": {**run, "method": method}, "grid": grid, "cases": int(P.shape[0]), "chunk_size": chunk_size,
            "chunks": [chunks.chunk_name(key) for key in keys]})
    return outcome


def case_rows(module: ModuleType, run: dict, swept: list[str], values: np.ndarray) -> tuple[np.ndarray, list]:
    """(p of each case that passes the checks, as rows; per case None or why it is refused, "error: ...")."""
    rows, refusals = [], []
    y0 = np.array([0.0, run["v0"]])
    for case in values.tolist():
        try:
            chosen, voltage = chain_values(module, dict(zip(swept, case)))
            if voltage is not None:
                settings(module, {**run, "voltage": voltage})
        except SimulationInputError as error:
            refusals.append(f"error: {error}")
            continue
        rows.append(latches(module, y0, voltage, chosen))
        refusals.append(None)
    return np.array(rows).reshape(-1, len(module.P_NAMES)), refusals


def _table(module: ModuleType, run: dict, method: int, swept: list[str], values: np.ndarray, names: list[str]):
    """The chunk's rows: its cases run in one batch; a case the checks refuse is recorded with why (not run)."""
    P, refusals = case_rows(module, run, swept, values)
    ok = np.array([why is None for why in refusals], dtype=bool)
    a = run_cases(module, P, t_end=run["t_end"], v0=run["v0"], rtol=run["rtol"], atol=run["atol"],
                  t_out=np.linspace(0.0, run["t_end"], run["points"]), method=method, max_steps=run["max_steps"],
                  max_events=run["max_events"])
    refused = sorted({why for why in refusals if why is not None})
    status = np.empty(ok.size, np.int64)
    status[ok] = a.status
    status[~ok] = [len(a.status_words) + refused.index(why) for why in refusals if why is not None]

    def spread(x, fill=np.nan):
        full = np.full(ok.size, fill, dtype=np.asarray(x).dtype)
        full[ok] = x
        return full

    numbers = [a.t_trip, a.thrust, a.drive, a.travel, a.peak, a.t_peak, a.extra_travel]
    cells = [*(columns.numbers(np.ascontiguousarray(values[:, k])) for k in range(values.shape[1])),
             columns.texts([*a.status_words, *refused], status), *(columns.numbers(spread(x)) for x in numbers),
             columns.texts([*a.verdict_words, "-"], spread(a.verdict, len(a.verdict_words))),
             columns.numbers(spread(a.stall_margin)),
             columns.numbers(spread(a.t_stop)), columns.numbers(spread(a.events, 0)),
             columns.numbers(spread(a.steps, 0))]
    if clearance_stages(module):
        cells += [columns.numbers(spread(a.impacts, 0)), columns.numbers(spread(a.energy_lost))]
    return columns.table(dict(zip(names, cells)))
