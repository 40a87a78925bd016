"""A chain scene's values as a run takes them: by name (the module's PARAM_NAMES, and ``voltage``, the
motor's U / U_n), numbers in SI or strings with a unit of the value's quantity (model/values.py), checked
by the ranges the scene reader applies (the module's PARAM_RANGES) and by its jam rule: a stage's slope
plus its effective friction angle (derived by the module's ``prepare``) must stay below 90 deg."""
from __future__ import annotations

import math
from types import ModuleType

import numpy as np

from tswm_common import units
from tswm_runtime.model.values import ValueInputError, quantities, si_value
from tswm_runtime.simulation.simulate import SimulationInputError, _finite


def unknown_value(module: ModuleType, name: str) -> str:
    """Why ``name`` cannot be set in a chain: the names it has."""
    return (f"parameter {name!r}: chain scene {module.SCENE!r} has no such value (values: "
            f"{', '.join(module.PARAM_NAMES)}{', voltage' if hasattr(module, 'MOTOR_VOLTAGE') else ''})")


def chain_values(module: ModuleType, params: dict | None) -> tuple[np.ndarray | None, float | None]:
    """(the values in PARAM_NAMES order, the scene's with ``params`` in their place; None without params,
    the voltage given or None)."""
    if not params:
        return None, None
    index = {name: j for j, name in enumerate(module.PARAM_NAMES)}
    values, voltage = list(module.PARAM_DEFAULTS), None
    for name, raw in params.items():
        if name == "voltage" and hasattr(module, "MOTOR_VOLTAGE"):
            voltage = _finite("voltage", raw)
            continue
        if name not in index:
            raise SimulationInputError(unknown_value(module, name))
        try:
            value = si_value(module, name, raw)
        except ValueInputError as error:
            raise SimulationInputError(str(error)) from None
        values[index[name]] = _finite(f"parameter {name}", value)
    for j, (lo, hi, lo_in, hi_in) in enumerate(module.PARAM_RANGES):
        _in_range(module, j, values, lo, values[index[hi]] if isinstance(hi, str) else hi, lo_in, hi_in,
                  hi if isinstance(hi, str) else None)
    row = np.array(values)
    _jams(module, row)
    return row, voltage


def _in_range(module: ModuleType, j: int, values: list, lo, hi, lo_in: bool, hi_in: bool, sibling) -> None:
    name, value = module.PARAM_NAMES[j], values[j]
    below = lo is not None and (value < lo or (value == lo and not lo_in))
    above = hi is not None and (value > hi or (value == hi and not hi_in))
    if below or above:
        quantity = quantities(module)[name][1] or "dimensionless"
        bound = [f"{'>=' if lo_in else '>'} {units.show(lo, quantity)}" if lo is not None else "",
                 f"{'<=' if hi_in else '<'} {sibling or units.show(hi, quantity)}" if hi is not None else ""]
        raise SimulationInputError(f"parameter {name} = {units.show(value, quantity)} ({module.PARAM_KEYS[j]}): "
                                   f"must be {' and '.join(b for b in bound if b)}")


def _jams(module: ModuleType, values: np.ndarray) -> None:
    """Refuse values under which a stage jams (slope + effective friction angle >= 90 deg)."""
    p = np.zeros(len(module.P_NAMES))
    p[module.P_VALUES:module.P_DERIVED] = values
    module.prepare(p)
    for k in range(module.STAGES):
        gamma, rho = p[module.P_GAMMA + k], p[module.P_RHO + k]
        if not gamma + rho < math.pi / 2:
            raise SimulationInputError(
                f"stage {k + 1}: slope {units.show(gamma, 'angle')} + effective friction angle "
                f"{units.show(rho, 'angle')} must be < 90 deg (else the stage jams)")
