"""The scene file's rules for parameter values, applied to free values at run time.

The scene reader records every model parameter's rule; a generated module carries
those that involve a free parameter as plain data (``PARAM_CHECKS``), so a value set
with ``--set``, ``simulate(params=...)`` or a sweep is held to the same rules as the
scene file's, without SymPy or the scene reader. A check is one of

    ("range", name, key, lo, hi, lo_inclusive, hi_inclusive, allowed)
    ("bound", name, key, lo, hi, allowed)         lo <= value(name) <= hi: where arithmetic holds
    ("less", name, key, other, allowed)          value(name) < value(other)
    ("at_most", name, key, other, allowed)       value(name) <= value(other)
    ("jam", gamma, key, rho_key, law, allowed)   gamma + largest friction angle < 90 deg

``allowed`` is the rule as the scene reader words it, in display units. A chain module carries its
values' ranges instead (``PARAM_RANGES``, beside ``PARAM_KEYS``); ``module_checks`` words them as these
checks, and each stage's jam rule as a "jam" check on the slope and effective friction angle that the
module's ``prepare`` derives (slots of its p named in ``P_NAMES``, which ``violations`` fills for them).
Every message names the value with its unit (angles in degrees), the rule and the scene file's key.
"""
from __future__ import annotations

import math
from types import ModuleType

import numpy as np

from tswm_common import units
from tswm_runtime.common.memo import remembered
from tswm_runtime.model.values import quantities

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
    if kind == "at_most":
        return value(check[1]) <= value(check[3])
    if kind == "jam":
        _, gamma, _, rho_key, law, _ = check
        return value(gamma) + _largest_friction_angle(law, value(rho_key)) < 90 * DEG
    raise ValueError(f"unknown parameter check {kind!r}")


def _message(module: ModuleType, check: tuple, value) -> str:
    known = quantities(module)

    def show(name: str, quantity: str | None = None) -> str:
        si, quantity = known.get(name, ("", quantity))
        if quantity in units.DISPLAY:
            return f"{name} = {units.in_display(float(value(name)), quantity):.9g} {units.display_unit(quantity)}"
        return f"{name} = {float(value(name)):.9g} {si or ''}".rstrip()

    kind = check[0]
    if kind == "range":
        return f"parameter {show(check[1])}: must be {check[7]} ({check[2]} in the scene file)"
    if kind == "bound":
        return f"parameter {show(check[1])}: must be {check[5]} ({check[2]} in the scene file)"
    if kind in ("less", "at_most"):
        return f"parameter {show(check[1])}: must be {check[4]} ({show(check[3])}; {check[2]} in the scene file)"
    return (f"parameters {show(check[1], 'angle')} and {show(check[3], 'angle')}: must keep {check[5]} ({check[2]} in "
            "the scene file)")


def module_checks(module: ModuleType) -> tuple:
    """The module's rules as checks: its PARAM_CHECKS, or a chain module's ranges and jam rules
    (``_chain_checks``), worded once per module."""
    if not hasattr(module, "PARAM_RANGES"):
        return getattr(module, "PARAM_CHECKS", ())
    return remembered(_CHAIN_CHECKS, module, lambda: _chain_checks(module))


_CHAIN_CHECKS: dict = {}


def _chain_checks(module: ModuleType) -> tuple:
    """A chain module's PARAM_RANGES (lo, hi, lo included, hi included; None: no bound; hi the name of a
    sibling value, which the value must stay below, or at most equal where hi is included) as "range" and "less" or
    "at_most" checks, and per stage the scene
    reader's jam rule: slope + effective friction angle (derived by ``prepare``) < 90 deg."""
    checks = []
    for name, key, (lo, hi, lo_in, hi_in) in zip(module.PARAM_NAMES, module.PARAM_KEYS, module.PARAM_RANGES):
        quantity = quantities(module)[name][1] or "dimensionless"
        sibling = hi if isinstance(hi, str) else None
        bound = [f"{'>=' if lo_in else '>'} {units.show(lo, quantity)}" if lo is not None else "",
                 f"{'<=' if hi_in else '<'} {sibling or units.show(hi, quantity)}" if hi is not None else ""]
        checks.append(("range", name, key, lo, None if sibling else hi, lo_in, hi_in,
                       " and ".join(b for b in bound if b) or "finite"))
        if sibling:
            checks.append(("at_most", name, key, sibling, f"<= {sibling}") if hi_in else
                          ("less", name, key, sibling, f"< {sibling}"))
    for k in range(module.STAGES):
        checks.append(("jam", module.P_NAMES[module.P_GAMMA + k], f"stage[{k + 1}]", module.P_NAMES[module.P_RHO + k],
                       "constant", "slope + effective friction angle < 90 deg, else the stage jams"))
    return tuple(checks)


def _derived(module: ModuleType, P: np.ndarray) -> dict:
    """A chain module's derived slots (P_NAMES from P_DERIVED on) for rows P of its values, by its prepare."""
    p = np.zeros((P.shape[0], len(module.P_NAMES)))
    p[:, module.P_VALUES:module.P_DERIVED] = P
    for row in p:
        module.prepare(row)
    return {name: p[0, j] if P.shape[0] == 1 else p[:, j]
            for j, name in enumerate(module.P_NAMES) if j >= module.P_DERIVED}


def violations(module: ModuleType, P: np.ndarray) -> list[str]:
    """Per row of free parameters P (PARAM_NAMES order), '' or why the row breaks a rule."""
    P = np.atleast_2d(np.asarray(P, dtype=np.float64))
    # one row (simulate's every call): numbers, not arrays of one (numpy's per-call cost was ~25 us a row)
    free = {name: P[0, j] if P.shape[0] == 1 else P[:, j] for j, name in enumerate(module.PARAM_NAMES)}

    derived: dict = {}

    def value(name: str):
        if name in free:
            return free[name]
        if hasattr(module, "PARAM_RANGES"):    # a chain module: its derived slots, worked out once
            if not derived:
                derived.update(_derived(module, P))
            return derived[name]
        return module.FIXED[name]

    reasons = [""] * P.shape[0]
    with np.errstate(all="ignore"):
        held = [(check, _holds(check, value)) for check in module_checks(module)]
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
    return remembered(_ROW_CHECKS, module, lambda: _compiled_check(module))


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
        elif kind == "at_most":
            terms.append(f"{value(check[1])} <= {value(check[3])}")
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
