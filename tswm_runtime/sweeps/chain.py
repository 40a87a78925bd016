"""A drive train's sizing table: a chain scene over a grid of its motor's voltage (``voltage``, U / U_n)
and its stages' friction coefficients (``mu_1`` .. ``mu_N``), one row of answers per case.

A chain has no free parameters: each distinct set of friction coefficients is its own module, derived
and compiled on first use and cached (model.scenes.load_chain_variant); the voltage is read from the
module's parameter vector, so the cases of one friction set share a module. A case that fails (bad
value, a run that stops) is recorded with its status and the sweep goes on.
"""
from __future__ import annotations

import itertools
import math
import re
from pathlib import Path

from tswm_runtime.model.scenes import load_chain_variant
from tswm_runtime.simulation.chain import simulate_chain
from tswm_runtime.sweeps.grid import GridError, parse_items

NAME = re.compile(r"voltage|mu_[1-9]")
COLUMNS = ("status", "t_trip [s]", "thrust at trip", "peak after trip", "extra travel", "holds", "stall margin")


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


def sizing(scene: str | Path, grid: dict[str, list[float]], overrides: dict, notice=lambda text: None):
    """The sizing table (pandas DataFrame): one row per case of the grid's combinations."""
    import pandas as pd

    names = [n for n in grid if n.startswith("mu_")]
    voltages = grid.get("voltage", [None])
    rows = []
    for mus in itertools.product(*(grid[n] for n in names)):
        mu = {int(n[3:]): value for n, value in zip(names, mus)}
        try:
            module = load_chain_variant(scene, mu)
            failure = None
        except ValueError as error:          # SceneError: the variant jams or mu is out of range
            module, failure = None, str(error)
        for voltage in voltages:
            case = {**{n: v for n, v in zip(names, mus)}, **({"voltage": voltage} if voltage is not None else {})}
            notice(f"case {len(rows) + 1}: " + ", ".join(f"{k} = {v:g}" for k, v in case.items()))
            rows.append({**case, **(_row(module, voltage, overrides) if module else
                                    {"status": f"error: {failure}"})})
    table = pd.DataFrame(rows, columns=[*names, *(["voltage"] if "voltage" in grid else []), *COLUMNS])
    unit = "N" if module is None or module.BODY_MOTIONS[-1] == "translation" else "N m"
    travel = "m" if module is None or module.BODY_MOTIONS[-1] == "translation" else "rad"
    return table.rename(columns={"thrust at trip": f"thrust at trip [{unit}]", "peak after trip":
                                 f"peak after trip [{unit}]", "extra travel": f"extra travel [{travel}]"})


def _row(module, voltage: float | None, overrides: dict) -> dict:
    """One case's answers; a run refused or failed gives its status."""
    try:
        result = simulate_chain(module, **overrides, **({"voltage": voltage} if voltage is not None else {}))
    except ValueError as error:
        return {"status": f"error: {error}"}
    a = result.answers
    trip, peak = a["trip"], a["peak_after_trip"]
    return {"status": result.status, "t_trip [s]": trip["t"] if trip else math.nan,
            "thrust at trip": trip["thrust"] if trip and trip["thrust"] is not None else math.nan,
            "peak after trip": peak["thrust"] if peak else math.nan,
            "extra travel": a["extra_travel"] if a["extra_travel"] is not None else math.nan,
            "holds": a["holds"]["verdict"], "stall margin": a["stall_margin"] if a["stall_margin"] else math.nan}
