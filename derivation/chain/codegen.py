"""Emit the numba module of a chain scene through a Jinja2 template (templates/chain_module.py.j2).

Every formula comes from derivation/chain/: each stage's equivalent wedge (stages.py) and each
sliding mode's reduced equation of motion, normal forces, denominator and stage forces
(dynamics.py); the scene's values are slots of the parameter vector p (their defaults the scene's, printed
by ``inert``) and what they determine (slopes, friction angles, levers, FTFs, speed factors) is derived
from them once per run by the module's ``prepare(p)``, so the code depends on the chain's structure only. The
module's rhs, jac and guards take the runtime's explicit signatures, so the compiled step loop
(tswm_runtime/integration/segment.py) runs it; tswm_runtime/chains/kernel.py decides its modes. A mode
and its mirror image (the same regimes on the other flanks, moving the other way) share their functions
(``_mode_calls``: each expression checked equal or opposite in SymPy), as the single-stage modules do.
"""
from __future__ import annotations

import hashlib
import re
from importlib import resources

import jinja2
import sympy as sp

from derivation import mechanics as mech
from derivation.chain import clearance as cl
from derivation.chain import dynamics as dyn
from derivation.chain import stages as st
from derivation.chain import valve as vl
from derivation.chain.scene import ChainScene
from derivation.codegen import GENERATOR_VERSION, GenerationError, _comment, _docstring, _Printer, inert, module_name

q0 = sp.Symbol("q_0", real=True)          # body 0's coordinate (the state y[0]; v_0 is y[1])
MOTOR = sp.Symbol("motor", real=True)     # the motor's torque (or force) on body 0 at v_0, from its table
DIRECTION = sp.Symbol("direction", real=True)   # the sign of v_0 in a sliding mode, 0 at rest
STATES = ("q0", "v0")
SWITCHED_GUARDS = ("seat", "switch", "delay")   # the seat's contact, the switch picking up or dropping out, its delay
# With a clearance: the gap closing on flank a, on flank b, the output group's speed reaching 0.
CLEARANCE_GUARDS = ("gap_a", "gap_b", "v_out")
# Its latches after the contact per clearance stage: the groups' directions, whether the output and the input group is
# held at rest (stuck while the stage is open: its acceleration 0), then rho_sign per stage, then the gap offset G_k per
# clearance stage, the current clearance stage (its index in CLEARANCE_STAGES: open, or last opened) and its c_k.
CLEARANCE_LATCHES = ("direction_in", "direction_out", "held_out", "held_in")
Q_CUR, V_CUR, C_CUR = sp.symbols("q_cur v_cur c_cur", real=True)   # y[2], y[3] and c_k of the current stage k
GENERATOR_SOURCES = ("chain/codegen.py", "chain/clearance.py", "chain/dynamics.py", "chain/stages.py", "chain/scene.py",
                     "chain/valve.py", "templates/chain_module.py.j2")


def generator_digest() -> str:
    """sha256 over the chain generator's sources."""
    h = hashlib.sha256()
    root = resources.files("derivation")
    for name in GENERATOR_SOURCES:
        h.update(name.encode() + root.joinpath(*name.split("/")).read_bytes())
    return h.hexdigest()


