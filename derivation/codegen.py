"""Emit one numba module per scene from the model IR, through a Jinja2 template.

Fixed parameters become named module constants written as the scene gives them
(``gamma = math.radians(4.76)  # wedge.gamma``), and every subexpression of fixed
parameters only a derived constant defined by its formula (``tan_gamma = math.tan(gamma)``),
evaluated once at import; numba folds module globals, so the code reads like the derivation
at no cost. Free parameters are read from the parameter vector ``p``. Every function is a
top-level ``@njit(cache=True)`` function calling the others as module globals, so numba
caches and inlines them. Mirror-image modes (the other flank or direction: the same
equations with -rho for rho) share one set of functions taking ``rho_sign``; a function
whose body equals an earlier one's is emitted as an alias of it. A schedule's breakpoints
and values are numpy arrays of the module (data, printed inertly), read at the latched piece
by one law and one event function. The module imports math and numba only, and numpy for
a schedule's arrays.
"""
from __future__ import annotations

import dataclasses
import hashlib
import keyword
import math
import re
import textwrap
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import jinja2
import sympy as sp
from sympy.functions.elementary.piecewise import ExprCondPair
from sympy.printing.pycode import PythonCodePrinter

from derivation import laws, mechanics
from derivation.mechanics import S1, S2, t
from derivation.model import Model, compose_laws as _compose, param_symbol
from derivation.scene import NAME, SceneError
from tswm_common import units
from tswm_common.files import EditedModuleError, body_digests, write_atomic

GENERATOR_VERSION = "0.1.0"
STICK_GUARDS = ("cone_forward", "cone_backward", "flank_normal")
SLIDING_GUARDS = ("phi", "v1", "D", "jam")
SLIDE_GUARDS = ("slide_exit_a", "slide_exit_b")
GAP_GUARDS = ("gap_a", "gap_b")   # free flight: the gap to flank a, to flank b
OBSERVABLES = (S1, S2)


class GenerationError(SceneError):
    """A scene whose module cannot be generated as inert, finite code; the message names the key."""


_NON_FINITE = (sp.oo, -sp.oo, sp.zoo, sp.nan)


def _non_finite(expr: sp.Expr) -> bool:
    """Whether a folded expression holds a number a double cannot carry: inf, nan, or a nonzero
    number that underflows to 0."""
    return expr.has(*_NON_FINITE) or any(not math.isfinite(float(a)) or (not a.is_zero and float(a) == 0)
                                         for a in expr.atoms(sp.Float))


def inert(value, name: str) -> str:
    """Python source for a constant from a scene: repr() of str, bool, int, finite float and
    tuples/dicts of them; anything else (inf, nan, objects) is refused, naming the constant."""
    def check(v) -> None:
        if isinstance(v, (tuple, list)):
            for item in v:
                check(item)
        elif isinstance(v, dict):
            for key, item in v.items():
                check(key)
                check(item)
        elif isinstance(v, float):
            if not math.isfinite(v):
                raise GenerationError(f"module constant {name} would hold {v!r}: every number in generated code "
                                      "must be finite")
        elif v is not None and not isinstance(v, (str, bool, int)):
            raise GenerationError(f"module constant {name}: cannot emit a {type(v).__name__}")
    check(value)
    return repr(value)


def source_form(value: float, written: tuple[float, str] | None, name: str) -> str:
    """A fixed value as the scene file gives it, printed inertly and still a constant numba folds:
    ``math.radians(4.76)`` for "4.76 deg", ``-20.0 * 1000.0`` for "-20 kN" (the same double as
    the SI value); the SI value itself when it was given in SI."""
    if written is None:
        return inert(value, name)
    number, unit = written
    if unit == "deg" and math.radians(number) == value:
        return f"math.radians({inert(number, name)})"
    if number * units.factor(unit) == value:
        return f"{inert(number, name)} * {inert(units.factor(unit), name)}"
    return inert(value, name)


def _comment(text: str) -> str:
    """Text for a comment after code: a scene key such as ``load.at[0]``, nothing else."""
    if not re.fullmatch(r"[A-Za-z0-9_.\[\]]{1,80}", text):
        raise GenerationError(f"refusing to emit a comment that is not a scene key: {text[:80]!r}")
    return text


def _aliased(functions: list[Function]) -> list[Function]:
    """The functions with each one whose body, arguments and signature equal an earlier
    one's turned into an alias of it (mirror-image modes often have one Jacobian)."""
    first: dict[tuple, str] = {}
    out = []
    for f in functions:
        key = (f.args, f.lines, f.result, f.signature)
        if key in first and f.lines:
            out.append(Function(f.name, f.args, f.doc, (), "", alias=first[key]))
        else:
            first.setdefault(key, f.name)
            out.append(f)
    return out


def _docstring(text: str) -> str:
    """Text for a docstring: only generator-made text, which never holds quotes that end it or escapes."""
    if '"""' in text or "\\" in text or not text.isprintable():
        raise GenerationError(f"refusing to emit a docstring that is not plain text: {text[:80]!r}")
    return text


@dataclass(frozen=True)
class Function:
    """One emitted function: its name, arguments, docstring, body lines and return value."""

    name: str
    args: str
    doc: str
    lines: tuple[str, ...]
    result: str
    signature: str = ""          # explicit numba signature name, for the contract functions
    alias: str = ""              # the earlier function with the same body: emitted as name = alias
    jit: bool = True             # False: plain Python on numpy arrays


