"""Scene files (docs/scene-format.md): a wedge variant and its run, read from TOML, checked, in SI."""

from __future__ import annotations

import difflib
import hashlib
import importlib.resources
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

from tswm_common import units
from tswm_common.text import printable

DEG = math.pi / 180
FLANKS = ("a", "b")
MODES = ("forward", "backward", "stick", "sliding")
LITERAL_MODES = (("forward",), ("forward", "sliding"))
EQUATIONS = ("consistent", "literal")
METHODS = ("dopri5", "rosenbrock23", "rodas4", "auto")
TOP_KEYS = ("name", "description", "equations", "wedge", "friction", "drive", "load",
            "impact", "mesh", "lost_motion", "reference", "modes", "run")
NAME = re.compile(r"[a-z0-9][a-z0-9-]{0,63}")     # a file name on every system: at most 64 characters
MAX_DESCRIPTION = 2000                            # characters
MAX_SCENE_BYTES = 1_000_000                       # a scene file is a page of TOML; refuse anything near this
_SCENES = importlib.resources.files("derivation") / "scenes"


class SceneError(ValueError):
    """A scene that cannot be used; the message names file, dotted key, value and allowed range."""


class ChainSceneGiven(SceneError):
    """A chain scene ([[stage]] tables) given to the one-stage reader: derivation.chain.scene reads it."""


@dataclass(frozen=True)
class Param:
    """One model parameter, in SI; free ones are read from a parameter vector at run time."""
    name: str
    value: float
    unit: str
    free: bool
    key: str


@dataclass(frozen=True)
class Law:
    """A drive, load or friction law and its parameters, keyed by the law's own key names.

    A schedule (``kind == "schedule"``) has no keyed parameters but ``breakpoints`` and
    ``values``, and ``options`` {"variable": "t" | "x2", "shape": "steps" | "linear"}.
    """
    kind: str
    params: dict[str, Param]
    options: dict[str, str] = field(default_factory=dict)
    breakpoints: tuple[Param, ...] = ()
    values: tuple[Param, ...] = ()

    def all_params(self) -> tuple[Param, ...]:
        return (*self.params.values(), *self.breakpoints, *self.values)


@dataclass(frozen=True)
class Run:
    """Integration settings, in SI."""
    t_end: float
    x1: float
    v1: float
    gap: float                   # normal gap from flank a at t = 0 (scenes with clearance)
    rtol: float
    atol: float
    method: str
    max_steps: int


@dataclass(frozen=True)
class Scene:
    """A validated scene; shared slopes and friction laws are the same objects on both flanks."""
    name: str
    description: str
    equations: str
    flanks: tuple[str, ...]
    gamma: dict[str, Param]
    m1: Param
    m2: Param
    friction: dict[str, Law]
    drive: Law
    load: Law
    reference: dict[str, Param]
    modes: tuple[str, ...]
    run: Run
    source: str
    digest: str
    torque_switch: Param | None = None   # trip threshold S1_trip on S1 ([drive.torque_switch])
    checks: tuple[tuple, ...] = ()       # the rules of every model parameter, as data (see Checks)
    clearance: Param | None = None       # normal clearance between the flanks (backlash), None: zero
    restitution: Param | None = None     # coefficient of restitution of a flank impact ([impact])
    mesh: dict[str, Param] | None = None # compliant flanks: stiffness, damping ([mesh]), None: rigid
    lost_motion: dict[str, Param] | None = None  # travel, stem_mass, restitution ([lost_motion]), None: none
    written: dict[str, tuple[float, str]] = field(default_factory=dict)  # key -> (number, unit) as written,
                                                                         # for values not written in SI

    def params(self) -> tuple[Param, ...]:
        """Every distinct model parameter once: wedge, friction, drive, torque switch, load, reference."""
        return tuple(dict.fromkeys((
            *self.gamma.values(), self.m1, self.m2,
            *(p for law in self.friction.values() for p in law.all_params()),
            *self.drive.all_params(), *([self.torque_switch] if self.torque_switch else []),
            *self.load.all_params(), *self.reference.values(),
            *(p for p in (self.clearance, self.restitution) if p is not None), *(self.mesh or {}).values(),
            *(self.lost_motion or {}).values(),
        )))

    def free_params(self) -> tuple[Param, ...]:
        """The free parameters, in params() order."""
        return tuple(p for p in self.params() if p.free)