class _Code:
    """Python source of expressions in the chain's symbols: one CSE per function, each value or derived number
    it uses read from its slot of p (``slots``), the body forces from ``body_forces`` where an expression
    uses them; ``derive(name, formula)`` adds a derived slot that ``prepare`` fills (``_layout``)."""

    def __init__(self, stages: int, slots: dict[sp.Symbol, str], derive, states: dict[sp.Symbol, str] | None = None):
        self.sym = dyn.symbols(stages)
        self.slots = slots
        self.derive = derive
        self.states = states or {}      # with a clearance: the output group's coordinate and both groups' speeds
        self.printer = _Printer()

    @property
    def runtime(self) -> set[sp.Symbol]:
        """What a mode's expressions read at run time: the body forces and what they are made of (with a
        clearance also the states ``states``)."""
        return {*self.sym.force, MOTOR, q0, DIRECTION, vl.POWERED, vl.SEATED, *self.states}

    def reads(self, used: set) -> list[str]:
        """``name = p[SLOT]`` for each value or derived symbol in ``used``, in slot order."""
        return [f"{s} = p[{self.slots[s]}]" for s in self.slots if s in used]

    def state_lines(self, used: set, direction: str) -> list[str]:
        """The lines that compute the run-time symbols in ``used``: the body forces of a sliding mode in
        ``direction`` (a number or the argument's name), q0, the motor's torque, its power, the seat."""
        lines = []
        if used & set(self.sym.force):
            lines.append(f"{', '.join(map(str, self.sym.force))} = body_forces(t, y, p, {direction})")
        if q0 in used:
            lines.append("q_0 = y[0]")
        lines += [f"{s} = {at}" for s, at in self.states.items() if s in used]
        if MOTOR in used:
            lines.append("motor = motor_torque(y[1], p)")
        if vl.POWERED in used:
            lines.append("powered = motor_on(p)")
        if vl.SEATED in used:
            lines.append("seated = p[P_SEATED]")
        return lines

    def body(self, exprs: list[sp.Expr], direction: str = "0.0") -> tuple[list[str], list[str]]:
        """Lines and results; the body forces of a sliding mode in ``direction``."""
        exprs = [sp.sympify(e) for e in exprs]
        used = set().union(*(e.free_symbols for e in exprs))
        lines = self.state_lines(used, direction) + self.reads(used)
        replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("c"))
        lines += [f"{s} = {self.printer.doprint(e)}" for s, e in replacements]
        return lines, [self.printer.doprint(e) for e in reduced]

    def function(self, name: str, doc: str, exprs: list[sp.Expr], args: str = "t, y, p",
                 direction: str = "0.0") -> dict:
        lines, results = self.body(exprs, direction)
        return {"name": name, "args": args, "doc": doc, "lines": lines, "result": ", ".join(results)}

    def terms(self, expr: sp.Expr) -> dict:
        """``expr`` as sum of coefficient times run-time symbol (None: the constant term): each coefficient
        d expr / d symbol free of the run-time symbols (a mode's expressions are affine in the body forces:
        Newton's laws are linear in them), checked here; a GenerationError names an expression that is not."""
        expr = sp.sympify(expr)
        used = sorted(expr.free_symbols & self.runtime, key=str)
        out = {None: expr.subs({r: 0 for r in used})}
        for r in used:
            out[r] = sp.diff(expr, r)
            if out[r].free_symbols & self.runtime:
                raise GenerationError(f"a chain mode's expression is not affine in {r}: {expr}")
        return out

    def blocks(self, name: str, doc: str, exprs: list[sp.Expr], variants: dict[str, tuple[str, dict]]) -> dict:
        """A function ``name`` over coefficient blocks: its expressions as sums of coefficients times run-time
        symbols (``terms``), one block per variant (``variants``: suffix -> (what it stands for, the substitution
        that makes it: friction angles' and other signs)), its coefficients derived once per run into consecutive
        slots of p, the first at D_<name>_<suffix>_0 (a derived slot); the function takes a block's first slot as
        ``k`` and reads p[k + i]: no trigonometry of the scene's values per call."""
        signed = {suffix: [self.terms(e.subs(at, simultaneous=True)) for e in exprs]
                  for suffix, (_, at) in variants.items()}
        layout = [(i, r) for i in range(len(exprs)) for r in [None, *sorted(self.runtime, key=str)]
                  if any(r in t[i] and t[i][r] != 0 for t in signed.values())]
        for suffix, (shown, _) in variants.items():
            for j, (i, r) in enumerate(layout):
                self.derive(sp.Symbol(f"{name}_{suffix}_{j}", real=True), signed[suffix][i].get(r, sp.Integer(0)),
                            f"{name}_{suffix}_{j}: {name}'s result {i}, its {r or 'constant'} term ({shown})")
        results = [" + ".join(f"p[k + {j}]" + (f"*{r}" if r is not None else "") for j, (at, r) in enumerate(layout)
                              if at == i) or "0.0" for i in range(len(exprs))]
        return {"name": name, "args": "t, y, p, direction, k", "doc": doc, "stride": len(layout),
                "lines": self.state_lines({r for _, r in layout}, "direction"), "result": ", ".join(results)}

    def rho_variants(self, combos: dict[tuple[int, ...], str]) -> dict[str, tuple[str, dict]]:
        """``blocks``' variants of friction-angle sign combinations (``combos``: signs -> suffix): rho_k -> -rho_k
        where a sign is negative."""
        return {suffix: (", ".join(f"{'+' if s > 0 else '-'}{rho}" for s, rho in zip(signs, self.sym.rho)),
                         {rho: s * rho for rho, s in zip(self.sym.rho, signs) if s < 0})
                for signs, suffix in combos.items()}


def _range(rule, names: dict[str, str]) -> tuple:
    """A rule's (lo, hi, lo_in, hi_in) for the module: None for no bound; hi the slot name of a sibling value
    (the hysteresis is at most the setting)."""
    hi = names[rule.hi] if isinstance(rule.hi, str) else rule.hi
    return (rule.lo, hi, rule.lo_in, rule.hi_in)


