"""Free-parameter values as users write them: a number in SI units or a string with a unit of the
parameter's quantity ("-5 kN", "200 kg", "4.76 deg"), converted to SI with the scene units table."""
from __future__ import annotations

import math
from types import ModuleType

from tswm_common import units
from tswm_common.text import printable
from tswm_runtime.common.memo import remembered


class ValueInputError(ValueError):
    """A parameter value that cannot be read as a number of the parameter's quantity."""


def si_value(module: ModuleType, name: str, value):
    """``value`` of free parameter ``name`` in SI: numbers pass through; a string is a number with
    or without a unit of the parameter's quantity. A finite value outside ``units.LIMITS`` of its
    quantity is refused. Unknown names pass through unchanged (the caller refuses them with the
    list of free parameters)."""
    si, quantity = quantities(module).get(name, (None, None))
    if isinstance(value, str):
        value = _from_text(name, value, si, quantity)
    try:
        number = float(value)
    except (TypeError, ValueError):
        return value   # not a number: the caller refuses it
    problem = units.out_of_bounds(number, quantity) if quantity and math.isfinite(number) else None
    if problem:
        raise ValueInputError(f"parameter {name} = {number:g} {si}".rstrip() + f": {problem}")
    return value


def quantities(module: ModuleType) -> dict:
    """{free parameter: (its SI unit, its quantity or None)}, worked out once per module."""
    def build():
        quantity = {units.si_unit(q): q for q in units.UNITS}
        return {name: (si, quantity.get(si)) for name, si in zip(module.PARAM_NAMES, module.PARAM_UNITS)}
    return remembered(_QUANTITIES, module, build)


_QUANTITIES: dict = {}


def _from_text(name: str, value: str, si: str | None, quantity: str | None):
    """A string value in SI: a plain number, or a number with a unit of the parameter's quantity."""
    text = value.strip()
    try:
        return float(text)
    except ValueError:
        pass
    if si is None:
        return value
    if quantity is None:
        raise ValueInputError(f"parameter {name} = '{printable(value)}': must be a number in {si or 'SI units'}")
    try:
        return units.to_si(text, quantity)
    except units.UnitError as error:
        raise ValueInputError(f"parameter {name} = '{printable(value)}': {error}") from None