@dataclass(frozen=True)
class Rule:
    """How one numeric key is read: quantity, allowed range in SI, default (None: required)."""
    quantity: str
    lo: float | None = None
    hi: float | str | None = None  # a number, or a key of the same table that bounds it
    lo_in: bool = False
    hi_in: bool = False
    default: float | None = None
    integer: bool = False


GAMMA = Rule("angle", 0.0, 90 * DEG)
WEDGE = {"m1": Rule("mass", 0.0), "m2": Rule("mass", 0.0)}
CLEARANCE = Rule("length", 0.0, lo_in=True)      # >= 0 (0: the flanks part and meet at once); absent: rigid
IMPACT = {"restitution": Rule("dimensionless", 0.0, 1.0, lo_in=True, hi_in=True)}
MESH = {"stiffness": Rule("stiffness", 0.0), "damping": Rule("damping", 0.0, lo_in=True, default=0.0)}
LOST_MOTION = {"travel": Rule("length", 0.0, lo_in=True), "stem_mass": Rule("mass", 0.0),
               "restitution": Rule("dimensionless", 0.0, 1.0, lo_in=True, hi_in=True)}
FRICTION_LAWS = {
    "constant": {"rho": Rule("angle", 0.0, 90 * DEG, lo_in=True)},
    "velocity": {"a": Rule("dimensionless", 0.0, lo_in=True),
                 "b": Rule("dimensionless", 0.0), "c": Rule("dimensionless", 0.0)},
}
SCHEDULE = {}  # "schedule" laws have the keys variable, shape, at, values (_Reader.schedule)
SCHEDULE_VARIABLES = {"t": "time", "x2": "length"}
SCHEDULE_SHAPES = ("steps", "linear")
MAX_BREAKPOINTS = 1000
DRIVE_LAWS = {
    "kloss": {"Fmax": Rule("force", 0.0), "V0": Rule("velocity", 0.0),
              "Vmax": Rule("velocity", 0.0, "V0")},
    "constant": {"F1": Rule("force")},
    "linear": {"F0": Rule("force"), "V0": Rule("velocity", 0.0)},
    "schedule": SCHEDULE,
}
LOAD_LAWS = {
    "constant": {"F2": Rule("force")},
    "step": {"F2_before": Rule("force", default=0.0), "F2_after": Rule("force"),
             "t_step": Rule("time", 0.0, lo_in=True)},
    "spring": {"k": Rule("stiffness", 0.0), "x2_contact": Rule("length"),
               "preload": Rule("force", 0.0, lo_in=True)},
    "schedule": SCHEDULE,
}
TORQUE_SWITCH = Rule("force", 0.0)
REFERENCE = {"Ft1": Rule("force", 0.0), "Ft2": Rule("force", 0.0)}
RUN = {
    "t_end": Rule("time", 0.0, default=1.0),
    "x1": Rule("length", default=0.0),
    "v1": Rule("velocity", default=0.0),
    "gap": Rule("length", 0.0, lo_in=True, default=0.0),
    "rtol": Rule("dimensionless", 1e-13, 1e-2, lo_in=True, hi_in=True, default=1e-6),   # = simulate.RTOL_RANGE
    "atol": Rule("dimensionless", 1e-20, 1.0, lo_in=True, hi_in=True, default=1e-9),   # = simulate.ATOL_RANGE
    "max_steps": Rule("dimensionless", 1, 1e9, lo_in=True, hi_in=True, default=100000, integer=True),  # MAX_STEPS
}
# Largest friction angle of a law (at v = 0) and the key that sets it, for the jam check.
MAX_RHO = {
    "constant": ("rho", "friction angle rho", lambda p: p["rho"].value),
    "velocity": ("c", "rho(0) = 1/c deg", lambda p: DEG / p["c"].value),
}


def max_friction_angle(kind: str, value: float) -> float:
    """The largest friction angle [rad] of a law from its MAX_RHO key's value (jam check)."""
    return value if kind == "constant" else DEG / value


def shipped_scenes() -> tuple[str, ...]:
    """Names of the scenes shipped in derivation/scenes/."""
    return tuple(sorted(f.name.removesuffix(".toml") for f in _SCENES.iterdir()
                        if f.name.endswith(".toml")))