def module_name(scene_name: str) -> str:
    return scene_name.replace("-", "_")


# What code generation reads (not the document writer, the audit or PDF building): a module
# names the sha256 of these, so only a change that can change the code makes it stale.
GENERATOR_SOURCES = ("scene.py", "mechanics.py", "laws.py", "paper.py", "model.py", "codegen.py",
                     "templates/module.py.j2")


def generator_digest() -> str:
    """sha256 over the generator's own sources, so a module names the code that wrote it."""
    h = hashlib.sha256()
    root = resources.files("derivation")
    for name in GENERATOR_SOURCES:
        h.update(name.encode() + root.joinpath(*name.split("/")).read_bytes())
    h.update(b"units.py" + (resources.files("tswm_common") / "units.py").read_bytes())   # scene units
    return h.hexdigest()


RHO_SIGN = sp.Symbol("rho_sign", real=True)   # +1 or -1: the friction angle's sign in mirror-image modes


@dataclass(frozen=True)
class Call:
    """Which functions a mode calls: those emitted for ``group``, with ``rho_sign`` = ``sign``
    (0: the group's functions take no sign). ``leader`` is the mode they are derived from."""

    group: str
    leader: str
    sign: int = 0

    def __call__(self, prefix: str, args: str) -> str:
        """Source of the call of the group's function ``prefix`` with ``args``."""
        sign = f", {inert(float(self.sign), str(RHO_SIGN))}" if self.sign else ""
        return f"{prefix}_{self.group}({args}{sign})"


def _equations(model: Model, mode) -> tuple:
    """Every expression the module emits as code for a mode: rates, reactions, consistency, contact."""
    further = tuple(getattr(mode, name) for name, _ in _further_accelerations(model))
    return (mode.accel, mode.S1, mode.S2, mode.denominator, mode.jam, *mode.mesh, *further,
            *state_rates(model, mode))


def mirror_calls(model: Model) -> dict[str, Call]:
    """Each mode -> the functions it calls. A mode on a flank whose equations are an earlier
    one's with rho replaced by -rho (the mirror flank, the other direction) shares that mode's
    functions, emitted once with rho replaced by rho_sign rho; equal equations share them too."""
    rho = _friction_symbol(model)
    leaders: dict[str, tuple[tuple, tuple]] = {}       # leader -> (its equations, with -rho)
    members: dict[str, list[tuple[str, int]]] = {}     # leader -> [(mode, rho_sign)]
    for mode in model.modes:
        if not mode.flank or rho is None or mode.slide is not None:
            members[mode.name] = [(mode.name, 1)]
            continue
        equations = _equations(model, mode)
        for leader, (same, mirrored) in leaders.items():
            if equations in (same, mirrored):
                members[leader].append((mode.name, 1 if equations == same else -1))
                break
        else:
            leaders[mode.name] = (equations, tuple(e if e is None else e.subs(rho, -rho) for e in equations))
            members[mode.name] = [(mode.name, 1)]
    calls: dict[str, Call] = {}
    for leader, group in members.items():
        signed = any(sign < 0 for _, sign in group)
        name = _group_name(leader, [m for m, _ in group], {c.group for c in calls.values()} | set(members))
        calls.update({m: Call(name, leader, sign if signed else 0) for m, sign in group})
    return calls


def _friction_symbol(model: Model) -> sp.Symbol | None:
    """The friction angle's symbol when both flanks share it (else the flanks are no mirror images)."""
    friction = [q.symbol for q in model.laws if law_function_name(q.symbol).startswith("friction_angle")]
    return friction[0] if len(friction) == 1 else None


def _group_name(leader: str, modes: list[str], taken: set[str]) -> str:
    """fwd_a with fwd_b -> fwd; with bwd_a, bwd_b too -> sliding (mesh_fwd_a ... -> mesh_sliding)."""
    if len(modes) == 1:
        return leader
    bases = {re.sub(r"_[ab]$", "", m) for m in modes}
    name = bases.pop() if len(bases) == 1 else re.sub(r"(fwd|bwd)_[ab]$", "sliding", leader)
    return name if name not in taken - {leader} else leader


def _signed(mode, call: Call, rho: sp.Symbol | None):
    """The leader's equations under its group's name, with rho_sign rho for rho when the group is signed."""
    if not call.sign:
        return dataclasses.replace(mode, name=call.group)
    flip = {rho: RHO_SIGN * rho}
    changed = {f.name: _subs(getattr(mode, f.name), flip) for f in dataclasses.fields(mode)
               if f.name not in ("name", "regime", "flank", "direction", "declared", "slide")}
    return dataclasses.replace(mode, name=call.group, **changed)


def _subs(value, sub: dict):
    if isinstance(value, tuple):
        return tuple(_subs(v, sub) for v in value)
    return value.subs(sub) if isinstance(value, sp.Basic) else value