def _layout(chain: ChainScene) -> tuple[list[dict], list[dict], dict[sp.Symbol, str], object]:
    """p after its latches: the scene's values (name, slot, SI value, scene key, unit, range) and what
    ``prepare`` derives from them (name, slot, formula in the values and earlier derived names), the
    slot of each symbol the generated functions read, and ``derive(target, formula)``, which adds a derived
    slot (the mode functions' coefficients, ``_Code.blocks``)."""
    n = len(chain.stages)
    sym = dyn.symbols(n)
    printer = _Printer()
    values, derived, slots = [], [], {}
    pairs = chain.value_rules()
    names = {p.key.rsplit(".", 1)[-1]: p.name for p, _ in pairs
             if p.key.startswith("switch.") or p.key.endswith(".clearance")}
    for p, rule in pairs:
        slot = f"V_{p.name}"
        values.append({"name": p.name, "slot": slot, "si": p.value, "value": inert(p.value, p.name), "key": p.key,
                       "unit": p.unit, "range": _range(rule, names)})
        slots[sp.Symbol(p.name, real=True)] = slot

    inertia = {sym.inertia[j]: sp.Symbol(body.inertia.name, real=True) for j, body in enumerate(chain.bodies)}

    def derive(target: sp.Symbol, expr, note: str = "") -> None:
        slot = f"D_{target}"
        expr = sp.sympify(expr).subs(inertia)
        derived.append({"name": str(target), "slot": slot, "formula": printer.doprint(expr), "expr": expr,
                        "note": note or f"{target} = {printer.doprint(expr)}"})
        for v in values:
            v["read"] = v.get("read", False) or sp.Symbol(v["name"], real=True) in expr.free_symbols
        slots[target] = slot
    per_stage = []
    for k, stage in enumerate(chain.stages):
        kind, wedge = st.kinds()[stage.kind], st.equivalent_wedge(stage.kind)
        names_k = {symbol: sp.Symbol(stage.params[key].name, real=True) for key, symbol in kind.keys.items()}
        per_stage.append({sym.gamma[k]: sp.atan(wedge.tan_gamma), sym.rho[k]: sp.atan(wedge.tan_rho),
                          sym.lever_in[k]: wedge.lever_in, sym.lever_out[k]: wedge.lever_out})
        per_stage[-1] = {t: sp.sympify(e).subs(names_k) for t, e in per_stage[-1].items()}
    for group in (sym.gamma, sym.rho, sym.lever_in, sym.lever_out):
        for k, target in enumerate(group):
            derive(target, per_stage[k][target])
    for k in range(n):
        for name, flank in (("psi_t", "a"), ("psi_i", "b")):
            derive(sp.Symbol(f"{name}_{k + 1}", real=True), _psi(sym, k, flank))
    for j, factor in enumerate(dyn.speed_factors(sym)):
        derive(sp.Symbol(f"c_{j}", real=True), factor)
    valve = chain.bodies[-1].valve
    derive(sp.Symbol("load_friction", real=True), vl.coulomb(valve) if valve else sp.Float(0.0))
    derive(sp.Symbol("delay", real=True), vl.symbol(chain.switch.delay) if chain.switch else sp.Float(0.0))
    for j, body in enumerate(chain.bodies):
        slots[sym.inertia[j]] = slots[sp.Symbol(body.inertia.name, real=True)]
    return values, derived, slots, derive


def current(chain: ChainScene) -> tuple[sp.Symbol, sp.Symbol, sp.Symbol]:
    """(q, v, c) of the current clearance stage k: y[2], y[3] and c_k = v_k / v_0 of the rigid chain (a latch with
    several clearance stages; with one, q_k, v_k and its derived c_k)."""
    if len(chain.clearances) > 1:
        return Q_CUR, V_CUR, C_CUR
    k = chain.clearances[0].stage
    return sp.Symbol(f"q_{k}", real=True), sp.Symbol(f"v_{k}", real=True), sp.Symbol(f"c_{k}", real=True)


def _coordinates(chain: ChainScene) -> list[sp.Expr]:
    """Each body's coordinate (q = 0 at the start): q_j = c_j q_0 with c_j = v_j / v_0 (derived by ``prepare``);
    with clearances, a body after one (the scene allows no spring between two) moves rigidly with the last body,
    whose coordinate is (c_N / c_k) y[2] with k the current clearance stage (``current``; y[2] is rescaled when
    another stage opens), so q_j = (c_j / c_k) y[2]."""
    c = [sp.Symbol(f"c_{j}", real=True) for j in range(len(chain.bodies))]
    if not chain.clearances:
        return [c_j * q0 for c_j in c]
    q, _, c_k = current(chain)
    first = chain.clearances[0].stage
    return [c[j] * q0 if j < first else c[j] / c_k * q for j in range(len(chain.bodies))]


def _forces(chain: ChainScene, code: _Code, direction: sp.Expr) -> list[sp.Expr]:
    """The generalized force on each body: its force or torque, the motor's while powered, less a spring's
    stiffness times its coordinate q_j (``_coordinates``), and the valve's force on the last body moving in
    ``direction``."""
    q = _coordinates(chain)
    return [sp.Symbol(b.force.name, real=True) + (vl.drive(MOTOR) if b.motor is not None else 0)
            - (sp.Symbol(b.stiffness.name, real=True) * q[j] if b.stiffness is not None else 0) + (vl.valve_force(b.valve, q[j], direction) if b.valve is not None else 0)
            for j, b in enumerate(chain.bodies)]


