"""Drive, load and friction laws of a scene as SymPy expressions.

Each builder takes the scene's ``Law`` and a function that maps a ``Param`` to its
symbol, and returns the expression together with the events the law brings (times or
positions where it jumps), so the runtime can stop there instead of stepping over.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import sympy as sp

from derivation.mechanics import t, v1
from derivation.scene import Law, Param

SymbolOf = Callable[[Param], sp.Symbol]


@dataclass(frozen=True)
class LawEvent:
    """A zero crossing at which a law jumps: ``expr`` changes sign there."""

    name: str
    expr: sp.Expr
    doc: str


def kloss_textbook(Fmax: sp.Expr, slip: sp.Expr, slip_max: sp.Expr) -> sp.Expr:
    """Kloss' motor curve as printed, singular at synchronous speed (slip = 0)."""
    return 2 * Fmax / (slip / slip_max + slip_max / slip)


def drive_force(law: Law, sym: SymbolOf) -> sp.Expr:
    """F1(v1) on body 1."""
    p = {k: sym(v) for k, v in law.params.items()}
    if law.kind == "kloss":
        slip, slip_max = p["V0"] - v1, p["V0"] - p["Vmax"]
        return sp.together(kloss_textbook(p["Fmax"], slip, slip_max))   # 2 Fmax s smax / (s^2 + smax^2)
    if law.kind == "constant":
        return p["F1"]
    if law.kind == "linear":
        return p["F0"] * (1 - v1 / p["V0"])
    raise ValueError(f"drive.law = {law.kind!r}: not a drive law")


def load_force(law: Law, sym: SymbolOf, x2: sp.Expr) -> tuple[sp.Expr, tuple[LawEvent, ...]]:
    """F2(t, x2) on body 2 and the events where it jumps."""
    p = {k: sym(v) for k, v in law.params.items()}
    if law.kind == "constant":
        return p["F2"], ()
    if law.kind == "step":
        event = LawEvent("load_step", t - p["t_step"], "the load steps at t = t_step")
        return sp.Piecewise((p["F2_before"], t < p["t_step"]), (p["F2_after"], True)), (event,)
    if law.kind == "spring":
        squeeze = x2 - p["x2_contact"]
        event = LawEvent("load_contact", squeeze, "body 2 reaches the spring at x2 = x2_contact")
        force = sp.Piecewise((0, squeeze < 0), (-(p["preload"] + p["k"] * squeeze), True))
        return force, (event,)
    raise ValueError(f"load.law = {law.kind!r}: not a load law")


def friction_angle(law: Law, sym: SymbolOf, slope: sp.Expr) -> sp.Expr:
    """rho(v1) in radians; the velocity law is the paper's, in degrees of sliding speed."""
    p = {k: sym(v) for k, v in law.params.items()}
    if law.kind == "constant":
        return p["rho"]
    if law.kind == "velocity":
        sliding_speed = sp.Abs(v1) / sp.cos(slope)
        return sp.pi / 180 / (p["a"] * sliding_speed ** p["b"] + p["c"])
    raise ValueError(f"friction.law = {law.kind!r}: not a friction law")