def _where(model: Model, group: str, calls: dict[str, Call]) -> str:
    """Docstring text naming the modes that call a group's functions, and their rho_sign."""
    modes = [m for m in model.modes if calls[m.name].group == group]
    if len(modes) == 1:
        return f"mode {modes[0].name} ({modes[0].regime})"
    if not calls[modes[0].name].sign:
        return "modes " + ", ".join(m.name for m in modes)
    by_sign = [(s, [m.name for m in modes if calls[m.name].sign == s]) for s in (1, -1)]
    return "modes " + "; ".join(f"{', '.join(names)} (rho_sign = {s})" for s, names in by_sign if names)


class _Printer(PythonCodePrinter):
    """Python source for numba: math-module functions, exact doubles for numbers."""

    def __init__(self):
        super().__init__({"standard": "python3", "fully_qualified_modules": True})

    def _print_Float(self, expr):
        value = float(expr)
        if not math.isfinite(value) or (value == 0 and not expr.is_zero):  # backstop: fold() names the key
            raise GenerationError(f"a non-finite number ({value!r}) would be emitted as code")
        return repr(value)


class _Emitter:
    """Turns IR expressions into function bodies for one scene."""

    def __init__(self, model: Model, free: tuple[str, ...]):
        self.model = model
        self.vector = free + latch_names(model)   # the names in p
        self.printer = _Printer()
        arrays = scheduled(model)   # schedule entries: arrays of the module, never in an expression
        fixed = [p for p in model.params if p.name not in free and p.name not in arrays]
        self.fixed = {param_symbol(p): sp.Float(repr(p.value)) for p in fixed}
        self.fixed_params = {param_symbol(p): p for p in fixed}
        self.derived: dict[sp.Expr, sp.Symbol] = {}   # subexpression of fixed parameters -> its constant
        self.finite: set[sp.Expr] = set()             # expressions fold() found finite with the fixed values
        self.law_functions = {q.symbol: law_function_name(q.symbol) for q in model.laws}
        self.inlined_laws = compose_laws(model)
        self.calls = mirror_calls(model)
        leaders = [self.calls[m.name] for m in model.modes if self.calls[m.name].leader == m.name]
        self.emitted_modes = [_signed(model.mode(c.leader), c, _friction_symbol(model)) for c in leaders]
        self.where = {c.group: _where(model, c.group, self.calls) for c in leaders}
        self.args = {c.group: "t, y, p" + (f", {RHO_SIGN}" if c.sign else "") for c in leaders}

    def print(self, expr) -> str:
        return self.printer.doprint(expr)

    def body(self, outputs: list[sp.Expr], law: sp.Symbol | None = None,
             states_from_y: bool = True) -> tuple[list[str], list[str]]:
        """Unpack states (unless the function takes them as arguments), free parameters and
        laws the outputs use; one CSE over the outputs.

        A law symbol may share its name with a parameter (a constant load ``F2``): outside
        the law's own function the value then comes from the law, inside it from ``p``.
        """
        exprs = [self.named(self.fold(sp.sympify(e))) for e in outputs]
        used = set().union(*(e.free_symbols for e in exprs))
        calls = [q.symbol for q in self.model.laws if q.symbol in used and q.symbol != law]
        lines = [f"{s} = y[{i}]" for i, s in enumerate(self.model.states) if s in used and states_from_y]
        lines += [f"{name} = p[{i}]" for i, name in enumerate(self.vector)
                  if sp.Symbol(name, real=True) in used and sp.Symbol(name, real=True) not in calls]
        for schedule in schedules(self.model):
            if used & set(schedule.piece_symbols):
                names = ", ".join(str(s) if s in used else "_" for s in schedule.piece_symbols)
                lines.append(f"{names} = {schedule.owner}_schedule_piece(p)")
        lines += [f"{s} = {self.law_functions[s]}(t, y, p)" for s in calls]
        replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("c"))
        if any(_non_finite(e) for e in [*(e for _, e in replacements), *reduced]):   # CSE folds numbers too
            raise self.refusal([sp.sympify(e) for e in outputs])
        lines += [f"{s} = {self.print(e)}" for s, e in replacements]
        return lines, [self.print(sp.Float(e) if e.is_Number else e) for e in reduced]

    def fold(self, expr: sp.Expr) -> sp.Expr:
        """``expr``, checked: with the fixed parameters folded in it must stay finite (else
        refused, naming the keys). Returned as it is: the constants stay named."""
        if expr not in self.finite:
            if _non_finite(expr.xreplace(self.fixed)):
                raise self.refusal([expr])
            self.finite.add(expr)
        return expr

    def _fixed_only(self, expr) -> bool:
        return (isinstance(expr, sp.Expr) and not isinstance(expr, ExprCondPair) and bool(expr.free_symbols)
                and expr.free_symbols <= self.fixed.keys())

    def named(self, expr: sp.Expr) -> sp.Expr:
        """``expr`` with every maximal subexpression of fixed parameters only (beyond a lone
        parameter) replaced by a derived module constant."""
        if expr.is_Atom:
            return expr
        if self._fixed_only(expr):
            return self.constant(expr)
        if isinstance(expr, sp.Piecewise):
            return sp.Piecewise(*[(self.named(e), self.named(c)) for e, c in expr.args])
        if isinstance(expr, (sp.Add, sp.Mul)):
            fixed = [a for a in expr.args if self._fixed_only(a)]
            rest = [self.named(a) for a in expr.args if not self._fixed_only(a)]
            if len(fixed) > 1 or (fixed and not fixed[0].is_Symbol):
                fixed = [self.constant(expr.func(*fixed))]
            return expr.func(*fixed, *rest)
        return expr.func(*(self.named(a) for a in expr.args))

    def constant(self, expr: sp.Expr) -> sp.Expr:
        """The derived constant for a subexpression of fixed parameters (a lone one is itself)."""
        if expr.is_Symbol:
            return expr
        if expr not in self.derived:
            self.derived[expr] = sp.Symbol(self._constant_name(expr), real=True)
        return self.derived[expr]

    def _constant_name(self, expr: sp.Expr) -> str:
        """A readable identifier for a derived constant: tan_gamma, m1_tan_gamma, ..."""
        if isinstance(expr, sp.Pow) and expr.exp == -1:
            text = "inv_" + sp.sstr(expr.base)
        elif expr.could_extract_minus_sign():
            text = "minus_" + sp.sstr(-expr).replace("**", "_pow_")
        else:
            text = sp.sstr(expr).replace("**", "_pow_")
        text = re.sub(r"[^0-9a-zA-Z]+", "_", text).strip("_")
        name = ("k_" + text if text[:1].isdigit() else text) if len(text) <= 32 else f"k{len(self.derived) + 1}"
        taken = {str(s) for s in self.derived.values()} | {str(s) for s in self.fixed} | set(self.vector)
        while name in taken or keyword.iskeyword(name):
            name += "_"
        return name

    def derived_constants(self) -> list[tuple[str, str]]:
        """(name, formula) of the derived constants, in the order they were made."""
        return [(str(symbol), self.print(expr)) for expr, symbol in self.derived.items()]

    def refusal(self, exprs: list[sp.Expr]) -> GenerationError:
        """The error for outputs whose folded numbers a double cannot hold, naming the scene keys to blame:
        those without which the fold is finite, else those of extreme magnitude, else all involved."""
        involved = sorted({s for e in exprs for s in e.free_symbols if s in self.fixed}, key=str)

        def finite_without(s):
            rest = {k: v for k, v in self.fixed.items() if k != s}
            return not any(_non_finite(e.subs(rest)) for e in exprs)

        extreme = [s for s in involved if self.fixed_params[s].value and
                   not 1e-150 < abs(self.fixed_params[s].value) < 1e150]
        culprits = [s for s in involved if finite_without(s)] or extreme or involved
        keys = ", ".join(f"{self.fixed_params[s].key} = {self.fixed_params[s].value!r} {self.fixed_params[s].unit}"
                         .rstrip() for s in culprits)
        where = "; ".join(_short(e) for e in exprs)
        return GenerationError(f"{self.model.scene.source}: {keys or 'the fixed parameters'}: folding the fixed "
                               f"value{'s' if len(culprits) > 1 else ''} into the code gives a number a double "
                               f"cannot hold (inf, nan, or an underflow to 0) in {where[:300]}; choose a value "
                               "that keeps it finite, or make the parameter free")

    def function(self, name: str, doc: str, outputs: list[sp.Expr], law: sp.Symbol | None = None,
                 args: str = "t, y, p") -> Function:
        lines, results = self.body(outputs, law)
        return Function(name, args, doc, tuple(lines), ", ".join(results))


