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

import numpy as np

from tswm_runtime.model.scenes import load_chain_variant
from tswm_runtime.simulation.chain import simulate_chain

NAME = re.compile(r"voltage|mu_[1-9]")
COLUMNS = ("status", "t_trip [s]", "thrust at trip", "peak after trip", "extra travel", "holds", "stall margin")


class ChainSweepError(ValueError):
    """A bad --grid for a chain sweep; the message names it."""


def parse_grid(specs: list[str], stages: int) -> dict[str, list[float]]:
    """NAME=START:STOP:COUNT, NAME=V1,V2,... or NAME=VALUE for voltage and mu_1 .. mu_N (plain numbers)."""
    grid: dict[str, list[float]] = {}
    for spec in specs:
        name, _, values = spec.partition("=")
        if not NAME.fullmatch(name) or (name.startswith("mu_") and int(name[3:]) > stages):
            raise ChainSweepError(f"--grid {spec!r}: a chain sweeps voltage and mu_1 .. mu_{stages}")
        if name in grid:
            raise ChainSweepError(f"--grid {spec!r}: {name} given twice")
        try:
            if values.count(":") == 2:
                start, stop, count = values.split(":")
                if not count.isdigit() or not 1 <= int(count) <= 1000:
                    raise ValueError("COUNT must be an integer in [1, 1000]")
                numbers = [float(x) for x in np.linspace(float(start), float(stop), int(count))]
            else:
                numbers = [float(x) for x in values.split(",")]
        except ValueError as error:
            raise ChainSweepError(f"--grid {spec!r}: expected NAME=START:STOP:COUNT or NAME=V1,V2,... ({error})") \
                from None
        if not all(math.isfinite(x) for x in numbers):
            raise ChainSweepError(f"--grid {spec!r}: values must be finite")
        grid[name] = numbers
    if not grid:
        raise ChainSweepError("--grid: give voltage=... and/or mu_k=... for a chain")
    return grid


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