def load_scene(name_or_path: str | os.PathLike) -> Scene:
    """Load a shipped scene by name ("paper") or a scene file by path."""
    if isinstance(name_or_path, str) and name_or_path in shipped_scenes():
        return _parse((_SCENES / f"{name_or_path}.toml").read_bytes(), f"shipped:{name_or_path}")
    source = os.fspath(name_or_path)
    try:
        data = Path(source).read_bytes()
    except OSError as err:
        raise SceneError(f"{printable(source)}: cannot read scene file ({err.strerror}); "
                         f"shipped scenes: {', '.join(shipped_scenes())}") from err
    return _parse(data, source)


def parse_scene(text: str, source: str = "<string>") -> Scene:
    """Parse scene text; source names it in messages."""
    return _parse(text.encode("utf-8"), source)


def read_toml(data: bytes, source: str) -> dict:
    """A scene file's TOML document, refusing oversized, undecodable or too deeply nested files."""
    if len(data) > MAX_SCENE_BYTES:
        raise SceneError(f"{printable(source)}: {len(data)} bytes: a scene file must be at most {MAX_SCENE_BYTES} bytes")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise SceneError(f"{printable(source)}: not a valid UTF-8 TOML file: {printable(err)}") from err
    except RecursionError:
        raise SceneError(f"{printable(source)}: not a usable TOML file: its arrays or tables are nested too deeply "
                         "(a scene nests tables two levels deep)") from None


def _parse(data: bytes, source: str) -> Scene:
    doc = read_toml(data, source)
    try:
        return _Reader(source).scene(doc, hashlib.sha256(data).hexdigest())
    except RecursionError:   # writing a deeply nested value back for a message
        raise SceneError(f"{printable(source)}: a value is nested too deeply to be a scene value") from None


def _join(path: str, key: str) -> str:
    """Dotted key of key inside path ("" is the top level)."""
    return f"{path}.{key}" if path else key


def _toml(raw: object) -> str:
    """A raw TOML value written back as TOML, for messages."""
    if isinstance(raw, bool):
        return str(raw).lower()
    if isinstance(raw, str):
        return f'"{printable(raw)}"' if len(raw) <= 80 else f'"{printable(raw[:60])}..." ({len(raw)} characters)'
    if isinstance(raw, float):
        return f"{raw:g}"
    if isinstance(raw, list):
        return f"[{', '.join(map(_toml, raw))}]"
    if isinstance(raw, dict):
        return "{" + ", ".join(f"{printable(k)} = {_toml(v)}" for k, v in raw.items()) + "}"
    return str(raw)


def _range(rule: Rule, hi: float | None, hi_key: str | None) -> str:
    """The allowed range of a rule as text, e.g. "in (0, 90) deg" or "> 0 kg"."""
    def num(value: float) -> str:
        return f"{units.in_display(value, rule.quantity):g}"

    if rule.lo is not None and hi is not None:
        text = (f"in {'[' if rule.lo_in else '('}{num(rule.lo)}, "
                f"{num(hi)}{']' if rule.hi_in else ')'}")
    elif rule.lo is not None:
        text = f"{'>=' if rule.lo_in else '>'} {num(rule.lo)}"
    elif hi is not None:
        text = f"{'<=' if rule.hi_in else '<'} {num(hi)}"
    else:
        text = "finite"
    text = f"{text} {units.display_unit(rule.quantity)}".rstrip()
    return f"{text} (below {hi_key})" if hi_key else text


def _in_range(rule: Rule, value: float, hi: float | None) -> bool:
    """Whether an SI value lies in the rule's range (hi already resolved to a number)."""
    above = rule.lo is None or value > rule.lo or (rule.lo_in and value == rule.lo)
    below = hi is None or value < hi or (rule.hi_in and value == hi)
    return above and below