def law_function_name(symbol: sp.Symbol) -> str:
    base = {"F1": "drive_force", "F2": "load_force", "x2": "body2_position", "F2_carried": "carried_load",
            "m2_carried": "carried_mass"}
    name = str(symbol)
    return base.get(name, name.replace("rho", "friction_angle"))


def compose_laws(model: Model) -> dict:
    """Each law symbol -> its expression in states, t and parameters only."""
    return _compose(model.laws)


def _short(expr: sp.Expr) -> str:
    return sp.sstr(expr)


def _mode_functions(em: _Emitter) -> list[Function]:
    out = []
    for mode in em.emitted_modes:
        where, args = em.where[mode.name], em.args[mode.name]

        def function(name, doc, outputs):
            return em.function(name, doc, outputs, args=args)
        out.append(function(f"outputs_{mode.name}", f"(a1, S1, S2, F1, F2) in {where}: an output row, "
                            "each law evaluated once", [mode.accel, mode.S1, mode.S2, mechanics.F1, mechanics.F2]))
        out.append(function(f"accel_{mode.name}", f"a1 in {where}: {_short(mode.accel)}", [mode.accel]))
        for name, doc in _further_accelerations(em.model):
            rate = getattr(mode, name)
            out.append(function(f"{name}_{mode.name}", f"{doc} in {where}: {_short(rate)}", [rate]))
        if mode.slide is not None:
            out.append(function(f"reactions_{mode.name}", f"(S1, S2) in {where}: Filippov's combination "
                                "lambda (S1, S2)_fwd_a + (1 - lambda) (S1, S2)_fwd_b, lambda = rate_b / (rate_b - "
                                "rate_a)", [mode.S1, mode.S2]))
            out.append(function("slide_exits", "(slide_exit_a, slide_exit_b) = (-rate_a, rate_b): sliding along "
                                "phi = 0 persists while both are > 0. rate_a (rate_b) = d phi/dt along fwd_a "
                                f"(fwd_b) = {_short(mode.slide.rate)} with that mode's a1",
                                [-mode.slide.rate_a, mode.slide.rate_b]))
            continue
        out.append(function(f"reactions_{mode.name}", f"(S1, S2) in {where}: "
                            f"S1 = {_short(mode.S1)}, S2 = {_short(mode.S2)}", [mode.S1, mode.S2]))
        if mode.mesh:
            what = "(N, slip)" if mode.direction else "(N, cone_forward, cone_backward)"
            out.append(function(f"contact_{mode.name}", f"{what} of the compliant contact in {where}: "
                                f"N = {_short(mode.normal)}; the mode holds while each is >= 0 (the slip "
                                "keeps its sign)", list(mode.mesh)))
        if mode.denominator is not None:
            outs = [mode.denominator] + ([mode.jam] if mode.jam is not None else [])
            out.append(function(f"consistency_{mode.name}", f"(D{', jam' if mode.jam is not None else ''}) "
                                f"in {where}: the mode exists while each is > 0. D = "
                                f"{_short(mode.denominator)}", outs))
    return out


