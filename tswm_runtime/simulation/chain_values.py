"""A chain scene's values as a run takes them: by name (the module's PARAM_NAMES, and ``voltage``, the
motor's U / U_n), numbers in SI or strings with a unit of the value's quantity (model/values.py), checked
by the ranges the scene reader applies (the module's PARAM_RANGES) and by its jam rule (a stage's slope
plus its effective friction angle, derived by the module's ``prepare``, must stay below 90 deg), both
through model/checks.py, as a scene module's free values are."""
from __future__ import annotations

from types import ModuleType

import numpy as np

from tswm_runtime.model import checks
from tswm_runtime.model.values import ValueInputError, si_value
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
    row = np.array(values)
    problem = checks.violations(module, row)[0]
    if problem:
        raise SimulationInputError(problem)
    return row, voltage
