"""Drive, load and friction laws of a scene as SymPy expressions.

Each force builder takes the scene's ``Law`` and a function that maps a ``Param`` to its
symbol, and returns the expression together with its ``Pieces`` when the law is
piecewise (a step, a spring contact, a schedule): the law is then written in terms of a
piece index that the runtime latches per segment, so no integration step ever sees the
law jump or kink; the breakpoints are events (segment boundaries) instead, through one
event function per law whose target moves with the piece. A schedule's breakpoints and
values are data (``Schedule``), arrays of the emitted module: however many breakpoints it
has, the law is one expression in the piece in force.
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
    """The event of a piecewise law: ``expr``, how far the state lies inside the latched piece,
    is >= 0 there and falls through 0 where the state leaves it (either way)."""

    name: str
    expr: sp.Expr
    doc: str


@dataclass(frozen=True)
class Schedule:
    """A schedule's breakpoints and values: data, arrays of the emitted module (a free entry is
    read from p), never one expression per piece. The law and its event are written in the
    symbols of the piece in force, which the module reads from the arrays at the latched piece:
    the breakpoints around it and its line, force = level + slope (variable - origin)."""

    owner: str                   # "load" or "drive"
    shape: str                   # "steps" or "linear"
    variable: str                # "t" or "x2"
    breakpoints: tuple[Param, ...]
    values: tuple[Param, ...]
    lower: sp.Symbol             # the breakpoint below the piece (-inf before the first)
    upper: sp.Symbol             # the breakpoint above it (+inf after the last)
    level: sp.Symbol             # the force at origin
    slope: sp.Symbol             # d force / d variable inside the piece (0 for steps, outside the breakpoints)
    origin: sp.Symbol            # where the piece's line has the force level

    @property
    def piece_symbols(self) -> tuple[sp.Symbol, ...]:
        """In the order the module's piece function returns them."""
        return self.lower, self.upper, self.level, self.slope, self.origin


@dataclass(frozen=True)
class Pieces:
    """A piecewise law's latched piece index: the number of its breakpoints the state has passed.

    The runtime sets ``symbol`` (a slot of the parameter vector) at the start and after
    every event of the law, so inside a segment the law is one smooth piece. ``event``
    is the law's one event function, written in the latched piece: it tells whether the
    state lies in a piece, which is how the runtime finds the piece to latch.
    """

    symbol: sp.Symbol
    event: LawEvent
    count: int                   # number of pieces (breakpoints + 1)
    doc: str
    schedule: Schedule | None = None


def piecewise(index: sp.Symbol, pieces: list[sp.Expr]) -> sp.Expr:
    """pieces[k] where the latched ``index`` is k (the last piece for every larger index)."""
    half = sp.Rational(1, 2)
    return sp.Piecewise(*[(e, index < k + half) for k, e in enumerate(pieces[:-1])], (pieces[-1], True))


def kloss_textbook(Fmax: sp.Expr, slip: sp.Expr, slip_max: sp.Expr) -> sp.Expr:
    """Kloss' motor curve as printed, singular at synchronous speed (slip = 0)."""
    return 2 * Fmax / (slip / slip_max + slip_max / slip)


def _two_pieces(index: sp.Symbol, pieces: list[sp.Expr], past: sp.Expr, event: tuple[str, str],
                doc: str) -> tuple[sp.Expr, Pieces]:
    """A law of two pieces, the second where ``past`` >= 0; ``event`` is its (name, doc)."""
    return piecewise(index, pieces), Pieces(index, LawEvent(event[0], piecewise(index, [-past, past]), event[1]),
                                            2, doc)


def _schedule(law: Law, owner: str, variable: sp.Expr) -> tuple[sp.Expr, Pieces]:
    """A schedule in t or x2: piecewise constant ("steps") or linear between breakpoints, as data."""
    name, shape = law.options["variable"], law.options["shape"]
    symbols = [sp.Symbol(f"{owner}_{s}", real=True) for s in ("lower", "upper", "level", "slope", "origin")]
    schedule = Schedule(owner, shape, name, law.breakpoints, law.values, *symbols)
    force = schedule.level if shape == "steps" else schedule.level + schedule.slope * (variable - schedule.origin)
    event = LawEvent(f"{owner}_schedule", sp.Min(variable - schedule.lower, schedule.upper - variable),
                     f"the {owner} schedule passes a breakpoint in {name}")
    index = sp.Symbol(f"{owner}_piece", real=True)
    doc = f"piece of the {owner} schedule in {name} ({shape}): breakpoints passed"
    return force, Pieces(index, event, len(law.breakpoints) + 1, doc, schedule)


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
        return _schedule(law, "drive", t if law.options["variable"] == "t" else x2)
    raise ValueError(f"drive.law = {law.kind!r}: not a drive law")


def load_force(law: Law, sym: SymbolOf, x2: sp.Expr) -> tuple[sp.Expr, Pieces | None]:
    """F2(t, x2) on body 2 and its pieces when it is piecewise."""
    p = {k: sym(v) for k, v in law.params.items()}
    if law.kind == "constant":
        return p["F2"], None
    index = sp.Symbol("load_piece", real=True)
    if law.kind == "step":
        return _two_pieces(index, [p["F2_before"], p["F2_after"]], t - p["t_step"],
                           ("load_step", "the load steps at t = t_step"), "piece of the step load: 1 from t = t_step on")
    if law.kind == "spring":
        squeeze = x2 - p["x2_contact"]
        return _two_pieces(index, [sp.Integer(0), -(p["preload"] + p["k"] * squeeze)], squeeze,
                           ("load_contact", "body 2 reaches the spring at x2 = x2_contact"),
                           "piece of the spring load: 1 while body 2 presses the spring")
    if law.kind == "schedule":
        return _schedule(law, "load", t if law.options["variable"] == "t" else x2)
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