def _measured(chain: ChainScene, mode: dyn.SlidingMode) -> sp.Expr:
    """What the torque switch measures in a mode: body 0's drive torque (its torque and the motor's) or
    stage k's generalized force on its output body; 0 without a switch."""
    if chain.switch is None:
        return sp.Integer(0)
    if chain.switch.stage == 0:
        body = chain.bodies[0]
        return sp.Symbol(body.force.name, real=True) + (MOTOR if body.motor is not None else 0)
    return mode.on_output[chain.switch.stage - 1]


def _jam(code: _Code, mode: dyn.SlidingMode) -> sp.Expr:
    """The product of the stages' jam factors cos(gamma_k + f s rho_k), from mechanics: > 0 unless one jams."""
    return sp.Mul(*(mech.sliding(f, mode.direction).jam_factor.subs({mech.gamma: code.sym.gamma[k],
                                                                       mech.rho: code.sym.rho[k]})
                    for k, f in enumerate(mode.flanks)))


def _mode_exprs(chain: ChainScene, code: _Code, mode: dyn.SlidingMode) -> dict[str, list[sp.Expr]]:
    """A sliding mode's expressions per generated function: a_0; D, jam, N_k, what the switch measures; per
    stage the forces on its input and output body and its normal force."""
    return {"accel": [mode.accel],
            "contact": [mode.denominator, _jam(code, mode), *mode.normal, _measured(chain, mode)],
            "stage_forces": [e for pair in zip(mode.on_input, mode.on_output, mode.normal) for e in pair]}


def _signs(exprs: dict, shared: dict) -> dict[str, tuple[int, ...]] | None:
    """Per function, the sign each of a mode's expressions has against the shared function's (equal or opposite:
    its mirror image, the same regimes on the other flank in the other direction); None when one is neither."""
    out = {}
    for name, own in exprs.items():
        signs = []
        for e, base in zip(own, shared[name]):
            if e == base or sp.expand(e - base) == 0:
                signs.append(1)
            elif e == -base or sp.expand(e + base) == 0:
                signs.append(-1)
            else:
                return None
        out[name] = tuple(signs)
    return out


def _rho_signs(mode: dyn.SlidingMode, base: dyn.SlidingMode) -> tuple[int, ...]:
    """Per stage +1 where the mode's regime is the base mode's, -1 where it is the other: there the stage's FTF
    is the base's with -rho for rho (tan(gamma + rho) against tan(gamma - rho))."""
    return tuple(1 if r == b else -1 for r, b in zip(mode.regimes, base.regimes))


def _with_rho_signs(code: _Code, exprs: dict, signs: tuple[int, ...]) -> dict:
    """The expressions with each stage's friction angle times its sign."""
    flip = {rho: s * rho for rho, s in zip(code.sym.rho, signs) if s < 0}
    return {name: [e.subs(flip, simultaneous=True) for e in own] for name, own in exprs.items()} if flip else exprs


def _mode_calls(chain: ChainScene, code: _Code, modes: list[dyn.SlidingMode]) -> tuple[list[dict], list[dict]]:
    """The per-mode functions, one set per group of modes that are the first's with some stages' friction
    angles negated (the other regime of a stage) and mirrored (the same regimes on the other flanks in the
    other direction: the body forces in the direction the caller passes), each checked in SymPy, expression by
    expression, equal or opposite; per mode the call: the group's functions, its direction, the first slot of
    its friction-angle signs' coefficients (``_Code.blocks``) and which results change sign."""
    calls, groups = [], []     # groups: (first index, its expressions)
    for index, mode in enumerate(modes):
        exprs = _mode_exprs(chain, code, mode)
        found = next(((first, rho, signs) for first, base in groups
                      if (signs := _signs(exprs, _with_rho_signs(code, base, rho := _rho_signs(mode, modes[first]))))
                      is not None), None)
        if found is None:
            groups.append((index, exprs))
            found = (index, (1,) * len(mode.regimes), {name: (1,) * len(e) for name, e in exprs.items()})
        first, rho, signs = found
        calls.append({"group": first, "direction": f"{mode.direction:.1f}", "rho": rho,
                      "suffix": "".join("p" if s > 0 else "m" for s in rho),
                      "accel_sign": "-" if signs["accel"][0] < 0 else "",
                      "contact_flips": [k for k, sg in enumerate(signs["contact"]) if sg < 0],
                      "force_flips": [k for k, sg in enumerate(signs["stage_forces"]) if sg < 0]})
    functions = []
    for group, exprs in groups:
        members = [i for i, call in enumerate(calls) if call["group"] == group]
        combos = {calls[i]["rho"]: calls[i]["suffix"] for i in members}
        functions += _group_functions(code, group, modes, exprs, combos,
                                      "; modes " + ", ".join(f"{i} ({modes[i].name})" for i in members))
    return functions, calls


