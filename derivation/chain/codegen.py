"""Emit the numba module of a chain scene through a Jinja2 template (templates/chain_module.py.j2).

Every formula comes from derivation/chain/: each stage's equivalent wedge (stages.py) and each
sliding mode's reduced equation of motion, normal forces, denominator and stage forces
(dynamics.py); the scene's values enter only as named module constants printed by ``inert``. The
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
GENERATOR_SOURCES = ("chain/codegen.py", "chain/dynamics.py", "chain/stages.py", "chain/scene.py",
                     "chain/valve.py", "templates/chain_module.py.j2")


def generator_digest() -> str:
    """sha256 over the chain generator's sources."""
    h = hashlib.sha256()
    root = resources.files("derivation")
    for name in GENERATOR_SOURCES:
        h.update(name.encode() + root.joinpath(*name.split("/")).read_bytes())
    return h.hexdigest()


class _Code:
    """Python source of expressions in the chain's symbols: one CSE per function, the body forces
    from ``body_forces`` where an expression uses them."""

    def __init__(self, stages: int):
        self.sym = dyn.symbols(stages)
        self.printer = _Printer()

    def body(self, exprs: list[sp.Expr], direction: str = "0.0") -> tuple[list[str], list[str]]:
        """Lines and results; the body forces of a sliding mode in ``direction`` (a number or the argument's
        name)."""
        exprs = [sp.sympify(e) for e in exprs]
        used = set().union(*(e.free_symbols for e in exprs))
        lines = []
        if used & set(self.sym.force):
            lines.append(f"{', '.join(map(str, self.sym.force))} = body_forces(t, y, p, {direction})")
        if q0 in used:
            lines.append("q_0 = y[0]")
        if MOTOR in used:
            lines.append("motor = motor_torque(y[1], p)")
        if vl.POWERED in used:
            lines.append("powered = motor_on(p)")
        if vl.SEATED in used:
            lines.append("seated = p[P_SEATED]")
        replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("c"))
        lines += [f"{s} = {self.printer.doprint(e)}" for s, e in replacements]
        return lines, [self.printer.doprint(e) for e in reduced]

    def function(self, name: str, doc: str, exprs: list[sp.Expr], args: str = "t, y, p",
                 direction: str = "0.0") -> dict:
        lines, results = self.body(exprs, direction)
        return {"name": name, "args": args, "doc": doc, "lines": lines, "result": ", ".join(results)}


def _constants(chain: ChainScene, code: _Code) -> tuple[list[tuple[str, str, str]], list[tuple[str, str]]]:
    """(name, value, scene key) of the scene's values and (name, formula) of the chain's symbols from them."""
    given, derived = [], []
    sym = code.sym
    for k, stage in enumerate(chain.stages):
        kind, wedge = st.kinds()[stage.kind], st.equivalent_wedge(stage.kind)
        names = {symbol: sp.Symbol(stage.params[key].name, real=True) for key, symbol in kind.keys.items()}
        given += [(p.name, inert(p.value, p.name), p.key) for p in stage.params.values()]
        for target, expr in ((sym.gamma[k], sp.atan(wedge.tan_gamma)), (sym.rho[k], sp.atan(wedge.tan_rho)),
                             (sym.lever_in[k], wedge.lever_in), (sym.lever_out[k], wedge.lever_out)):
            derived.append((str(target), code.printer.doprint(sp.sympify(expr).subs(names))))
    valve = chain.bodies[-1].valve
    for j, body in enumerate(chain.bodies):
        for param in (body.inertia, body.force, body.stiffness, *(vars(body.valve).values() if body.valve else ())):
            if param is not None:
                given.append((param.name, inert(param.value, param.name), param.key))
        derived.append((str(sym.inertia[j]), body.inertia.name))
    if chain.switch is not None:
        given += [(p.name, inert(p.value, p.name), p.key) for p in (chain.switch.setting, chain.switch.hysteresis,
                                                                    chain.switch.delay)]
    derived.append(("LOAD_FRICTION", code.printer.doprint(vl.coulomb(valve)) if valve else "0.0"))
    return given, derived


