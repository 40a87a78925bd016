"""A drive train's sizing table: a chain scene over a grid of any of its values (the module's
PARAM_NAMES: ``mu_1``, ``force_2``, ...) and its motor's voltage (``voltage``, U / U_n), one row of
answers per case.

Every value is a slot of the module's parameter vector p, so all cases run on one module, compiled
once (tswm_runtime/simulation/chain_values.py checks each case's values as the scene reader would). A
case that fails (a value out of its range, a stage that jams, a run that stops) is recorded with its
status and the sweep goes on.
"""
from __future__ import annotations

import itertools
import math

from tswm_runtime.model.values import ValueInputError, si_value
from tswm_runtime.simulation.chain import simulate_chain
from tswm_runtime.simulation.chain_values import unknown_value
from tswm_runtime.sweeps.grid import GridError, parse_items

COLUMNS = ("status", "t_trip [s]", "thrust at trip", "peak after trip", "extra travel", "holds", "stall margin")


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


def sizing(module, grid: dict[str, list[float]], overrides: dict, notice=lambda text: None):
    """The sizing table (pandas DataFrame): one row per case of the grid's combinations, all on ``module``."""
    import pandas as pd

    names = list(grid)
    rows = []
    for values in itertools.product(*grid.values()):
        case = dict(zip(names, values))
        notice(f"case {len(rows) + 1}: " + ", ".join(f"{k} = {v:g}" for k, v in case.items()))
        rows.append({**case, **_row(module, case, overrides)})
    table = pd.DataFrame(rows, columns=[*names, *COLUMNS])
    unit = "N" if module.BODY_MOTIONS[-1] == "translation" else "N m"
    travel = "m" if module.BODY_MOTIONS[-1] == "translation" else "rad"
    return table.rename(columns={"thrust at trip": f"thrust at trip [{unit}]", "peak after trip":
                                 f"peak after trip [{unit}]", "extra travel": f"extra travel [{travel}]"})


def _row(module, case: dict, overrides: dict) -> dict:
    """One case's answers; a run refused or failed gives its status."""
    try:
        result = simulate_chain(module, case, **overrides)
    except ValueError as error:
        return {"status": f"error: {error}"}
    a = result.answers
    trip, peak = a["trip"], a["peak_after_trip"]
    return {"status": result.status, "t_trip [s]": trip["t"] if trip else math.nan,
            "thrust at trip": trip["thrust"] if trip and trip["thrust"] is not None else math.nan,
            "peak after trip": peak["thrust"] if peak else math.nan,
            "extra travel": a["extra_travel"] if a["extra_travel"] is not None else math.nan,
            "holds": a["holds"]["verdict"], "stall margin": a["stall_margin"] if a["stall_margin"] else math.nan}