def _group_functions(code: _Code, index: int, modes: list[dyn.SlidingMode], exprs: dict, combos: dict,
                     members: str) -> list[dict]:
    docs = {"accel": "a_0",
            "contact": "(D, jam, N_1, ..., N_N, measured): the denominator, the stages' jam factors' product and each "
                       "stage's normal force; the mode holds while each is >= 0 (D, jam > 0); what the torque switch "
                       "measures",
            "stage_forces": "per stage (on its input body, on its output body, normal force)"}
    return [code.blocks(f"{name}_{index}", f"{docs[name]} in mode {index}: {modes[index].name}{members} (their body "
                        "forces in `direction`, the coefficients of their stages' friction-angle signs from slot k: "
                        f"D_{name}_{index}_<p or m per stage>_0)", e, code.rho_variants(combos))
            for name, e in exprs.items()]


def _by_state(code: _Code, chain: ChainScene, accel: sp.Expr, direction: sp.Expr) -> tuple[sp.Expr, ...]:
    """(d a / d q_0, d a / d motor) of an acceleration in the body forces, the valve's in ``direction``, and with a
    clearance in stage k d a / d q_k: the springs' and the motor's share (the forces are the only state dependence;
    the motor's torque changes with v_0 by its table's slope, ``motor_slope``)."""
    accel = accel.subs(dict(zip(code.sym.force, _forces(chain, code, direction))))
    by = (q0, MOTOR) + ((current(chain)[0],) if chain.clearances else ())
    return tuple(sp.diff(accel, x) for x in by)


def _jacobian(code: _Code, chain: ChainScene, mode: dyn.SlidingMode) -> tuple[sp.Expr, ...]:
    """d a_0 by q_0 and by the motor's torque (and by q_k with a clearance) in a mode (``_by_state``)."""
    return _by_state(code, chain, mode.accel, mode.direction)


def _jacobians(code: _Code, chain: ChainScene, modes: list[dyn.SlidingMode]) -> tuple[list[str], list[tuple]]:
    """The reads of p the Jacobian needs and (the modes, d a_0 / d q_0, d a_0 / d v_0) for each distinct pair
    of the modes' Jacobian entries (a mode and its mirror image have the same), in the order of their first
    mode."""
    found: dict[tuple[str, ...], list[int]] = {}
    used: set = set()
    for index, mode in enumerate(modes):
        entries = _jacobian(code, chain, mode)
        used |= set().union(*(e.free_symbols for e in entries))
        found.setdefault(tuple(code.printer.doprint(e) for e in entries), []).append(index)
    reads = code.reads(used)
    reads += [f"{s} = {at}" for s, at in code.states.items() if s in used]
    return reads, [(indices, *entries) for entries, indices in found.items()]


