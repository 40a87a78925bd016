"""Chain scene files: ``[[stage]]`` and ``[[body]]`` tables, read, checked and turned into numbers.

Stage k (counted from 1) joins body k-1 and body k ([[body]] tables counted from 0). Messages name a
key as stage[k].mu or body[k].inertia. A translating body may carry a spring (``stiffness``); the
``[run]`` table gives the run (docs/scene-format.md, "Chains of stages").
"""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import sympy as sp

from derivation.chain import stages as st
from derivation.chain.dynamics import MAX_STAGES
from derivation.chain.selector import ChainValues
from derivation.scene import (CLEARANCE, DEG, FLANKS, IMPACT, MAX_DESCRIPTION, NAME, Param, Rule, SceneError, _Reader,
                              _toml, read_toml)
from derivation.scene import RUN as SCENE_RUN
from tswm_common import units
from tswm_common.text import printable

TOP_KEYS = ("name", "description", "stage", "body", "switch", "run")
ANGLE = Rule("angle", 0.0, 90 * DEG)
TILT = Rule("angle", 0.0, 90 * DEG, lo_in=True)      # 0: a flank square to the wedge plane
SIZE = Rule("length", 0.0)
MU = Rule("dimensionless", 0.0, 10.0, lo_in=True)
RULES = {"gamma": ANGLE, "lead_angle": ANGLE, "pressure_angle": TILT, "flank_angle": TILT,
         "worm_radius": SIZE, "wheel_radius": SIZE, "lead": SIZE, "mean_diameter": SIZE, "mu": MU}
BODY = {st.ROTATION: ("inertia", "torque"), st.TRANSLATION: ("mass", "force")}
SPRING = Rule("stiffness", 0.0, lo_in=True, default=0.0)    # translating bodies: F = force - stiffness q
MOTOR_POINTS = 100
VALVE = {"packing": Rule("force", 0.0, lo_in=True, default=0.0), "dp": Rule("pressure", 0.0, lo_in=True, default=0.0),
         "area": Rule("area", 0.0, lo_in=True, default=0.0),
         "valve_factor": Rule("dimensionless", 0.0, 10.0, lo_in=True, hi_in=True, default=1.0),
         "packing_dp": Rule("area", 0.0, lo_in=True, default=0.0)}     # packing friction per dp: N/Pa = m^2
SEAT = {"seat": Rule("length"), "seat_stiffness": Rule("stiffness", 0.0)}
SWITCH_TIMES = {"delay": Rule("time", 0.0, lo_in=True, default=0.0)}
VOLTAGE = Rule("dimensionless", 0.0, 2.0, hi_in=True, default=1.0)   # U / U_n
GAP = Rule("length", 0.0, "clearance", lo_in=True, hi_in=True, default=0.0)   # run.gap_k in [0, stage[k].clearance]
STAGE_CLEARANCE = {"clearance": CLEARANCE, **IMPACT}
RUN = {"t_end": SCENE_RUN["t_end"], "v0": Rule("dimensionless", -1e12, 1e12, lo_in=True, hi_in=True, default=0.0),
       "rtol": SCENE_RUN["rtol"], "atol": SCENE_RUN["atol"], "max_steps": SCENE_RUN["max_steps"]}


@dataclass(frozen=True)
class Stage:
    """One stage as written: its kind, its parameters (in SI) and its modelled flanks."""
    kind: str
    params: dict[str, Param]
    flanks: tuple[str, ...]


@dataclass(frozen=True)
class Body:
    """One body: rotating (inertia in kg m^2, torque in N m) or translating (mass in kg, force in N,
    a spring's stiffness in N/m: the force falls by stiffness q from q = 0 at the start)."""
    motion: str
    inertia: Param
    force: Param
    stiffness: Param | None = None
    motor: Motor | None = None
    valve: Valve | None = None


@dataclass(frozen=True)
class Valve:
    """The valve side of the last (translating) body: a Coulomb friction of constant magnitude
    packing + packing_dp dp + valve_factor dp area against its motion (the packing's part grows with the
    differential pressure by packing_dp, in N/Pa = m^2), and a seat at travel ``seat`` (a spring of
    ``seat_stiffness`` beyond it; None: no seat)."""
    packing: Param
    dp: Param
    area: Param
    valve_factor: Param
    packing_dp: Param
    seat: Param | None
    seat_stiffness: Param | None


