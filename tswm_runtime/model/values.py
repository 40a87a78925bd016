"""Free-parameter values as users write them: a number in SI units or a string with a unit of the
parameter's quantity ("-5 kN", "200 kg", "4.76 deg"), converted to SI with the scene units table."""
from __future__ import annotations

from types import ModuleType

from tswm_common import units


class ValueInputError(ValueError):
    """A parameter value that cannot be read as a number of the parameter's quantity."""


def si_value(module: ModuleType, name: str, value):
    """``value`` of free parameter ``name`` in SI: numbers pass through; a string is a number with
    or without a unit of the parameter's quantity. Unknown names pass through unchanged (the caller
    refuses them with the list of free parameters)."""
    if not isinstance(value, str):
        return value
    text = value.strip()
    try:
        return float(text)
    except ValueError:
        pass
    si = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS)).get(name)
    if si is None:
        return value
    quantity = {units.si_unit(q): q for q in units.UNITS}.get(si)
    if quantity is None:
        raise ValueInputError(f"parameter {name} = {value!r}: must be a number in {si or 'SI units'}")
    try:
        return units.to_si(text, quantity)
    except units.UnitError as error:
        raise ValueInputError(f"parameter {name} = {value!r}: {error}") from None
