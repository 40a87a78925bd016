"""The --grid option of `tswm sweep`, one syntax for a scene's free parameters and for a chain's voltage
and friction coefficients.

Each item is NAME=START:STOP:COUNT (COUNT points, both ends included), NAME=V1,V2,... or NAME=VALUE;
every value is a number in SI or a number with a unit of the name's quantity ("-15 kN"), as the caller's
``value`` reads it. One limit: COUNT, the length of a list and the number of cases of the whole grid
(their product) are each at most MAX_CASES, checked before anything is built.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

MAX_CASES = 10**7
SYNTAX = "NAME=START:STOP:COUNT, NAME=V1,V2,... or NAME=VALUE"


class GridError(ValueError):
    """A --grid item that cannot be used; the message names it."""


def parse_items(items: list[str], value: Callable[[str, str], float], unknown: Callable[[str], str | None],
               example: str) -> dict[str, np.ndarray]:
    """{name: its values} of the items, in their order. ``value(name, text)`` is a value in SI (raising
    ValueError with the reason), ``unknown(name)`` why a name cannot be swept (None: it can); ``example``
    an item for the messages ("F2=-15000:0:11")."""
    grid: dict[str, np.ndarray] = {}
    for item in items:
        name, sep, spec = (s.strip() for s in item.partition("="))
        where = f"--grid {item!r}"
        if not sep or not name or not spec:
            raise GridError(f"{where}: expected {SYNTAX}, e.g. {example}")
        problem = unknown(name)
        if problem:
            raise GridError(f"--grid {name!r}: {problem}")
        if name in grid:
            raise GridError(f"{where}: {name} is given twice")
        grid[name] = _axis(where, spec, lambda text: _number(where, name, text, value), example)
    cases = math.prod(values.size for values in grid.values())
    if cases > MAX_CASES:
        raise GridError(f"--grid: {cases} cases ({' x '.join(str(v.size) for v in grid.values())}), more than the "
                        f"{MAX_CASES:.0e} one sweep runs; coarsen the grid or split it")
    return grid


def _axis(where: str, spec: str, number: Callable[[str], float], example: str) -> np.ndarray:
    parts = spec.split(":")
    if len(parts) == 1:
        texts = spec.split(",")
        if len(texts) > MAX_CASES:
            raise GridError(f"{where}: {len(texts)} values, more than {MAX_CASES:.0e}")
        return np.array([number(text) for text in texts])
    if len(parts) != 3:
        raise GridError(f"{where}: expected {SYNTAX}, e.g. {example}")
    start, stop = number(parts[0]), number(parts[1])
    try:
        count = int(parts[2])
    except ValueError:
        raise GridError(f"{where}: count {parts[2].strip()!r} is not an integer") from None
    if not 1 <= count <= MAX_CASES:
        raise GridError(f"{where}: count {count} must be in [1, {MAX_CASES:.0e}]")
    return np.linspace(start, stop, count)


def _number(where: str, name: str, text: str, value: Callable[[str, str], float]) -> float:
    text = text.strip()
    if not text:
        raise GridError(f"{where}: an empty value")
    try:
        number = float(value(name, text))
    except ValueError as error:
        raise GridError(f"{where}: {error}") from None
    if not math.isfinite(number):
        raise GridError(f"{where}: {text!r} is not finite")
    return number