# A position state's rate is its velocity state; a velocity state's rate is the mode's acceleration
# of that name (a Mode field, and the module's dispatch function of the same name), with its doc.
VELOCITY = {mechanics.x1: mechanics.v1, mechanics.gap: mechanics.gap_rate, mechanics.x3: mechanics.v3}
ACCELERATION = {mechanics.v1: ("accel", "a1"), mechanics.gap_rate: ("gap_accel", "d gap_rate/dt"),
                mechanics.v3: ("stem_accel", "d v3/dt, the stem's acceleration (0 held, F2/m3 on its own, a2 carried)")}


def _further_accelerations(model: Model) -> list[tuple[str, str]]:
    """(name, doc) of the accelerations besides a1 that the model's states need."""
    return [ACCELERATION[s] for s in model.states if s in ACCELERATION and s != mechanics.v1]


def state_rates(model: Model, mode) -> list[sp.Expr]:
    """d(states)/dt in ``mode``: a position state's velocity state, a velocity state's acceleration."""
    return [VELOCITY[s] if s in VELOCITY else getattr(mode, ACCELERATION[s][0]) for s in model.states]


def _rate_sources(model: Model) -> list[str]:
    """What rhs writes into dy[i], in the template: the velocity state, or the acceleration's dispatch."""
    index = {s: i for i, s in enumerate(model.states)}
    return [f"y[{index[VELOCITY[s]]}]" if s in VELOCITY else f"{ACCELERATION[s][0]}(mode, t, y, p)"
            for s in model.states]


def _jacobian(em: _Emitter, mode) -> Function:
    states = em.model.states
    f = [r.subs(em.inlined_laws) for r in state_rates(em.model, mode)]
    entries = [sp.diff(fi, s) for fi in f for s in states] + [sp.diff(fi, t) for fi in f]
    lines, results = em.body(entries)
    n = len(states)
    targets = [f"J[{i}, {j}]" for i in range(n) for j in range(n)] + [f"dfdt[{i}]" for i in range(n)]
    lines += [f"{target} = {value}" for target, value in zip(targets, results)]
    args = em.args[mode.name].replace("t, y, p", "t, y, p, J, dfdt")
    return Function(f"jac_{mode.name}", args, f"Jacobian of the right-hand side in {em.where[mode.name]}.",
                    tuple(lines), "")


def latch_names(model: Model) -> tuple[str, ...]:
    """The slots of p after the free parameters: latched times, then latched law pieces."""
    return tuple(str(latch.symbol) for latch in model.latches) + tuple(str(p.symbol) for p in model.pieces)


def guard_latches(model: Model, free: tuple[str, ...]) -> tuple[int, ...]:
    """Per guard, the index in p of the latch it sets (a trip time or a law's piece), else -1."""
    slot = {name: len(free) + i for i, name in enumerate(latch_names(model))}
    owner = {latch.name: slot[str(latch.symbol)] for latch in model.latches}
    owner.update({p.event.name: slot[str(p.symbol)] for p in model.pieces})
    return tuple(owner.get(name, -1) for name in guard_names(model))


def guard_pieces(model: Model) -> tuple[int, ...]:
    """Per guard, the number of pieces of the law whose piece it latches, else 0."""
    count = {p.event.name: p.count for p in model.pieces}
    return tuple(count.get(name, 0) for name in guard_names(model))


def schedules(model: Model) -> list[laws.Schedule]:
    """The model's schedules (their breakpoints and values are arrays of the module)."""
    return [p.schedule for p in model.pieces if p.schedule is not None]


def scheduled(model: Model) -> set[str]:
    """Names of the parameters that are entries of a schedule's arrays, not module constants."""
    return {p.name for s in schedules(model) for p in (*s.breakpoints, *s.values)}


def _array(values: list, name: str, dtype: str) -> str:
    """Source of a numpy array of scene values, each printed inertly: on one line where
    ``NAME = ...`` fits in 100 characters, else wrapped at 100 characters."""
    text = ", ".join(inert(v, name) for v in values)
    if len(name) + len(text) + len(f" = np.array([], dtype=np.{dtype})") <= 100:
        return f"np.array([{text}], dtype=np.{dtype})"
    lines = textwrap.wrap(text, 96, break_long_words=False, break_on_hyphens=False)
    return "np.array([" + "".join(f"\n    {line}" for line in lines) + f"\n], dtype=np.{dtype})"