@dataclass(frozen=True)
class Switch:
    """A torque switch: on body 0's drive torque (stage 0) or on stage k's force on its output body,
    picking up at ``setting``, dropping out below setting - hysteresis, cutting the motor ``delay``
    after it picked up (unless it dropped out before)."""
    stage: int
    setting: Param
    hysteresis: Param
    delay: Param
    quantity: str = "torque"      # of setting and hysteresis: "torque" or "force"


@dataclass(frozen=True)
class Motor:
    """A motor on body 0: its torque (or force) over its speed as a datasheet table in SI, linear between
    the points and the end values beyond them, scaled by voltage^2 (voltage = U / U_n)."""
    speed: tuple[float, ...]
    torque: tuple[float, ...]
    voltage: float


@dataclass(frozen=True)
class Clearance:
    """Stage ``stage``'s clearance along its flanks' normal (backlash), its restitution e and the normal gap from
    flank a at the start (run.gap_k, in [0, clearance])."""
    stage: int
    clearance: Param
    restitution: Param
    gap: Param


@dataclass(frozen=True)
class ChainRun:
    """The run: t_end [s], body 0's speed at t = 0 (rad/s rotating, m/s translating; q = 0 there),
    tolerances and the step budget."""
    t_end: float
    v0: float
    rtol: float
    atol: float
    max_steps: int


@dataclass(frozen=True)
class ChainScene:
    name: str
    description: str
    stages: tuple[Stage, ...]
    bodies: tuple[Body, ...]
    source: str
    digest: str
    run: ChainRun = ChainRun(1.0, 0.0, 1e-6, 1e-9, 100000)
    switch: Switch | None = None
    clearances: tuple[Clearance, ...] = ()   # per stage with a clearance, in stage order

    def values(self) -> ChainValues:
        """The equivalent wedges' numbers (slope, friction angle, levers) and the bodies', in SI."""
        wedges = [_equivalent(stage) for stage in self.stages]
        return ChainValues(*(tuple(w[k] for w in wedges) for k in range(4)),
                           tuple(b.inertia.value for b in self.bodies), tuple(b.force.value for b in self.bodies),
                           tuple(s.flanks for s in self.stages))

    def value_rules(self) -> list[tuple[Param, Rule]]:
        """Every value of the chain (stages, bodies, valve, switch; the motor's table and voltage aside) with
        the rule the scene reader checked it by, in the order the generated module keeps them in p."""
        out = [(p, RULES[key]) for stage in self.stages for key, p in stage.params.items()]
        for body in self.bodies:
            rules = body_rules(body.motion)
            out += [(p, rules[key]) for key, p in zip(BODY[body.motion], (body.inertia, body.force))]
            if body.stiffness is not None:
                out.append((body.stiffness, SPRING))
            if body.valve is not None:
                out += [(p, {**VALVE, **SEAT}[key]) for key, p in vars(body.valve).items() if p is not None]
        if self.switch is not None:
            rules = switch_rules(self.switch.quantity)
            out += [(getattr(self.switch, key), rule) for key, rule in rules.items()]
        for c in self.clearances:
            out += [(c.clearance, CLEARANCE), (c.restitution, IMPACT["restitution"]), (c.gap, GAP)]
        return out


def _equivalent(stage: Stage) -> tuple[float, float, float, float]:
    """(gamma, rho, lever_in, lever_out) of a stage from stages.equivalent_wedge."""
    wedge = st.equivalent_wedge(stage.kind)
    at = {symbol: stage.params[key].value for key, symbol in st.kinds()[stage.kind].keys.items()}
    number = lambda expr: float(sp.sympify(expr).subs(at))   # noqa: E731
    return (math.atan(number(wedge.tan_gamma)), math.atan(number(wedge.tan_rho)),
            number(wedge.lever_in), number(wedge.lever_out))