def generate_chain_module(chain: ChainScene) -> str:
    """Source of the chain scene's module: its code depends on the chain's structure only (stage kinds, their
    modelled flanks, which bodies have springs, motor, valve, seat, switch); the scene's values are the
    defaults of p's slots."""
    n = len(chain.stages)
    values, derived, slots, derive = _layout(chain)
    k = len(chain.clearances)
    states = None
    if k:
        q, v, c_k = current(chain)
        states = {q: "y[2]", sp.Symbol("v_0", real=True): "y[1]", v: "y[3]",
                  **({c_k: "p[P_SPEED_CUR]"} if k > 1 else {}),
                  **{sp.Symbol(f"gap_{c.stage}", real=True): f"p[P_GAP + {i}]" for i, c in enumerate(chain.clearances)}}
    code = _Code(n, slots, derive, states)
    reachable = dyn.reachable(tuple(s.flanks for s in chain.stages))
    modes = [dyn.sliding(direction, regimes) for direction, regimes in reachable]
    functions = [code.function("body_forces", "(F_0, ..., F_N): each body's force or torque (the motor's while "
                               "powered), a spring's part -stiffness q_j with q_j = (v_j/v_0) q_0, the valve's force "
                               "on the last body moving in `direction` (0: at rest, without its friction)",
                               _forces(chain, code, DIRECTION), args="t, y, p, direction")]
    shared, calls = _mode_calls(chain, code, modes)
    functions += shared
    gaps = CLEARANCE_GUARDS if k else ()
    guards = ("D", "jam", *(f"N_{i + 1}" for i in range(n)), "v0", *gaps, *SWITCHED_GUARDS)
    directions = [tuple([-1] * (n + 2) + [-mode.direction] + [-1] * (len(gaps) + len(SWITCHED_GUARDS)))
                  for mode in modes]
    opened = []
    for i, c in enumerate(chain.clearances):
        own, calls_i, block = _open_functions(chain, code, c)
        functions += own
        opened.append(_open_template(chain, slots, c, i, calls_i, block))
        directions.append(tuple([-1] * len(guards)))
    switch, valve = chain.switch, chain.bodies[-1].valve
    seat = valve.seat if valve is not None else None
    first = len(vl.P_NAMES)
    slot = {d["slot"]: first + len(values) + i for i, d in enumerate(derived)}
    motor = chain.bodies[0].motor
    points = len(motor.speed) if motor else 0
    motor_first = first + len(values) + len(derived)     # the motor's table after the derived slots: speeds, torques
    open_first = motor_first + 2 * points                # with a clearance, its latches after the motor's table
    constants = {
        "SCENE": chain.name, "DESCRIPTION": chain.description, "SCENE_DIGEST": chain.digest, "STAGES": n,
        "STATES": STATES, "MODES": tuple(m.name for m in modes), "MODE_DIRECTION": tuple(m.direction for m in modes),
        "MODE_REGIMES": tuple(m.regimes for m in modes), "MODE_FLANKS": tuple(m.flanks for m in modes),
        "STAGE_KINDS": tuple(s.kind for s in chain.stages),
        "BODY_MOTIONS": tuple(b.motion for b in chain.bodies), "GUARDS": guards,
        "GUARD_DIRECTIONS": tuple(directions), "OBSERVABLES": (), "RUN": dict(vars(chain.run)),
        "PARAM_NAMES": tuple(v["name"] for v in values), "PARAM_UNITS": tuple(v["unit"] for v in values),
        "PARAM_KEYS": tuple(v["key"] for v in values), "PARAM_RANGES": tuple(v["range"] for v in values),
        "DERIVED": tuple(d["name"] for d in derived),
        "P_NAMES": (*vl.P_NAMES, *(v["name"] for v in values), *(f"derived {d['name']}" for d in derived),
                    *(f"motor {name} {i}" for name in ("speed", "torque") for i in range(points))),
        "P_SWITCH": vl.P_SWITCH, "P_PICK": vl.P_PICK, "P_SEATED": vl.P_SEATED, "P_VOLTAGE": vl.P_VOLTAGE,
        "P_VALUES": first, "P_DERIVED": first + len(values),
        "P_GAMMA": slot["D_gamma_1"], "P_RHO": slot["D_rho_1"], "P_LEVER_IN": slot["D_r_in_1"],
        "P_LEVER_OUT": slot["D_r_out_1"], "P_PSI": slot["D_psi_t_1"], "P_SPEED": slot["D_c_0"],
        "P_SLACK": slot["D_load_friction"], "P_DELAY": slot["D_delay"],
        "P_SEAT": first + next(i for i, v in enumerate(values) if v["name"] == seat.name) if seat else -1,
        "ARMED": vl.ARMED, "PICKED": vl.PICKED, "TRIPPED": vl.TRIPPED,
        "SWITCH_ON": -1 if switch is None else switch.stage, "HAS_SEAT": seat is not None,
    }
    if k:
        stages = tuple(c.stage for c in chain.clearances)
        q, v, _ = current(chain)
        first_latch = open_first + k
        constants.update({
            "STATES": ("q0", "v0", str(q).replace("_", ""), str(v).replace("_", "")), "CLEARANCE_STAGES": stages,
            "OPEN": len(modes), "MODES": (*constants["MODES"], *(f"open: stage {j}" for j in stages)),
            "MODE_DIRECTION": (*constants["MODE_DIRECTION"], *(0,) * k),
            "MODE_REGIMES": (*constants["MODE_REGIMES"], *((),) * k),
            "MODE_FLANKS": (*constants["MODE_FLANKS"], *((),) * k),
            "P_NAMES": (*constants["P_NAMES"], *(f"contact {j}" for j in stages), *CLEARANCE_LATCHES,
                        *(f"rho_sign {i + 1}" for i in range(n)), *(f"gap offset {j}" for j in stages),
                        "current clearance stage", "its c_k"),
            "P_CONTACT": open_first, "P_DIRECTION_IN": first_latch, "P_DIRECTION_OUT": first_latch + 1,
            "P_HELD_OUT": first_latch + 2, "P_HELD_IN": first_latch + 3, "P_RHO_SIGN": first_latch + 4,
            "P_GAP": first_latch + 4 + n, "P_CURRENT": first_latch + 4 + n + k,
            "P_SPEED_CUR": first_latch + 5 + n + k, "IMPACT_FRAME": IMPACT_FRAME})
    for i, v in enumerate(values):
        v["index"] = first + i
    for d in derived:
        d["index"] = slot[d["slot"]]
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(resources.files("derivation") / "templates")),
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["docstring"] = _docstring
    env.filters["comment"] = _comment
    jac_reads, jacobians = _jacobians(code, chain, modes)
    body = env.get_template("chain_module.py.j2").render(
        clearances=opened,
        chain=chain, n=n, modes=modes, calls=calls, constants={k: inert(v, k) for k, v in constants.items()},
        values=values, defaults=inert(tuple(v["si"] for v in values), "PARAM_DEFAULTS"),
        derived=derived, prepare_lines=[*(f"{v['name']} = p[{v['slot']}]" for v in values if v["read"]),
                                        *_prepare_lines(derived, code.printer)],
        functions=functions, jac_reads=jac_reads, jacobians=jacobians, motor=motor,
        motor_arrays={name: inert(table, name) for name, table in (
            ("MOTOR_SPEED", motor.speed), ("MOTOR_TORQUE", motor.torque))} if motor else {},
        motor_voltage=inert(motor.voltage, "voltage") if motor else "", motor_points=points,
        motor_slots={"speed": motor_first, "torque": motor_first + points}, guards=guards,
        contact_targets=", ".join(f"g[{k}]" for k in range(n + 2)),
        force_targets=", ".join(f"out[{k}]" for k in range(3 * n)),
        body_targets=", ".join(f"out[{j}]" for j in range(n + 1)),
        impact_targets=", ".join(f"out[{j}]" for j in range(len(IMPACT_FRAME))),
        setting=f"p[V_{switch.setting.name}]" if switch else "math.inf",
        hysteresis=f"p[V_{switch.hysteresis.name}]" if switch else "0.0",
        seat=f"p[V_{seat.name}]" if seat is not None else "math.nan")
    body = re.sub(r"\n+@njit", "\n\n\n@njit", body)
    header = (f"# Generated by tswm {GENERATOR_VERSION} from chain scene '{chain.name}'. DO NOT EDIT: regenerate "
              "it from its scene file.\n"
              f"# scene-sha256: {chain.digest}\n"
              f"# generator-sha256: {generator_digest()}\n"
              f"# generator-version: {GENERATOR_VERSION}\n"
              f"# body-sha256: {hashlib.sha256(body.encode()).hexdigest()}\n")
    source = header + body
    try:
        compile(source, f"{module_name(chain.name)}.py", "exec")
    except SyntaxError as error:
        raise GenerationError(f"{chain.source}: the generated chain module does not compile ({error})") from None
    return source


