"""Units accepted in scene files: a small table and a parser for "4.76 deg" or plain SI numbers."""

import math
import re

from tswm_common.text import printable

# quantity -> {unit: factor to SI}; the first unit is the SI unit tswm stores.
UNITS: dict[str, dict[str, float]] = {
    "mass": {"kg": 1.0, "g": 1e-3, "t": 1e3},
    "length": {"m": 1.0, "mm": 1e-3},
    "angle": {"rad": 1.0, "deg": math.pi / 180},
    "force": {"N": 1.0, "kN": 1e3},
    "velocity": {"m/s": 1.0, "mm/s": 1e-3},
    "time": {"s": 1.0, "ms": 1e-3},
    "stiffness": {"N/m": 1.0, "N/mm": 1e3, "kN/mm": 1e6},
    "damping": {"N s/m": 1.0, "kN s/m": 1e3},
    "inertia": {"kg m^2": 1.0, "g m^2": 1e-3},      # moment of inertia of a rotating body (chains)
    "torque": {"N m": 1.0, "kN m": 1e3},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "bar": 1e5, "MPa": 1e6},   # a valve's differential pressure (chains)
    "area": {"m^2": 1.0, "cm^2": 1e-4, "mm^2": 1e-6},
    "dimensionless": {"": 1.0},
}
DISPLAY = {"angle": "deg"}  # unit used in messages where it is not the SI unit
# quantity -> (smallest, largest) magnitude of a value in SI (smallest: of a nonzero one; None: any).
# Products of these (F / m, k x, m v^2, c v) stay below 1e40 and their ratios above 1e-40, far from
# where doubles overflow (1.8e308) or underflow, so a scene inside them computes finite numbers;
# m2 = 1e308 kg made S1 = inf, forces of 1e300 N NaN states. Velocities reach 1e12 m/s: a linear
# drive with V0 = 1e12 m/s is the usual way to write a constant force with a speed term.
LIMITS: dict[str, tuple[float | None, float]] = {
    "mass": (1e-9, 1e9),
    "force": (None, 1e12),
    "length": (None, 1e6),
    "velocity": (None, 1e12),
    "time": (None, 1e9),
    "stiffness": (None, 1e15),
    "damping": (None, 1e12),
    "inertia": (1e-12, 1e9),
    "torque": (None, 1e12),
    "pressure": (None, 1e12),
    "area": (None, 1e6),
}

_QUANTITY = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*")


class UnitError(ValueError):
    """A value that is not a finite number with a unit of the expected quantity."""


def si_unit(quantity: str) -> str:
    """The SI unit stored for a quantity ("" when dimensionless)."""
    return next(iter(UNITS[quantity]))


def display_unit(quantity: str) -> str:
    """The unit used to show values of a quantity in messages."""
    return DISPLAY.get(quantity, si_unit(quantity))


def in_display(value: float, quantity: str) -> float:
    """An SI value converted to the display unit."""
    return value / UNITS[quantity][display_unit(quantity)]


def show(value: float, quantity: str) -> str:
    """An SI value as text in the display unit, e.g. "4.76 deg"."""
    return f"{in_display(value, quantity):g} {display_unit(quantity)}".rstrip()


def to_si(raw: object, quantity: str) -> float:
    """Convert a plain number (already SI) or a string "<number> <unit>" to SI."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float, str)):
        raise UnitError(f"expected {_expected(quantity)}")
    if isinstance(raw, str):
        number, unit = _split(raw, quantity)
        value = number * UNITS[quantity][unit]
    else:
        value = float(raw)
    if not math.isfinite(value):
        raise UnitError("must be a finite number")
    return value


def written(raw: object, quantity: str) -> tuple[float, str] | None:
    """(number, unit) of a valid value written with a unit other than the SI unit ("4.76 deg"), else None."""
    if not isinstance(raw, str) or quantity == "dimensionless":
        return None
    number, unit = _split(raw, quantity)
    return None if unit == si_unit(quantity) else (number, unit)


def factor(unit: str) -> float:
    """The factor to SI of a unit in the table."""
    return next(table[unit] for table in UNITS.values() if unit in table)
def out_of_bounds(value: float, quantity: str) -> str | None:
    """Why an SI value lies outside LIMITS for its quantity ("|value| must be <= 1e+12 N"), or None."""
    if quantity not in LIMITS:
        return None
    smallest, largest = LIMITS[quantity]
    unit = si_unit(quantity)
    if abs(value) > largest:
        return f"|value| must be <= {largest:g} {unit} (where double arithmetic holds)"
    if smallest is not None and 0.0 < abs(value) < smallest:
        return f"|value| must be >= {smallest:g} {unit} (where double arithmetic holds)"
    return None


def describe(raw: int | float | str, quantity: str) -> str:
    """A valid value as written, followed by its display-unit value when that reads differently."""
    shown = show(to_si(raw, quantity), quantity)
    if isinstance(raw, str):
        number, unit = _split(raw, quantity)
        written = f"{number:g} {unit}"
    else:
        written = f"{raw:g} {si_unit(quantity)}".rstrip()
    return shown if written == shown else f"{written} (= {shown})"


def _split(raw: str, quantity: str) -> tuple[float, str]:
    """Number and unit of a string such as "4.76 deg", checked against the quantity."""
    if quantity == "dimensionless":
        raise UnitError(f"expected {_expected(quantity)}")
    match = _QUANTITY.fullmatch(raw)
    if not match:
        raise UnitError(f"expected {_expected(quantity)}")
    unit = match[2]
    if unit not in UNITS[quantity]:
        owner = next((q for q, table in UNITS.items() if unit in table), None)
        if not unit:
            problem = "missing unit"
        elif owner:
            problem = f"'{printable(unit)}' is {article(owner)} {owner} unit"
        else:
            problem = f"unknown unit '{printable(unit)}'"
        raise UnitError(f"{problem}; expected {_expected(quantity)}")
    return float(match[1]), unit


def _expected(quantity: str) -> str:
    """What a value of the quantity may look like, for messages."""
    if quantity == "dimensionless":
        return "a plain number (dimensionless)"
    names = ", ".join(UNITS[quantity])
    return (f"{article(quantity)} {quantity}: a plain number in {si_unit(quantity)} or '<number> <unit>' "
            f"with unit {names}")


def article(word: str) -> str:
    """'an' before a vowel sound, else 'a' (the quantity names here have no silent letters)."""
    return "an" if word[:1].lower() in "aeiou" else "a"