def body_rules(motion: str) -> dict[str, Rule]:
    """A body's inertia (or mass) and torque (or force) rules; a translating body's spring's."""
    inertia_key, force_key = BODY[motion]
    quantity = "mass" if motion == st.TRANSLATION else "inertia"
    return {inertia_key: Rule(quantity, 0.0), force_key: Rule(force_key if force_key == "torque" else "force",
                                                              default=0.0),
            **({"stiffness": SPRING} if motion == st.TRANSLATION else {})}


def switch_rules(quantity: str) -> dict[str, Rule]:
    """The torque switch's setting, hysteresis (at most the setting) and delay."""
    return {"setting": Rule(quantity, 0.0), "hysteresis": Rule(quantity, 0.0, "setting", lo_in=True, default=0.0),
            **SWITCH_TIMES}


def _suffixed(params: dict[str, Param], index: int) -> dict[str, Param]:
    """Params named key_index (mu_1, force_2): the names of p's slots in the generated module."""
    return {key: replace(p, name=f"{key}_{index}") for key, p in params.items()}


SCENES = Path(__file__).resolve().parent / "scenes"


def shipped_chains() -> tuple[str, ...]:
    """Names of the chain scenes shipped in derivation/chain/scenes/."""
    return tuple(sorted(f.name.removesuffix(".toml") for f in SCENES.iterdir() if f.name.endswith(".toml")))


def load_chain(path: str | os.PathLike) -> ChainScene:
    """Read a chain scene file, or a shipped chain scene by name ("mov")."""
    if isinstance(path, str) and path in shipped_chains():
        path = SCENES / f"{path}.toml"
    source = os.fspath(path)
    try:
        data = Path(source).read_bytes()
    except OSError as err:
        raise SceneError(f"{printable(source)}: cannot read scene file ({err.strerror})") from err
    return _ChainReader(source).chain(read_toml(data, source), hashlib.sha256(data).hexdigest())


def parse_chain(text: str, source: str = "<string>") -> ChainScene:
    """Parse chain scene text; source names it in messages."""
    data = text.encode("utf-8")
    return _ChainReader(source).chain(read_toml(data, source), hashlib.sha256(data).hexdigest())