def _schedule_data(model: Model, free: tuple[str, ...]) -> list[dict]:
    """Per schedule, what the template emits: its arrays (a free entry's default in the table, its
    index in p in the slots, -1 where fixed) and the function reading the piece in force."""
    out = []
    index = {name: i for i, name in enumerate(free + latch_names(model))}
    for piece in (p for p in model.pieces if p.schedule is not None):
        s, prefix = piece.schedule, piece.schedule.owner.upper()
        arrays = {}
        for key, entries in (("AT", s.breakpoints), ("VALUES", s.values)):
            arrays[f"{prefix}_{key}"] = _array([e.value for e in entries], f"{prefix}_{key}", "float64")
            arrays[f"{prefix}_{key}_SLOTS"] = _array([index.get(e.name, -1) for e in entries],
                                                     f"{prefix}_{key}_SLOTS", "int64")
        out.append({"owner": s.owner, "shape": s.shape, "variable": s.variable, "arrays": arrays, "prefix": prefix,
                    "slot": index[str(piece.symbol)], "piece": str(piece.symbol), "linear": s.shape == "linear"})
    return out


def _parameter_checks(model: Model, free: tuple[str, ...]) -> tuple[tuple, ...]:
    """The scene's rules that involve a free parameter: the runtime applies them to free values."""
    names = set(free)
    return tuple(c for c in model.scene.checks if names & {c[1], *(c[3:4] if c[0] in ("less", "jam") else ())})


MESH_GUARDS = ("mesh_normal", "slip")   # compliant contact: its normal force, the slip


def guard_names(model: Model) -> tuple[str, ...]:
    if any(m.mesh for m in model.modes):
        cones = STICK_GUARDS[:2] if any(m.mesh and not m.direction for m in model.modes) else ()
        return (MESH_GUARDS + cones + tuple(e.name for e in model.events) + tuple(latch.name for latch in model.latches)
                + GAP_GUARDS)
    sliding = SLIDING_GUARDS if any(m.jam is not None for m in model.modes) else SLIDING_GUARDS[:3]
    slide = SLIDE_GUARDS if any(m.slide is not None for m in model.modes) else ()
    return (sliding + (STICK_GUARDS if model.stick else ()) + tuple(e.name for e in model.events) + slide
            + tuple(latch.name for latch in model.latches) + (GAP_GUARDS if model.clearance is not None else ()))


def _guard_directions(model: Model) -> tuple[tuple[int, ...], ...]:
    """Per mode and guard: -1 falling, +1 rising, 0 both (constant-one guards never fire)."""
    names = guard_names(model)
    latches = {latch.name for latch in model.latches}
    law_events = {e.name for e in model.events}
    table = []
    for mode in model.modes:
        row = []
        for name in names:
            if name == "phi":
                row.append(-1 if mode.flank == "a" else 1)
            elif name in ("v1", "slip"):
                row.append(-mode.direction)
            elif name in ("D", "jam", "cone_forward", "cone_backward", "mesh_normal", *SLIDE_GUARDS, *GAP_GUARDS) \
                    or name in latches or name in law_events:
                row.append(-1)
            else:
                row.append(0)
        table.append(tuple(row))
    return tuple(table)


def _guards(em: _Emitter) -> Function:
    model = em.model
    names = guard_names(model)
    lines = ["for i in range(g.shape[0]):", "    g[i] = 1.0"]
    for index, mode in enumerate(model.modes):
        lines.append(f"{'if' if index == 0 else 'elif'} mode == {index}:  # {mode.name}")
        if mode.name == "free":
            gap = mechanics.gap
            gap_lines, gaps = em.body([gap, model.clearance - gap])
            lines += [f"    {line}" for line in gap_lines]
            lines.append(f"    g[{names.index('gap_a')}], g[{names.index('gap_b')}] = {gaps[0]}, {gaps[1]}")
        elif mode.mesh:
            targets = ("mesh_normal", "slip") if mode.direction else ("mesh_normal", *STICK_GUARDS[:2])
            contact = em.calls[mode.name]("contact", "t, y, p")
            lines.append(f"    {', '.join(f'g[{names.index(n)}]' for n in targets)} = {contact}")
        elif mode.slide is not None:
            lines.append(f"    g[{names.index('v1')}] = y[{len(model.states) - 1}]")
            lines.append(f"    g[{names.index(SLIDE_GUARDS[0])}], g[{names.index(SLIDE_GUARDS[1])}] = "
                         "slide_exits(t, y, p)")
        elif mode.direction:
            lines.append(f"    g[{names.index('phi')}] = switching(t, y, p)")
            lines.append(f"    g[{names.index('v1')}] = y[{len(model.states) - 1}]")
            if mode.jam is not None:
                lines.append(f"    g[{names.index('D')}], g[{names.index('jam')}] = "
                             f"{em.calls[mode.name]('consistency', 't, y, p')}")
            else:
                lines.append(f"    g[{names.index('D')}] = {em.calls[mode.name]('consistency', 't, y, p')}")
        else:
            targets = ", ".join(f"g[{names.index(n)}]" for n in STICK_GUARDS)
            lines.append(f"    {targets} = stick_conditions(t, y, p)")
    if model.events:
        ev_lines, ev_results = em.body([e.expr for e in model.events])
        lines += ev_lines + [f"g[{names.index(e.name)}] = {r}" for e, r in zip(model.events, ev_results)]
    for latch in model.latches:
        armed_lines, (armed,) = em.body([latch.armed])
        guard_lines, (guard,) = em.body([latch.guard])
        lines += armed_lines + [f"if {armed}:  # {latch.name}: {latch.doc}"]
        if {S1, S2} & latch.guard.free_symbols:
            lines.append("    S1, S2 = reactions(mode, t, y, p)")
        lines += [f"    {line}" for line in guard_lines] + [f"    g[{names.index(latch.name)}] = {guard}"]
    return Function("guards", "mode, t, y, p, g", "Event functions of `mode`, in the order of GUARDS.",
                    tuple(lines), "", "GUARDS_SIG")


