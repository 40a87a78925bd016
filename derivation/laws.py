"""Drive, load and friction laws of a scene as SymPy expressions.

Each force builder takes the scene's ``Law`` and a function that maps a ``Param`` to its
symbol, and returns the expression together with its ``Pieces`` when the law is
piecewise (a step, a spring contact, a schedule): the law is then written in terms of a
piece index that the runtime latches per segment, so no integration step ever sees the
law jump or kink; the breakpoints are events (segment boundaries) instead.
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
    """A breakpoint of a law: ``expr`` rises through 0 where the law passes it."""

    name: str
    expr: sp.Expr
    doc: str


@dataclass(frozen=True)
class Pieces:
    """A piecewise law's latched piece index: the number of its events whose expr is >= 0.

    The runtime sets ``symbol`` (a slot of the parameter vector) at the start and after
    every event of the law, so inside a segment the law is one smooth piece.
    """

    symbol: sp.Symbol
    events: tuple[LawEvent, ...]
    doc: str


def piecewise(index: sp.Symbol, pieces: list[sp.Expr]) -> sp.Expr:
    """pieces[k] where the latched ``index`` is k (the last piece for every larger index)."""
    half = sp.Rational(1, 2)
    return sp.Piecewise(*[(e, index < k + half) for k, e in enumerate(pieces[:-1])], (pieces[-1], True))


def kloss_textbook(Fmax: sp.Expr, slip: sp.Expr, slip_max: sp.Expr) -> sp.Expr:
    """Kloss' motor curve as printed, singular at synchronous speed (slip = 0)."""
    return 2 * Fmax / (slip / slip_max + slip_max / slip)


def _schedule(law: Law, sym: SymbolOf, owner: str, variable: sp.Expr) -> tuple[sp.Expr, Pieces]:
    """A schedule in t or x2: piecewise constant ("steps") or linear between breakpoints."""
    at = [sym(p) for p in law.breakpoints]
    values = [sym(p) for p in law.values]
    if law.options["shape"] == "steps":
        pieces = values                      # values[k] after breakpoint k (values[0] before the first)
    else:
        pieces = [values[0]] + [values[k] + (values[k + 1] - values[k]) * (variable - at[k]) / (at[k + 1] - at[k])
                                for k in range(len(at) - 1)] + [values[-1]]
    name = law.options["variable"]
    events = tuple(LawEvent(f"{owner}_at{k + 1}", variable - a, f"the {owner} schedule passes {name} = {a}")
                   for k, a in enumerate(at))
    index = sp.Symbol(f"{owner}_piece", real=True)
    doc = f"piece of the {owner} schedule in {name} ({law.options['shape']}): breakpoints passed"
    return piecewise(index, pieces), Pieces(index, events, doc)


def drive_force(law: Law, sym: SymbolOf, x2: sp.Expr) -> tuple[sp.Expr, Pieces | None]:
    """F1(t, x2, v1) on body 1 and its pieces when it is a schedule."""
    p = {k: sym(v) for k, v in law.params.items()}
    if law.kind == "kloss":
        slip, slip_max = p["V0"] - v1, p["V0"] - p["Vmax"]
        return sp.together(kloss_textbook(p["Fmax"], slip, slip_max)), None   # 2 Fmax s smax / (s^2 + smax^2)
    if law.kind == "constant":
        return p["F1"], None
    if law.kind == "linear":
        return p["F0"] * (1 - v1 / p["V0"]), None
    if law.kind == "schedule":
        return _schedule(law, sym, "drive", t if law.options["variable"] == "t" else x2)
    raise ValueError(f"drive.law = {law.kind!r}: not a drive law")


def load_force(law: Law, sym: SymbolOf, x2: sp.Expr) -> tuple[sp.Expr, Pieces | None]:
    """F2(t, x2) on body 2 and its pieces when it is piecewise."""
    p = {k: sym(v) for k, v in law.params.items()}
    if law.kind == "constant":
        return p["F2"], None
    index = sp.Symbol("load_piece", real=True)
    if law.kind == "step":
        event = LawEvent("load_step", t - p["t_step"], "the load steps at t = t_step")
        return (piecewise(index, [p["F2_before"], p["F2_after"]]),
                Pieces(index, (event,), "piece of the step load: 1 from t = t_step on"))
    if law.kind == "spring":
        squeeze = x2 - p["x2_contact"]
        event = LawEvent("load_contact", squeeze, "body 2 reaches the spring at x2 = x2_contact")
        return (piecewise(index, [sp.Integer(0), -(p["preload"] + p["k"] * squeeze)]),
                Pieces(index, (event,), "piece of the spring load: 1 while body 2 presses the spring"))
    if law.kind == "schedule":
        return _schedule(law, sym, "load", t if law.options["variable"] == "t" else x2)
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