def _forces(chain: ChainScene, code: _Code, direction: sp.Expr) -> list[sp.Expr]:
    """The generalized force on each body: its force or torque, the motor's while powered, less a spring's
    stiffness times its coordinate q_j = (v_j / v_0) q_0 (q = 0 at the start), and the valve's force on the
    last body moving in ``direction``."""
    factors = dyn.speed_factors(code.sym)
    return [sp.Symbol(b.force.name, real=True) + (vl.drive(MOTOR) if b.motor is not None else 0)
            - (sp.Symbol(b.stiffness.name, real=True) * factors[j] * q0 if b.stiffness is not None and b.stiffness.value
               else 0) + (vl.valve_force(b.valve, factors[j] * q0, direction) if b.valve is not None else 0)
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


def _mode_calls(chain: ChainScene, code: _Code, modes: list[dyn.SlidingMode]) -> tuple[list[dict], list[dict]]:
    """The per-mode functions, one set per group of mirror modes (the first mode of a group gives its
    expressions; the body forces in the direction the caller passes), and per mode the call: the group's
    functions, its direction and which results change sign."""
    functions, calls, groups = [], [], []     # groups: (first index, its expressions)
    for index, mode in enumerate(modes):
        exprs = _mode_exprs(chain, code, mode)
        found = next(((first, signs) for first, base in groups
                      if (signs := _signs(exprs, base)) is not None), None)
        if found is None:
            groups.append((index, exprs))
            found = (index, {name: (1,) * len(e) for name, e in exprs.items()})
            functions += _group_functions(code, index, modes, exprs)
        first, signs = found
        calls.append({"group": first, "direction": f"{mode.direction:.1f}", "accel_sign": "-" if signs["accel"][0] < 0
                      else "", "contact_flips": [k for k, sg in enumerate(signs["contact"]) if sg < 0],
                      "force_flips": [k for k, sg in enumerate(signs["stage_forces"]) if sg < 0]})
    for group, _ in groups:
        members = [f"{i} ({modes[i].name})" for i, call in enumerate(calls) if call["group"] == group]
        for f in functions:
            if f["group"] == group:
                f["doc"] += "; modes " + ", ".join(members) + " (their body forces in `direction`)"
    return functions, calls


def _group_functions(code: _Code, index: int, modes: list[dyn.SlidingMode], exprs: dict) -> list[dict]:
    args = "t, y, p, direction"
    docs = {"accel": "a_0",
            "contact": "(D, jam, N_1, ..., N_N, measured): the denominator, the stages' jam factors' product and each "
                       "stage's normal force; the mode holds while each is >= 0 (D, jam > 0); what the torque switch "
                       "measures",
            "stage_forces": "per stage (on its input body, on its output body, normal force)"}
    return [{**code.function(f"{name}_{index}", f"{docs[name]} in mode {index}: {modes[index].name}", e, args=args,
                             direction="direction"), "group": index} for name, e in exprs.items()]


def _jacobian(code: _Code, chain: ChainScene, mode: dyn.SlidingMode) -> tuple[str, str]:
    """(d a_0 / d q_0, d a_0 / d v_0) in a mode: the springs' and the motor's share (the forces are the only
    state dependence; the motor's torque changes with v_0 by its table's slope, ``motor_slope``)."""
    accel = mode.accel.subs(dict(zip(code.sym.force, _forces(chain, code, mode.direction))))
    return code.printer.doprint(sp.diff(accel, q0)), code.printer.doprint(sp.diff(accel, MOTOR))


def _jacobians(code: _Code, chain: ChainScene, modes: list[dyn.SlidingMode]) -> list[tuple[list[int], str, str]]:
    """(the modes, d a_0 / d q_0, d a_0 / d v_0) for each distinct pair of the modes' Jacobian entries (a mode
    and its mirror image have the same), in the order of their first mode."""
    found: dict[tuple[str, str], list[int]] = {}
    for index, mode in enumerate(modes):
        found.setdefault(_jacobian(code, chain, mode), []).append(index)
    return [(indices, by_q, by_motor) for (by_q, by_motor), indices in found.items()]


def generate_chain_module(chain: ChainScene) -> str:
    """Source of the chain scene's module."""
    values = chain.values()
    n = len(chain.stages)
    code = _Code(n)
    reachable = dyn.reachable(values.flanks)
    modes = [dyn.sliding(direction, regimes) for direction, regimes in reachable]
    given, derived = _constants(chain, code)
    psi = [tuple(code.printer.doprint(p) for p in _psi(code.sym, k)) for k in range(n)]
    functions = [code.function("body_forces", "(F_0, ..., F_N): each body's force or torque (the motor's while "
                               "powered), a spring's part -stiffness q_j with q_j = (v_j/v_0) q_0, the valve's force "
                               "on the last body moving in `direction` (0: at rest, without its friction)",
                               _forces(chain, code, DIRECTION), args="t, y, p, direction")]
    shared, calls = _mode_calls(chain, code, modes)
    functions += shared
    guards = ("D", "jam", *(f"N_{k + 1}" for k in range(n)), "v0", *SWITCHED_GUARDS)
    directions = [tuple([-1] * (n + 2) + [-mode.direction] + [-1] * len(SWITCHED_GUARDS)) for mode in modes]
    switch, valve = chain.switch, chain.bodies[-1].valve
    seat = valve.seat if valve is not None else None
    constants = {
        "SCENE": chain.name, "DESCRIPTION": chain.description, "SCENE_DIGEST": chain.digest, "STAGES": n,
        "STATES": STATES, "MODES": tuple(m.name for m in modes), "MODE_DIRECTION": tuple(m.direction for m in modes),
        "MODE_REGIMES": tuple(m.regimes for m in modes), "MODE_FLANKS": tuple(m.flanks for m in modes),
        "STAGE_KINDS": tuple(s.kind for s in chain.stages),
        "BODY_MOTIONS": tuple(b.motion for b in chain.bodies), "GUARDS": guards,
        "GUARD_DIRECTIONS": tuple(directions), "OBSERVABLES": (), "RUN": dict(vars(chain.run)),
        "P_NAMES": vl.P_NAMES, "P_SWITCH": vl.P_SWITCH, "P_PICK": vl.P_PICK, "P_SEATED": vl.P_SEATED,
        "P_VOLTAGE": vl.P_VOLTAGE,
        "ARMED": vl.ARMED, "PICKED": vl.PICKED, "TRIPPED": vl.TRIPPED,
        "SWITCH_ON": -1 if switch is None else switch.stage, "HAS_SEAT": seat is not None,
    }
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(resources.files("derivation") / "templates")),
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["docstring"] = _docstring
    env.filters["comment"] = _comment
    body = env.get_template("chain_module.py.j2").render(
        chain=chain, n=n, modes=modes, calls=calls, constants={k: inert(v, k) for k, v in constants.items()}, given=given,
        derived=derived, psi=psi, functions=functions, jacobians=_jacobians(code, chain, modes),
        factors=[code.printer.doprint(f) for f in dyn.speed_factors(code.sym)],
        inertia=[str(s) for s in code.sym.inertia], motor=chain.bodies[0].motor,
        motor_arrays={name: inert(values, name) for name, values in (
            ("MOTOR_SPEED", chain.bodies[0].motor.speed), ("MOTOR_TORQUE", chain.bodies[0].motor.torque))}
        if chain.bodies[0].motor else {},
        motor_voltage=inert(chain.bodies[0].motor.voltage, "voltage") if chain.bodies[0].motor else "", lever_in=[str(s) for s in code.sym.lever_in],
        lever_out=[str(s) for s in code.sym.lever_out], guards=guards,
        contact_targets=", ".join(f"g[{k}]" for k in range(n + 2)),
        force_targets=", ".join(f"out[{k}]" for k in range(3 * n)),
        body_targets=", ".join(f"out[{j}]" for j in range(n + 1)),
        switch={"SWITCH_SETTING": switch.setting.name, "SWITCH_HYSTERESIS": switch.hysteresis.name,
                "SWITCH_DELAY": switch.delay.name} if switch else {"SWITCH_SETTING": "math.inf",
                                                                  "SWITCH_HYSTERESIS": "0.0", "SWITCH_DELAY": "0.0"},
        seat=seat.name if seat is not None else "math.nan")
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


def _psi(sym: dyn.Symbols, k: int) -> tuple[sp.Expr, sp.Expr]:
    """Stage k's FTFs of forward sliding, tractive (flank a) and inverse-tractive (flank b), from mechanics."""
    return tuple(mech.sliding(f, 1).psi.subs({mech.gamma: sym.gamma[k], mech.rho: sym.rho[k]}) for f in "ab")