def _prepare_lines(derived: list[dict], printer: _Printer) -> list[str]:
    """``name = formula`` for each derived slot in order; the mode functions' coefficients (after the wedge
    numbers they are made of) through one CSE, their shared subexpressions first."""
    plain = [d for d in derived if not d["name"].startswith(("accel_", "contact_", "stage_forces_", "open_"))]
    blocks = derived[len(plain):]
    replacements, reduced = sp.cse([d["expr"] for d in blocks], symbols=sp.numbered_symbols("shared_"))
    return ([f"{d['name']} = {d['formula']}" for d in plain] + [f"{s} = {printer.doprint(e)}" for s, e in replacements]
            + [f"{d['name']} = {printer.doprint(e)}" for d, e in zip(blocks, reduced)])


IMPACT_FRAME = ("nu", "s", "W_nn", "W_nt", "W_tt", "mu", "e", "dv_in_dPn", "dv_in_dPt", "dv_out_dPn", "dv_out_dPt")


def _open_signs(n: int, k: int, exprs: list[sp.Expr]) -> list[sp.Symbol]:
    """The signs the open phase's expressions depend on while stage k is open, in ``open_block``'s bit order: each
    closed stage's regime rho_sign_i (its friction angle rho_i there stands for rho_sign_i rho_i), then the groups'
    directions direction_in, direction_out where an expression has them (a group holding a closed stage); k's own
    friction enters only the impact, unsigned."""
    used = set().union(*(e.free_symbols for e in exprs))
    return ([cl.rho_sign(i) for i in range(1, n + 1) if i != k]
            + [d for d in (cl.DIRECTION_IN, cl.DIRECTION_OUT) if d in used])


def _open_variants(code: _Code, signs: list[sp.Symbol]) -> dict[str, tuple[str, dict]]:
    """``_Code.blocks``' variants of the open phase: in variant m, sign b is -1 where bit b of m is set (a closed
    stage's rho_i then -rho_i), +1 otherwise."""
    rho_of = {cl.rho_sign(i + 1): rho for i, rho in enumerate(code.sym.rho)}
    variants = {}
    for m in range(2 ** len(signs)):
        value = {s: -1 if m >> b & 1 else 1 for b, s in enumerate(signs)}
        flip = {rho_of[s]: -rho_of[s] for s, v in value.items() if v < 0 and s in rho_of}
        variants["".join("p" if value[s] > 0 else "m" for s in signs)] = (
            ", ".join(f"{s} = {value[s]:+d}" for s in signs), {**value, **flip})
    return variants