IMPACT_FRAME = ("nu", "s", "W_nn", "W_nt", "W_tt", "mu", "e", "dv1_dgap_rate", "dv1_ds")
PICKUP_FRAME = ("nu", "s", "dnu_dP_fwd", "dv1_dP_fwd", "dnu_dP_bwd", "dv1_dP_bwd", "dnu_dP_stick", "stick_cone", "e",
                "J", "m3", "v2_per_v1")


def _impact(em: _Emitter) -> Function:
    """impact(flank, t, y, p, out): the frame of a collision on flank +1 (a) or -1 (b), in IMPACT_FRAME
    order, or of the stem's pickup (flank 0), in PICKUP_FRAME order."""
    model = em.model
    if model.pickup:
        body, values = em.body(list(model.pickup))
        doc = ("The frame of the stem's pickup (`flank` 0): out = (nu, s, dnu/dP and dv1/dP sliding forward, the same "
               "backward, dnu/dP in stick, stick cone, e, J, m3, v2/v1): nu = v3 - v2 (< 0: body 2 closes on the "
               "stem), s = v1, P the impulse on the stem; the wedge sticks under the impulse where the cone is >= 0; "
               "J v1^2/2 the kinetic energy of bodies 1 and 2.")
        lines = list(body) + [f"out[{k}] = {v}  # {name}" for k, (name, v) in enumerate(zip(PICKUP_FRAME, values))]
        return Function("impact", "flank, t, y, p, out", doc, tuple(lines), "", "GUARDS_SIG")
    if not model.impacts:
        return Function("impact", "flank, t, y, p, out", "No clearance or lost motion: nothing collides.",
                        ("out[:] = math.nan",), "", "GUARDS_SIG")
    doc = ("The frame of a collision on `flank` (+1 a, -1 b): out = (nu, s, W_nn, W_nt, W_tt, mu, e, dv1/d gap_rate, "
           "dv1/ds): nu = f gap_rate and s the slip, W the inverse mass in that frame, mu = tan(rho) of the flank, "
           "e the restitution, and v1 = dv1/d gap_rate gap_rate + dv1/ds s.")
    lines = []
    for index, imp in enumerate(model.impacts):
        body, values = em.body(list(imp.frame))
        lines.append(f"{'if' if index == 0 else 'else:'} {'flank == 1:' if index == 0 else ''}".rstrip()
                     + f"  # flank {imp.flank}")
        lines += [f"    {line}" for line in body]
        lines += [f"    out[{k}] = {v}  # {name}" for k, (name, v) in enumerate(zip(IMPACT_FRAME, values))]
    return Function("impact", "flank, t, y, p, out", doc, tuple(lines), "", "GUARDS_SIG")


def _body2(em: _Emitter) -> Function:
    """body2(x1, v1, gap, gap_rate, p) -> (x2, v2): plain Python, so it works on whole arrays."""
    lines, results = em.body(list(em.model.body2), states_from_y=False)
    return Function("body2", "x1, v1, gap, gap_rate, p", "(x2, v2), position and speed of body 2 "
                    f"(x2 = {_short(em.model.body2[0])}, v2 = {_short(em.model.body2[1])}); works on arrays.",
                    tuple(lines), ", ".join(results), jit=False)


def _functions(em: _Emitter) -> list[Function]:
    model = em.model
    fns = [em.function(law_function_name(q.symbol), f"{q.doc}: {q.symbol} = {_short(q.expr)}", [q.expr], q.symbol)
           for q in model.laws]
    fns.append(em.function("switching", f"phi = {_short(model.switching)}: zero where the contact force is",
                           [model.switching]))
    fns += _mode_functions(em)
    if model.stick is not None:
        st = model.stick
        fns.append(em.function("stick_conditions", "(cone_forward, cone_backward, flank_normal) at v1 = 0: "
                               "stick holds while both cones are >= 0; flank_normal > 0 holds on flank a",
                               [st.cone_forward, st.cone_backward, st.flank_normal]))
    fns += [_jacobian(em, mode) for mode in em.emitted_modes]
    fns.append(_body2(em))
    return fns