class _ChainReader(_Reader):
    """The scene reader's checks (units, ranges, unknown keys), applied to [[stage]] and [[body]]."""

    def tables(self, doc: dict, key: str, lo: int, hi: int) -> list[dict]:
        """The list of [[key]] tables, lo to hi of them."""
        expected = f"expected {lo} to {hi} [[{key}]] tables"
        raw = doc.get(key)
        if raw is None:
            self.fail(key, f"missing: {expected}")
        if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
            self.fail(key, expected, _toml(raw)[:80])
        if not lo <= len(raw) <= hi:
            self.fail(key, f"{expected} ({len(raw)} given)")
        return raw

    def stage(self, table: dict, k: int) -> Stage:
        path = f"stage[{k}]"
        kind = self.text(table, "kind", path, tuple(st.kinds()))
        keys = tuple(st.kinds()[kind].keys)
        self.keys(table, path, ("kind", "flanks", *keys, *STAGE_CLEARANCE))
        params = _suffixed(self.params(table, path, {key: RULES[key] for key in keys}), k)
        for param in params.values():
            if param.free:
                self.fail(param.key, "free parameters of a chain are not supported yet: give a plain value")
        flanks = self.subset(table, "flanks", path, FLANKS, default=list(FLANKS))
        stage = Stage(kind, params, flanks)
        gamma, rho, _, _ = _equivalent(stage)
        if gamma + rho >= 90 * DEG:
            self.fail(f"{path}.mu", f"slope {units.show(gamma, 'angle')} + effective friction angle "
                      f"{units.show(rho, 'angle')} (mu over the cosine of the flank's tilt) must be < 90 deg (else the "
                      "stage jams)", f"{params['mu'].value:g}")
        return stage

    def body(self, table: dict, j: int, motion: str, last: bool) -> Body:
        path = f"body[{j}]"
        inertia_key, force_key = BODY[motion]
        other = BODY[st.TRANSLATION if motion == st.ROTATION else st.ROTATION]
        for key in other:
            if key in table:
                self.fail(f"{path}.{key}", f"body {j} {'rotates' if motion == st.ROTATION else 'translates'} "
                          f"(set by the stages it joins): give {inertia_key} and {force_key}")
        spring = ("stiffness",) if motion == st.TRANSLATION else ()
        valve = (*VALVE, *SEAT) if last and motion == st.TRANSLATION else ()
        self.keys(table, path, (inertia_key, force_key, *spring, *(("motor",) if j == 0 else ()), *valve))
        params = _suffixed(self.params(table, path, body_rules(motion)), j)
        for param in params.values():
            if param.free:
                self.fail(param.key, "free parameters of a chain are not supported yet: give a plain value")
        motor = self.motor(table["motor"], f"{path}.motor") if "motor" in table else None
        valve = self.valve(table, path, j) if last and motion == st.TRANSLATION else None
        return Body(motion, params[inertia_key], params[force_key], params.get("stiffness"), motor, valve)

    def valve(self, table: dict, path: str, j: int) -> Valve | None:
        """Packing, differential pressure and seat keys of the last body j (None when none is given)."""
        if not any(key in table for key in (*VALVE, *SEAT)):
            return None
        params = _suffixed(self.plain(table, path, VALVE), j)
        seat = _suffixed(self.plain(table, path, SEAT), j) if "seat" in table or "seat_stiffness" in table else {}
        return Valve(*params.values(), seat.get("seat"), seat.get("seat_stiffness"))

    def plain(self, table: dict, path: str, rules: dict[str, Rule], prefix: str = "") -> dict[str, Param]:
        """Params of plain values (a chain has no free parameters yet)."""
        params = self.params(table, path, rules, prefix)
        for param in params.values():
            if param.free:
                self.fail(param.key, "free parameters of a chain are not supported yet: give a plain value")
        return params

    def switch(self, doc: dict, stages: tuple[Stage, ...], motions: list[str]) -> Switch | None:
        """[switch]: on = "motor" (body 0's drive torque) or "stage K" (stage K's force on body K)."""
        table = self.table(doc, "switch", required=False)
        if table is None:
            return None
        self.keys(table, "switch", ("on", "setting", "hysteresis", "delay"))
        choices = ("motor", *(f"stage {k}" for k in range(1, len(stages) + 1)))
        on = self.text(table, "on", "switch", choices)
        stage = 0 if on == "motor" else int(on.split()[1])
        quantity = "torque" if motions[stage] == st.ROTATION else "force"
        params = self.plain(table, "switch", switch_rules(quantity), "switch_")
        return Switch(stage, params["setting"], params["hysteresis"], params["delay"], quantity)

    def motor(self, table: object, path: str) -> Motor:
        """speed (SI, increasing from >= 0), torque (SI) of 2 to MOTOR_POINTS points; voltage = U / U_n."""
        if not isinstance(table, dict):
            self.fail(path, "expected a table {speed = [...], torque = [...], voltage = ...}", _toml(table)[:80])
        self.keys(table, path, ("speed", "torque", "voltage"))
        speed, torque = (self.array(table, key, path, 2, MOTOR_POINTS) for key in ("speed", "torque"))
        numbers = []
        for key, values in (("speed", speed), ("torque", torque)):
            for i, v in enumerate(values):
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > 1e12:
                    self.fail(f"{path}.{key}[{i}]", "expected a finite plain number in SI, |x| <= 1e12", _toml(v))
            numbers.append(tuple(float(v) for v in values))
        if len(speed) != len(torque):
            self.fail(f"{path}.torque", f"needs one value per speed ({len(speed)}), has {len(torque)}")
        if numbers[0][0] < 0 or any(b <= a for a, b in zip(numbers[0], numbers[0][1:])):
            self.fail(f"{path}.speed", "must increase strictly from a value >= 0", _toml(speed)[:200])
        voltage = self.number(table, "voltage", path, VOLTAGE, free_ok=False)[0]
        return Motor(*numbers, voltage)

    def clearances(self, stages: list[dict], run: dict,
                   bodies: tuple[Body, ...]) -> tuple[tuple[Clearance, ...], tuple[Body, ...]]:
        """stage[k].clearance (> 0) with stage[k].restitution (e in [0, 1]) and the start gap run.gap_k in
        [0, clearance], in any number of stages; at most one starts open (0 < gap_k < clearance: one open stage at a
        time is modelled), and no body between two stages with a clearance has a spring (its coordinate would follow
        both stages' backlash): such a translating body's stiffness must be 0 and it has no spring slot. Returns the
        clearances and the bodies."""
        out, opened = [], None
        for k, table in enumerate(stages, 1):
            path, gap = f"stage[{k}]", f"gap_{k}"
            if "clearance" not in table:
                for key, where in (("restitution", path), (gap, "run")):
                    if key in (table if where == path else run):
                        self.fail(f"{where}.{key}", f"needs a clearance in stage {k}: give stage[{k}].clearance")
                continue
            given = self.plain(table, path, STAGE_CLEARANCE)
            start = self.number(run, gap, "run", GAP, free_ok=False, siblings=given)[0]
            if given["clearance"].value == 0.0:
                self.fail(f"{path}.clearance", "must be > 0 in a chain (0: give the stage no clearance)",
                          _toml(table["clearance"]))
            if 0.0 < start < given["clearance"].value:
                if opened is not None:
                    self.fail(f"run.{gap}", f"stage {opened} starts open already (run.gap_{opened}): one open stage "
                              f"at a time is modelled, start stage {k} on a flank (0 or its clearance)", _toml(run[gap]))
                opened = k
            own = _suffixed(given, k)
            out.append(Clearance(k, own["clearance"], own["restitution"], Param(gap, start, "m", False, f"run.{gap}")))
        between = [j for j, body in enumerate(bodies) if body.stiffness is not None
                   and any(c.stage <= j for c in out) and any(c.stage > j for c in out)]
        for j in between:
            if bodies[j].stiffness.value != 0.0:
                self.fail(bodies[j].stiffness.key, f"body {j} lies between two stages with a clearance: a spring there "
                          "is not supported (give it to a body before the first or after the last such stage)")
        return tuple(out), tuple(replace(b, stiffness=None) if j in between else b for j, b in enumerate(bodies))

    def chain_run(self, doc: dict, stages: int) -> ChainRun:
        table = self.table(doc, "run", required=False) or {}
        self.keys(table, "run", (*RUN, *(f"gap_{k}" for k in range(1, stages + 1))))
        value = {k: self.number(table, k, "run", rule, free_ok=False)[0] for k, rule in RUN.items()}
        return ChainRun(**{**value, "max_steps": int(value["max_steps"])})

    def chain(self, doc: dict, digest: str) -> ChainScene:
        self.keys(doc, "", TOP_KEYS)
        name = self.text(doc, "name", "", pattern=NAME)
        description = self.text(doc, "description", "", default="")
        if len(description) > MAX_DESCRIPTION:
            self.fail("description", f"{len(description)} characters: must be at most {MAX_DESCRIPTION}")
        stage_tables = self.tables(doc, "stage", 1, MAX_STAGES)
        stages = tuple(self.stage(t, k) for k, t in enumerate(stage_tables, 1))
        kinds = [st.kinds()[s.kind] for s in stages]
        for k in range(1, len(stages)):
            if kinds[k - 1].motion_out != kinds[k].motion_in:
                self.fail(f"stage[{k + 1}].kind", f"takes a body in {kinds[k].motion_in}, but stage[{k}] "
                          f"({stages[k - 1].kind}) drives body {k} in {kinds[k - 1].motion_out}",
                          _toml(stages[k].kind))
        tables = self.tables(doc, "body", len(stages) + 1, len(stages) + 1)
        motions = [kinds[0].motion_in, *(kind.motion_out for kind in kinds)]
        bodies = tuple(self.body(t, j, m, j == len(stages)) for j, (t, m) in enumerate(zip(tables, motions)))
        run = self.chain_run(doc, len(stages))
        clearances, bodies = self.clearances(stage_tables, self.table(doc, "run", required=False) or {}, bodies)
        return ChainScene(name, description, stages, bodies, self.source, digest, run,
                          self.switch(doc, stages, motions), clearances)