def _open_functions(chain: ChainScene, code: _Code, c) -> tuple[list[dict], dict[str, str], str]:
    """The open phase of clearance ``c``'s stage k (``clearance.open_phase``, ``open_impact``): the groups'
    accelerations, (jam, the closed stages' normal forces, the gap, what the switch measures), the stage forces,
    the Jacobian and the impact's frame on each flank, each a sum of coefficients times the run-time symbols
    (``_Code.blocks``), a block per combination of the signs they depend on (``_open_signs``); the valve's
    friction in the output group's direction; body k's coordinate and speed are y[2], y[3] (the current stage's,
    ``current``: k is current while open) and its gap's offset the latch G_k (symbol gap_k). Returns the functions
    (named <name>_k), each one's call from the template (its block chosen by ``open_block_k(p)`` from the sign
    latches) and open_block_k's sum."""
    n, k = len(chain.stages), c.stage
    q, v, c_cur = current(chain)
    own = {sp.Symbol(f"q_{k}", real=True): q, sp.Symbol(f"v_{k}", real=True): v}
    at_k = {c_cur: sp.Symbol(f"c_{k}", real=True)}   # c_k for the current stage's c in the Jacobian
    phase = cl.open_phase(n, k)
    closed = sorted(phase.normal)
    sym = code.sym
    per_stage = []
    for i in range(1, n + 1):
        if i in phase.normal:
            w = phase.stage_force[i]
            per_stage += [sym.lever_in[i - 1] * -cl.signed_psi(i) * w, sym.lever_out[i - 1] * w, phase.normal[i]]
        else:
            per_stage += [sp.Integer(0)] * 3
    switch = chain.switch
    if switch is None:
        measured = sp.Integer(0)
    elif switch.stage == 0:
        measured = sp.Symbol(chain.bodies[0].force.name, real=True) + (MOTOR if chain.bodies[0].motor else 0)
    else:
        measured = per_stage[3 * (switch.stage - 1) + 1]
    restitution = sp.Symbol(c.restitution.name, real=True)
    exprs = {
        "open_accel": ("(a_0, a_k): the input and output groups' accelerations", list(phase.accel)),
        "open_contact": ("(jam, the closed stages' normal forces, the gap, what the torque switch measures)",
                         [phase.jam, *(phase.normal[i] for i in closed), phase.gap.subs(own), measured]),
        "open_stage_forces": ("per stage (on its input body, on its output body, normal force; 0 for the open "
                              "stage)", per_stage),
        "open_jacobian": ("(d a_0, d a_k) by q_0, by the motor's torque and by q_k",
                          [e.subs(at_k) for a in phase.accel for e in _by_state(code, chain, a, DIRECTION)])}
    for flank in ("a", "b"):
        im = cl.open_impact(n, k, flank)
        exprs[f"open_impact_{flank}"] = (f"the collision's frame on flank {flank} (IMPACT_FRAME)", [
            e.subs(own) for e in (im.nu, im.slip, im.W[0, 0], im.W[0, 1], im.W[1, 1], im.mu, restitution,
                                  *im.jump_in, *im.jump_out)])
    signs = _open_signs(n, k, [e for _, group in exprs.values() for e in group])
    variants = _open_variants(code, signs)
    first = next(iter(variants))
    functions, calls = [], {}
    for name, (doc, e) in exprs.items():
        f = code.blocks(f"{name}_{k}", f"{doc} while stage {k} is open (the body forces in the output group's "
                        f"`direction`; the coefficients of the signs {', '.join(map(str, signs))} from slot k: "
                        f"D_{name}_{k}_<p or m per sign>_0)", e, variants)
        functions.append(f)
        calls[name] = (f"{name}_{k}(t, y, p, p[P_DIRECTION_OUT], D_{name}_{k}_{first}_0 + {f['stride']} * "
                       f"open_block_{k}(p))" if f["stride"] else f"{name}_{k}(t, y, p, p[P_DIRECTION_OUT], 0)")
    latch = {cl.DIRECTION_IN: "P_DIRECTION_IN", cl.DIRECTION_OUT: "P_DIRECTION_OUT",
             **{cl.rho_sign(i): f"P_RHO_SIGN + {i - 1}" for i in range(1, n + 1)}}
    block = " + ".join(f"(1 if p[{latch[s]}] < 0.0 else 0) * {2 ** b}" for b, s in enumerate(signs))
    return functions, calls, block or "0"


def _open_template(chain: ChainScene, slots: dict[sp.Symbol, str], c, index: int, calls: dict[str, str],
                   block: str) -> dict:
    """What the template's open phase of clearance ``c`` (the ``index``-th) needs: the stage, its mode, the open
    functions' calls, ``open_block``'s sum of the sign latches' bits, the targets of open_contact and the slots it
    reads."""
    n, k = len(chain.stages), c.stage
    closed = [i for i in range(1, n + 1) if i != k]
    held = {"held_in": ("P_HELD_IN", 0, k - 1), "held_out": ("P_HELD_OUT", k, n)}   # its latch, its closed stages i < j <= n
    return {"stage": k, "index": index, "mode": f"OPEN + {index}" if index else "OPEN", "call": calls, "block": block,
            "held": [{"latch": latch, "guards": f"g[{2 + i}:{2 + j}]", "forces": f"out[{3 * i}:{3 * j}]",
                      "switch": f"{i} < SWITCH_ON <= {j}"} for latch, i, j in held.values() if j > i],
            "contact_targets": ", ".join(["g[1]", *(f"g[{1 + i}]" for i in closed), "gap"]),
            "c_last": slots[sp.Symbol(f"c_{n}", real=True)], "clearance": slots[sp.Symbol(c.clearance.name, real=True)]}


def _psi(sym: dyn.Symbols, k: int, flank: str) -> sp.Expr:
    """Stage k's FTF of forward sliding on a flank: tractive (a) or inverse-tractive (b), from mechanics."""
    return mech.sliding(flank, 1).psi.subs({mech.gamma: sym.gamma[k], mech.rho: sym.rho[k]})
