"""The scene file's rules for parameter values, applied to free values at run time.

The scene reader records every model parameter's rule; a generated module carries
those that involve a free parameter as plain data (``PARAM_CHECKS``), so a value set
with ``--set``, ``simulate(params=...)`` or a sweep is held to the same rules as the
scene file's, without SymPy or the scene reader. A check is one of

    ("range", name, key, lo, hi, lo_inclusive, hi_inclusive, allowed)
    ("bound", name, key, lo, hi, allowed)         lo <= value(name) <= hi: where arithmetic holds
    ("less", name, key, other, allowed)          value(name) < value(other)
    ("jam", gamma, key, rho_key, law, allowed)   gamma + largest friction angle < 90 deg

``allowed`` is the rule as the scene reader words it, in display units.
"""
from __future__ import annotations

import math
from types import ModuleType

import numpy as np

DEG = math.pi / 180


def _largest_friction_angle(law: str, value):
    """rho at v = 0 [rad] from the key that sets it: rho itself, or c (rho(0) = 1/c deg)."""
    return value if law == "constant" else DEG / value


def _holds(check: tuple, value, finite=np.isfinite) -> np.ndarray:
    """Where ``check`` holds, for arrays (or numbers) of parameter values (``value(name)``); called
    under np.errstate(all="ignore"), or for plain floats with ``finite`` = math.isfinite."""
    kind = check[0]
    if kind == "range":
        _, name, _, lo, hi, lo_in, hi_in, _ = check
        x = value(name)
        ok = finite(x)
        if lo is not None:
            ok &= (x >= lo) if lo_in else (x > lo)
        if hi is not None:
            ok &= (x <= hi) if hi_in else (x < hi)
        return ok
    if kind == "bound":
        x = value(check[1])
        return finite(x) & (x >= check[3]) & (x <= check[4])
    if kind == "less":
        return value(check[1]) < value(check[3])
    if kind == "jam":
        _, gamma, _, rho_key, law, _ = check
        return value(gamma) + _largest_friction_angle(law, value(rho_key)) < 90 * DEG
    raise ValueError(f"unknown parameter check {kind!r}")


def _message(module: ModuleType, check: tuple, value) -> str:
    units = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS))

    def show(name: str) -> str:
        return f"{name} = {float(value(name)):.9g} {units.get(name, '')}".rstrip()

    kind = check[0]
    if kind == "range":
        return f"parameter {show(check[1])}: must be {check[7]} ({check[2]} in the scene file)"
    if kind == "bound":
        return f"parameter {show(check[1])}: must be {check[5]} ({check[2]} in the scene file)"
    if kind == "less":
        return f"parameter {show(check[1])}: must be {check[4]} ({show(check[3])})"
    return f"parameters {show(check[1])} and {show(check[3])}: must keep {check[5]}"


def violations(module: ModuleType, P: np.ndarray) -> list[str]:
    """Per row of free parameters P (PARAM_NAMES order), '' or why the row breaks a rule."""
    P = np.atleast_2d(np.asarray(P, dtype=np.float64))
    # one row (simulate's every call): numbers, not arrays of one (numpy's per-call cost was ~25 us a row)
    free = {name: P[0, j] if P.shape[0] == 1 else P[:, j] for j, name in enumerate(module.PARAM_NAMES)}

    def value(name: str):
        return free[name] if name in free else module.FIXED[name]

    reasons = [""] * P.shape[0]
    with np.errstate(all="ignore"):
        held = [(check, _holds(check, value)) for check in getattr(module, "PARAM_CHECKS", ())]
    for check, ok in held:
        if ok is True or (np.ndim(ok) == 0 and ok):
            continue
        bad = ~np.broadcast_to(ok, (P.shape[0],))
        for row in np.flatnonzero(bad):
            if not reasons[row]:
                reasons[row] = _message(module, check, lambda n: np.broadcast_to(value(n), (P.shape[0],))[row])
    return reasons


def row_check(module: ModuleType):
    """``ok(row)``: whether a row of free values (plain floats, PARAM_NAMES order) keeps every rule of
    the module's PARAM_CHECKS, as one expression in plain float arithmetic compiled once per module
    (``_holds`` on each check cost ~1 us; this a tenth of it). Its text holds only ``r[j]`` (free
    values), ``c[k]`` (the rules' numbers and fixed values) and operators. It may raise
    ArithmeticError (a check that divides by zero); ``row_violation`` words a row that fails."""
    known = _ROW_CHECKS.get(module)
    if known is None:
        known = _compiled_check(module)
        if len(_ROW_CHECKS) >= 256:
            _ROW_CHECKS.clear()
        _ROW_CHECKS[module] = known
    return known


_ROW_CHECKS: dict = {}


def _compiled_check(module: ModuleType):
    free = {name: j for j, name in enumerate(module.PARAM_NAMES)}
    constants: list[float] = []

    def number(value) -> str:
        constants.append(float(value))
        return f"c[{len(constants) - 1}]"

    def value(name: str) -> str:
        return f"r[{free[name]}]" if name in free else number(module.FIXED[name])

    terms = []
    for check in getattr(module, "PARAM_CHECKS", ()):
        kind = check[0]
        if kind == "range":
            _, name, _, lo, hi, lo_in, hi_in, _ = check
            x = value(name)
            terms.append(f"isfinite({x})")
            if lo is not None:
                terms.append(f"{x} {'>=' if lo_in else '>'} {number(lo)}")
            if hi is not None:
                terms.append(f"{x} {'<=' if hi_in else '<'} {number(hi)}")
        elif kind == "bound":
            x = value(check[1])
            terms.append(f"isfinite({x}) and {number(check[3])} <= {x} <= {number(check[4])}")
        elif kind == "less":
            terms.append(f"{value(check[1])} < {value(check[3])}")
        elif kind == "jam":
            _, gamma, _, rho_key, law, _ = check
            rho = value(rho_key) if law == "constant" else f"{number(DEG)} / {value(rho_key)}"
            terms.append(f"{value(gamma)} + {rho} < {number(90 * DEG)}")
        else:
            raise ValueError(f"unknown parameter check {kind!r}")
    code = compile(f"lambda r: {' and '.join(f'({t})' for t in terms) or 'True'}", "<parameter checks>", "eval")
    return eval(code, {"__builtins__": {}, "isfinite": math.isfinite, "c": tuple(constants)})  # noqa: S307


def row_violation(module: ModuleType, row) -> str:
    """'' or why one row of free values (plain floats, PARAM_NAMES order) breaks a rule: checked in
    plain float arithmetic (numpy cost ~15 us a row, this ~2 us); a row that fails, or whose check
    divides by zero, gets ``violations``' answer and message."""
    free = dict(zip(module.PARAM_NAMES, row))

    def value(name: str):
        return free[name] if name in free else module.FIXED[name]

    try:
        if all(_holds(check, value, math.isfinite) for check in getattr(module, "PARAM_CHECKS", ())):
            return ""
    except ArithmeticError:
        pass
    return violations(module, [list(row)])[0]