def _load_factors(em: _Emitter) -> Function | None:
    ref = em.model.scene.reference
    if not ref:
        return None
    S1m, S2m = sp.symbols("S1m S2m", real=True)
    lines, results = em.body([sp.Abs(S1m) / param_symbol(ref["Ft1"]), sp.Abs(S2m) / param_symbol(ref["Ft2"])])
    return Function("load_factors", "S1m, S2m, p", "(KD1, KD2) = (|S1m| / Ft1, |S2m| / Ft2), eq. (10).",
                    tuple(lines), ", ".join(results))


def generate_module(model: Model, free: tuple[str, ...] | None = None) -> str:
    """Source of the scene's module. ``free`` overrides which parameters are free (benchmarks)."""
    scene = model.scene
    if not NAME.fullmatch(scene.name):   # it names the file and the header comment: a loaded scene always matches
        raise GenerationError(f"{scene.source}: name = {scene.name[:80]!r}: must match {NAME.pattern}")
    free = tuple(p.name for p in scene.params() if p.free) if free is None else free
    em = _Emitter(model, free)
    functions = _aliased(_functions(em))
    guards_function, load_factors, impact = _guards(em), _load_factors(em), _impact(em)
    by_name = {p.name: p for p in scene.params()}
    free_params = [by_name[n] for n in free]
    fixed = [p for p in scene.params() if p.name not in free]
    constant = [p for p in fixed if p.name not in scheduled(model)]   # schedule entries are arrays instead
    constants = {
        "SCENE": scene.name, "DESCRIPTION": scene.description, "SCENE_DIGEST": scene.digest, "EQUATIONS": scene.equations,
        "STATES": tuple(str(s) for s in model.states), "MODES": tuple(m.name for m in model.modes),
        "MODE_REGIME": tuple(m.regime for m in model.modes),
        "MODE_FLANK": tuple({"a": 1, "b": -1}.get(m.flank, 0) for m in model.modes),
        "MODE_DIRECTION": tuple(m.direction for m in model.modes),
        "MODE_DECLARED": tuple(m.declared for m in model.modes),
        "PARAM_NAMES": tuple(p.name for p in free_params), "PARAM_UNITS": tuple(p.unit for p in free_params),
        "PARAM_DEFAULTS": tuple(p.value for p in free_params), "FIXED": {p.name: p.value for p in fixed},
        "LATCH_NAMES": latch_names(model), "GUARD_LATCH": guard_latches(model, free),
        "GUARD_PIECES": guard_pieces(model),
        "MODE_D": tuple(_short(m.denominator) if m.denominator is not None else "" for m in model.modes),
        "PARAM_CHECKS": _parameter_checks(model, free),
        "OBSERVABLES": tuple(map(str, OBSERVABLES)), "OUTPUTS": ("a1", "S1", "S2", "F1", "F2"),
        "GUARDS": guard_names(model), "HAS_LOAD_FACTORS": load_factors is not None,
        "RUN": dict(vars(scene.run)),
    }
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(resources.files("derivation") / "templates")),
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["docstring"] = _docstring
    env.filters["inert"] = inert
    env.filters["comment"] = _comment
    body = env.get_template("module.py.j2").render(
        scene=scene, model=model, functions=functions, calls=em.calls,
        sources={p.name: source_form(p.value, scene.written.get(p.key), p.name) for p in constant},
        free=free_params, latches=model.latches, fixed=constant, schedules=_schedule_data(model, free),
        pieces=model.pieces, derived=em.derived_constants(), guards_function=guards_function, impact=impact,
        rates=_rate_sources(model), accelerations=_further_accelerations(model),
        load_factors=load_factors,
        guards=guard_names(model),
        constants={k: inert(v, k) for k, v in constants.items()}, directions=_guard_directions(model))
    again = scene.name if scene.source.startswith("shipped:") else "SCENE_FILE"
    body = re.sub(r"\n+@njit", "\n\n\n@njit", body)   # two blank lines before each function, as PEP 8 has it
    body = re.sub(r"(\n    [^\n]*)\n(\w+ = \w+  # the same function)", r"\1\n\n\n\2", body)   # and before aliases
    header = (f"# Generated by tswm {GENERATOR_VERSION} from scene '{scene.name}'. DO NOT EDIT: regenerate with "
              f"`tswm generate {again}`.\n"
              f"# scene-sha256: {scene.digest}\n"
              f"# generator-sha256: {generator_digest()}\n"
              f"# generator-version: {GENERATOR_VERSION}\n"
              f"# body-sha256: {hashlib.sha256(body.encode()).hexdigest()}\n")
    source = header + body
    try:
        compile(source, f"{module_name(scene.name)}.py", "exec")
    except SyntaxError as error:  # a generator bug, never the scene's text: that only enters through inert()
        raise GenerationError(f"{scene.source}: the generated module does not compile ({error})") from None
    return source


def body_is_intact(source: str) -> bool:
    """True when the module body still matches the hash in its header."""
    stated, actual = body_digests(source)
    return stated == actual


def write_module(model: Model, directory: str | Path, force: bool = False) -> Path:
    """Write the scene's module atomically; refuse to replace a hand-edited one unless ``force``."""
    path = Path(directory) / f"{module_name(model.scene.name)}.py"
    if path.exists() and not force and not body_is_intact(path.read_text()):
        raise EditedModuleError(f"{path} was edited by hand (its body no longer matches its body-sha256 header); "
                                "regenerating would lose the edit: use --force to overwrite it")
    return write_atomic(path, generate_module(model))