class _Reader:
    """Reads a parsed scene section by section; every failure raises SceneError naming the file."""

    def __init__(self, source: str):
        self.source = source
        self.checks: list[tuple] = []   # Checks, as data: what a free value must satisfy at run time
        self.written: dict[str, tuple[float, str]] = {}   # key -> (number, unit) of values not written in SI

    def rule(self, param: Param, rule: Rule, siblings: dict[str, Param] | None) -> None:
        """Record a parameter's rule as data: its range, and the sibling it must stay below."""
        hi = rule.hi if not isinstance(rule.hi, str) else None
        self.checks.append(("range", param.name, param.key, rule.lo, hi, rule.lo_in, rule.hi_in,
                            _range(rule, hi, None)))
        if isinstance(rule.hi, str):
            other = siblings[rule.hi]
            self.checks.append(("less", param.name, param.key, other.name, f"below {other.key}"))
        self.bound(param, rule.quantity)

    def bound(self, param: Param, quantity: str) -> None:
        """Record units.LIMITS of the quantity as a "bound" rule, [lo, hi] (a quantity with a smallest
        magnitude, mass, is positive: [smallest, largest]; else [-largest, largest]); not a "range":
        it says where arithmetic holds, not what the scene allows (a fit's default bounds)."""
        if quantity in units.LIMITS:
            smallest, largest = units.LIMITS[quantity]
            lo = smallest if smallest is not None else -largest
            unit = units.si_unit(quantity)
            self.checks.append(("bound", param.name, param.key, lo, largest,
                                f"in [{lo:g}, {largest:g}] {unit} (where double arithmetic holds)"))

    def fail(self, key: str, problem: str, value: str | None = None) -> NoReturn:
        """Raise naming the file and the dotted key (both as given: escaped by ``printable``)."""
        where = printable(key) if value is None else f"{printable(key)} = {value}"
        raise SceneError(f"{printable(self.source)}: {where}: {problem}")

    def keys(self, table: dict, path: str, allowed: tuple[str, ...]) -> None:
        """Refuse keys not in allowed, listing the allowed ones and the closest match."""
        for key in table:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                self.fail(_join(path, key), f"unknown key{hint}; allowed here: {', '.join(allowed)}")

    def table(self, parent: dict, key: str, path: str = "", required: bool = True,
              hint: str = "") -> dict | None:
        """A sub-table, or None when it is absent and not required."""
        dotted = _join(path, key)
        if key not in parent:
            if required:
                self.fail(dotted, f"missing required table{hint}")
            return None
        if not isinstance(parent[key], dict):
            self.fail(dotted, "expected a table", _toml(parent[key]))
        return parent[key]

    def text(self, table: dict, key: str, path: str, choices: tuple[str, ...] | None = None,
             default: str | None = None, pattern: re.Pattern | None = None) -> str:
        """A string key, optionally one of choices or matching pattern."""
        dotted = _join(path, key)
        allowed = f"one of {', '.join(map(_toml, choices))}" if choices else "a string"
        if pattern:
            allowed = f"a string matching {pattern.pattern}"
        if key not in table:
            if default is None:
                self.fail(dotted, f"missing required key; expected {allowed}")
            return default
        raw = table[key]
        if not isinstance(raw, str):
            self.fail(dotted, f"expected {allowed}", _toml(raw))
        if (choices and raw not in choices) or (pattern and not pattern.fullmatch(raw)):
            self.fail(dotted, f"must be {allowed}", _toml(raw))
        return raw

    def subset(self, table: dict, key: str, path: str, allowed: tuple[str, ...],
               default: list | None = None) -> tuple[str, ...]:
        """A non-empty list of distinct names from allowed, returned in allowed's order."""
        dotted = _join(path, key)
        need = f"a non-empty list of distinct names from {_toml(list(allowed))}"
        if key not in table and default is None:
            self.fail(dotted, f"missing required key; expected {need}")
        raw = table.get(key, default)
        if (not isinstance(raw, list) or not raw or len(set(map(str, raw))) != len(raw)
                or not all(isinstance(x, str) and x in allowed for x in raw)):
            self.fail(dotted, f"must be {need}", _toml(raw))
        return tuple(x for x in allowed if x in raw)

    def number(self, table: dict, key: str, path: str, rule: Rule, free_ok: bool = True,
               siblings: dict[str, Param] | None = None) -> tuple[float, bool]:
        """Value in SI and free flag of a numeric key, checked against its rule."""
        dotted = _join(path, key)
        hi, hi_key = rule.hi, None
        if isinstance(rule.hi, str):
            hi, hi_key = siblings[rule.hi].value, siblings[rule.hi].key
        if key not in table:
            if rule.default is None:
                self.fail(dotted, f"missing required key ({rule.quantity}, "
                                  f"{_range(rule, hi, hi_key)})")
            return float(rule.default), False
        raw, free = self.unwrap(table[key], dotted, free_ok)
        if rule.integer and (isinstance(raw, bool) or not isinstance(raw, int)):
            self.fail(dotted, "expected an integer", _toml(raw))
        try:
            value = units.to_si(raw, rule.quantity)
        except units.UnitError as err:
            self.fail(dotted, str(err), _toml(raw))
        if not _in_range(rule, value, hi):
            hint = ""
            if rule.quantity == "angle" and not isinstance(raw, str):
                hint = f"; plain numbers are SI (rad); write '{raw:g} deg'"
            self.fail(dotted, f"must be {_range(rule, hi, hi_key)}{hint}",
                      units.describe(raw, rule.quantity))
        bounds = units.out_of_bounds(value, rule.quantity)
        if bounds:
            self.fail(dotted, bounds, units.describe(raw, rule.quantity))
        form = units.written(raw, rule.quantity)
        if form is not None:
            self.written[dotted] = form
        return value, free

    def unwrap(self, raw: object, dotted: str, free_ok: bool) -> tuple[object, bool]:
        """Value and free flag of a plain value or a {value, free} table."""
        if not isinstance(raw, dict):
            return raw, False
        if not free_ok:
            self.fail(dotted, "expected a plain value; {value, free} tables are for model "
                              "parameters only", _toml(raw))
        self.keys(raw, dotted, ("value", "free"))
        if "value" not in raw:
            self.fail(f"{dotted}.value", "missing required key")
        free = raw.get("free", False)
        if not isinstance(free, bool):
            self.fail(f"{dotted}.free", "expected true or false", _toml(free))
        return raw["value"], free

    def params(self, table: dict, path: str, rules: dict[str, Rule],
               prefix: str = "") -> dict[str, Param]:
        """Params for the rules' keys, in rule order, named prefix + key."""
        out: dict[str, Param] = {}
        for key, rule in rules.items():
            value, free = self.number(table, key, path, rule, siblings=out)
            out[key] = Param(prefix + key, value, units.si_unit(rule.quantity), free,
                             _join(path, key))
            self.rule(out[key], rule, out)
        return out

    def law(self, table: dict, path: str, laws: dict[str, dict[str, Rule]],
            prefix: str = "", tables: tuple[str, ...] = ()) -> Law:
        """The law's kind and parameters; ``tables`` are sub-tables allowed beside its keys."""
        kind = self.text(table, "law", path, tuple(laws))
        if laws[kind] is SCHEDULE:
            self.keys(table, path, ("law", "variable", "shape", "at", "values", *tables))
            return self.schedule(table, path)
        self.keys(table, path, ("law", *laws[kind], *tables))
        return Law(kind, self.params(table, path, laws[kind], prefix))

    def array(self, table: dict, key: str, path: str, lo: int, hi: int) -> list:
        """A list of lo..hi entries."""
        dotted = _join(path, key)
        count = f"{lo}" if lo == hi else f"{lo} to {hi}"
        if key not in table:
            self.fail(dotted, f"missing required key; expected a list of {count} values")
        raw = table[key]
        if not isinstance(raw, list) or not lo <= len(raw) <= hi:
            size = f" ({len(raw)} entries)" if isinstance(raw, list) else ""
            self.fail(dotted, f"must be a list of {count} values{size}", _toml(raw)[:200])
        return raw

    def schedule(self, table: dict, path: str) -> Law:
        """A schedule in t or x2: breakpoints ``at`` (increasing) and ``values`` (forces)."""
        owner = path                      # "load" or "drive"
        force = {"load": "F2", "drive": "F1"}[owner]
        variable = self.text(table, "variable", path, tuple(SCHEDULE_VARIABLES))
        shape = self.text(table, "shape", path, SCHEDULE_SHAPES)
        at_raw = self.array(table, "at", path, 1, MAX_BREAKPOINTS)
        count = len(at_raw) + (1 if shape == "steps" else 0)
        why = "one more than at (the value before the first breakpoint first)" if shape == "steps" else "one per breakpoint"
        if not isinstance(table.get("values"), list) or len(table["values"]) != count:
            self.array(table, "values", path, count, count)  # fails with the count
        at_rule = Rule(SCHEDULE_VARIABLES[variable], 0.0 if variable == "t" else None, lo_in=True)
        breakpoints: list[Param] = []
        for i, raw in enumerate(at_raw):
            key = f"at[{i}]"
            value, free = self.number({key: raw}, key, path, at_rule)
            param = Param(f"{owner}_at{i + 1}", value, units.si_unit(at_rule.quantity), free, f"{path}.{key}")
            if breakpoints and not value > breakpoints[-1].value:
                self.fail(param.key, f"breakpoints must increase strictly (after {breakpoints[-1].key} = "
                                     f"{units.show(breakpoints[-1].value, at_rule.quantity)}; values: {why})",
                          units.show(value, at_rule.quantity))
            if at_rule.lo is not None:
                self.rule(param, at_rule, None)
            else:
                self.bound(param, at_rule.quantity)
            if breakpoints:
                self.checks.append(("less", breakpoints[-1].name, breakpoints[-1].key, param.name,
                                    f"below {param.key} (breakpoints increase)"))
            breakpoints.append(param)
        first = 0 if shape == "steps" else 1
        values = []
        for i, raw in enumerate(table["values"]):
            key = f"values[{i}]"
            value, free = self.number({key: raw}, key, path, Rule("force"))
            values.append(Param(f"{force}_{first + i}", value, "N", free, f"{path}.{key}"))
            self.bound(values[-1], "force")
        return Law("schedule", {}, {"variable": variable, "shape": shape}, tuple(breakpoints), tuple(values))

    def only_modelled(self, table: dict, path: str, flank_of: dict[str, str],
                      flanks: tuple[str, ...]) -> None:
        """Refuse per-flank keys for flanks the scene does not model."""
        for key, flank in flank_of.items():
            if key in table and flank not in flanks:
                self.fail(_join(path, key), f"flank {flank} is not modelled "
                                            f"(wedge.flanks = {_toml(list(flanks))})")

    def slopes(self, wedge: dict, flanks: tuple[str, ...]) -> dict[str, Param]:
        """gamma per modelled flank: one shared Param, or gamma_a / gamma_b."""
        per_flank = {f"gamma_{f}": f for f in FLANKS}
        self.only_modelled(wedge, "wedge", per_flank, flanks)
        given = [key for key in per_flank if key in wedge]
        if "gamma" in wedge or not given:
            if given:
                self.fail(f"wedge.{given[0]}", "give either wedge.gamma (all flanks) or "
                                               "gamma_a / gamma_b (per flank), not both")
            shared = self.params(wedge, "wedge", {"gamma": GAMMA})["gamma"]
            return {f: shared for f in flanks}
        gamma = {f: self.params(wedge, "wedge", {f"gamma_{f}": GAMMA})[f"gamma_{f}"]
                 for f in flanks}
        if len(flanks) == 2:
            a, b = gamma["a"], gamma["b"]
            if not math.isclose(a.value, b.value, rel_tol=1e-12):
                self.fail(b.key, f"must equal wedge.gamma_a = {units.show(a.value, 'angle')} "
                                 "with both flanks modelled: with different slopes the gap "
                                 "between the flanks would vary along the travel, which tswm "
                                 "does not model (its wedge.clearance is a constant gap between "
                                 "parallel flanks)", units.show(b.value, "angle"))
            if a.free or b.free:
                self.fail((b if b.free else a).key, "a free slope with both flanks modelled "
                          "must be given once as wedge.gamma (the flanks share one slope)")
        return gamma

    def friction(self, doc: dict, flanks: tuple[str, ...]) -> dict[str, Law]:
        """One shared law for all flanks, or one [friction.<flank>] table per modelled flank."""
        table = self.table(doc, "friction")
        tables = [k for k, v in table.items() if isinstance(v, dict) and "value" not in v]
        if not tables:
            shared = self.law(table, "friction", FRICTION_LAWS, "friction_")
            return {f: shared for f in flanks}
        others = [k for k in table if k not in tables]
        if others:
            self.fail("friction", "give either one law for all flanks (law = ... and its keys) "
                                  "or one table per flank ([friction.a], [friction.b]), not "
                                  f"both; found keys {', '.join(others)} and tables "
                                  f"{', '.join(tables)}")
        self.keys(table, "friction", FLANKS)
        self.only_modelled(table, "friction", {f: f for f in FLANKS}, flanks)
        hint = " (per-flank friction needs a table for every modelled flank)"
        return {f: self.law(self.table(table, f, "friction", hint=hint), f"friction.{f}",
                            FRICTION_LAWS, f"friction_{f}_") for f in flanks}

    def check_jam(self, gamma: dict[str, Param], friction: dict[str, Law]) -> None:
        """Refuse slope + largest friction angle >= 90 deg on any flank (the wedge jams)."""
        for flank, law in friction.items():
            key, label, max_rho = MAX_RHO[law.kind]
            slope, rho = gamma[flank].value, max_rho(law.params)
            self.checks.append(("jam", gamma[flank].name, gamma[flank].key, law.params[key].name, law.kind,
                                f"{gamma[flank].key} + {label} < 90 deg (else the wedge jams)"))
            if slope + rho >= 90 * DEG:
                p = law.params[key]
                self.fail(p.key, f"{gamma[flank].key} + {label} = "
                                 f"{units.in_display(slope, 'angle'):g} + "
                                 f"{units.in_display(rho, 'angle'):g} deg: must be < 90 deg "
                                 "(else the wedge jams)",
                          units.show(p.value, FRICTION_LAWS[law.kind][key].quantity))

    def torque_switch(self, drive: dict) -> Param | None:
        """The optional [drive.torque_switch]: the motor is cut for good once S1 reaches S1."""
        table = self.table(drive, "torque_switch", "drive", required=False)
        if table is None:
            return None
        self.keys(table, "drive.torque_switch", ("S1",))
        value, free = self.number(table, "S1", "drive.torque_switch", TORQUE_SWITCH)
        param = Param("S1_trip", value, units.si_unit("force"), free, "drive.torque_switch.S1")
        self.rule(param, TORQUE_SWITCH, None)
        return param

    def modes(self, doc: dict, equations: str) -> tuple[str, ...]:
        table = self.table(doc, "modes", required=False) or {}
        self.keys(table, "modes", ("include",))
        modes = self.subset(table, "include", "modes", MODES, default=["forward"])
        if equations == "literal" and modes not in LITERAL_MODES:
            self.fail("modes.include", 'equations = "literal" allows ["forward"] or ["forward", '
                      '"sliding"] only (the printed equations model forward sliding only)',
                      _toml(list(modes)))
        if equations == "consistent" and "sliding" in modes:
            self.fail("modes.include", '"sliding" (along phi = 0) needs equations = "literal": '
                      "the consistent model is continuous at phi = 0 (both flanks give the same "
                      "a1 there), so it never slides", _toml(list(modes)))
        return modes

    def clearance(self, doc: dict, wedge: dict, flanks: tuple[str, ...], equations: str,
                  run: Run) -> tuple[Param | None, Param | None, dict[str, Param] | None]:
        """wedge.clearance with [impact] restitution (rigid flanks) or [mesh] stiffness and damping
        (compliant flanks), or none of them; the start gap within the clearance."""
        impact = self.table(doc, "impact", required=False)
        mesh_table = self.table(doc, "mesh", required=False)
        if "clearance" not in wedge:
            for name, table in (("impact", impact), ("mesh", mesh_table)):
                if table is not None:
                    self.fail(name, f"[{name}] needs a clearance between the flanks: give wedge.clearance")
            if run.gap:
                self.fail("run.gap", "a start gap needs a clearance between the flanks: give wedge.clearance",
                          units.show(run.gap, "length"))
            return None, None, None
        if flanks != FLANKS or equations != "consistent":
            self.fail("wedge.clearance", 'a clearance needs both flanks (wedge.flanks = ["a", "b"]) and '
                      'equations = "consistent"')
        value, free = self.number(wedge, "clearance", "wedge", CLEARANCE)
        clearance = Param("clearance", value, units.si_unit("length"), free, "wedge.clearance")
        self.rule(clearance, CLEARANCE, None)
        if run.gap > value:
            self.fail("run.gap", f"must lie within the clearance, <= wedge.clearance = {units.show(value, 'length')}",
                      units.show(run.gap, "length"))
        if mesh_table is not None:
            if impact is not None:
                self.fail("impact", "give [impact] (rigid flanks that collide) or [mesh] (compliant flanks), "
                          "not both")
            self.keys(mesh_table, "mesh", tuple(MESH))
            return clearance, None, self.params(mesh_table, "mesh", MESH, "mesh_")
        if impact is None:
            self.fail("impact", "missing required table: a clearance needs [impact] restitution = e in [0, 1] "
                      "(0: the flanks stay together after an impact, 1: elastic), or [mesh] stiffness (and "
                      "damping) for compliant flanks")
        self.keys(impact, "impact", tuple(IMPACT))
        restitution = self.params(impact, "impact", IMPACT)["restitution"]
        return clearance, restitution, None

    def lost_motion(self, doc: dict, flanks: tuple[str, ...], equations: str,
                    clearance: Param | None) -> dict[str, Param] | None:
        """[lost_motion]: body 2 travels freely before it picks up the stem, which carries the load."""
        table = self.table(doc, "lost_motion", required=False)
        if table is None:
            return None
        if clearance is not None or equations != "consistent" or "a" not in flanks:
            self.fail("lost_motion", "lost motion needs rigid flanks without clearance (no wedge.clearance), "
                      'flank a (it carries the pickup) and equations = "consistent"')
        self.keys(table, "lost_motion", tuple(LOST_MOTION))
        return self.params(table, "lost_motion", LOST_MOTION, "lost_motion_")

    def run(self, doc: dict) -> Run:
        table = self.table(doc, "run", required=False) or {}
        self.keys(table, "run", (*RUN, "method"))
        value = {k: self.number(table, k, "run", rule, free_ok=False)[0] for k, rule in RUN.items()}
        method = self.text(table, "method", "run", METHODS, default="auto")
        return Run(**{**value, "max_steps": int(value["max_steps"])}, method=method)

    def scene(self, doc: dict, digest: str) -> Scene:
        if "stage" in doc:
            raise ChainSceneGiven(f"{printable(self.source)}: stage: a chain of stages ([[stage]] tables, "
                                  "docs/scene-format.md, \"Chains\") is read by derivation.chain.scene: tswm derive "
                                  "and tswm simulate take it, the one-stage commands do not")
        self.keys(doc, "", TOP_KEYS)
        name = self.text(doc, "name", "", pattern=NAME)
        description = self.text(doc, "description", "", default="")
        if len(description) > MAX_DESCRIPTION:
            self.fail("description", f"{len(description)} characters: must be at most {MAX_DESCRIPTION}")
        equations = self.text(doc, "equations", "", EQUATIONS, default="consistent")
        wedge = self.table(doc, "wedge")
        self.keys(wedge, "wedge", ("flanks", "gamma", "gamma_a", "gamma_b", "clearance", *WEDGE))
        flanks = self.subset(wedge, "flanks", "wedge", FLANKS)
        gamma = self.slopes(wedge, flanks)
        masses = self.params(wedge, "wedge", WEDGE)
        friction = self.friction(doc, flanks)
        self.check_jam(gamma, friction)
        drive_table = self.table(doc, "drive")
        drive = self.law(drive_table, "drive", DRIVE_LAWS, tables=("torque_switch",))
        torque_switch = self.torque_switch(drive_table)
        load = self.law(self.table(doc, "load"), "load", LOAD_LAWS)
        reference = self.table(doc, "reference", required=False)
        if reference is not None:
            self.keys(reference, "reference", tuple(REFERENCE))
            reference = self.params(reference, "reference", REFERENCE)
        modes = self.modes(doc, equations)
        if equations == "literal" and flanks != FLANKS:
            self.fail("wedge.flanks", 'equations = "literal" needs ["a", "b"] (the printed '
                      "model switches between both flanks)", _toml(list(flanks)))
        run = self.run(doc)
        clearance, restitution, mesh = self.clearance(doc, wedge, flanks, equations, run)
        lost_motion = self.lost_motion(doc, flanks, equations, clearance)
        scene = Scene(name, description, equations, flanks, gamma, masses["m1"], masses["m2"],
                      friction, drive, load, reference or {}, modes, run,
                      self.source, digest, torque_switch, tuple(dict.fromkeys(self.checks)), clearance, restitution, mesh,
                      lost_motion, dict(self.written))
        names = [p.name for p in scene.params()]
        assert len(set(names)) == len(names) and all(n.isidentifier() for n in names), names
        return scene
