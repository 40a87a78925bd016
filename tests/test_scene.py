"""Scene files: shipped scenes, unit conversion and one refusal per class of bad input."""

import hashlib
import math
from importlib.resources import files

import pytest

from tswm_common import units
from derivation.scene import SceneError, load_scene, parse_scene, shipped_scenes

# A valid scene as {section: {key: TOML value text}}; "" is the top level.
BASE = {
    "": {"name": '"t"'},
    "wedge": {"flanks": '["a", "b"]', "gamma": '"4.76 deg"', "m1": '"11.8 kg"',
              "m2": '"200 kg"'},
    "friction": {"law": '"velocity"', "a": "0.161", "b": "0.535", "c": "0.088"},
    "drive": {"law": '"kloss"', "Fmax": '"2178 N"', "V0": '"7.85 m/s"', "Vmax": '"6.5 m/s"'},
    "load": {"law": '"constant"', "F2": '"-15000 N"'},
    "reference": {"Ft1": '"990 N"', "Ft2": '"8303.7 N"'},
    "modes": {"include": '["forward", "stick"]'},
    "run": {"t_end": '"1 s"', "rtol": "1e-6", "atol": "1e-9", "method": '"dopri5"',
            "max_steps": "1000"},
}
PER_FLANK = {"friction": None, "friction.a.law": '"velocity"', "friction.a.a": "0.161",
             "friction.a.b": "0.535", "friction.a.c": "0.088",
             "friction.b.law": '"constant"', "friction.b.rho": '"3 deg"'}


def scene_text(changes: dict[str, str | None]) -> str:
    """BASE with changes: "section.key" (or a section name) to TOML value text, None deletes."""
    sections = {name: dict(keys) for name, keys in BASE.items()}
    for dotted, value in changes.items():
        if dotted in sections:
            del sections[dotted]
            if value is None:
                continue
        section, _, key = dotted.rpartition(".")
        if value is None:
            del sections[section][key]
        else:
            sections.setdefault(section, {})[key] = value
    lines = []
    for name, keys in sections.items():
        lines += [f"[{name}]"] if name else []
        lines += [f"{key} = {value}" for key, value in keys.items()]
    return "\n".join(lines) + "\n"


def scene(**changes):
    return parse_scene(scene_text(changes), "t.toml")


def test_base_is_valid():
    s = parse_scene(scene_text({}), "t.toml")
    assert s.name == "t" and s.source == "t.toml" and s.equations == "consistent"


def test_shipped_names():
    assert shipped_scenes() == ("asymmetric", "backlash", "load-schedule", "lost-motion", "mesh", "one-sided", "paper",
                                "paper-literal", "paper-lostmotion", "paper-runup", "seating", "slow-load",
                                "stiff-drive", "valve-travel")
    for name in shipped_scenes():
        s = load_scene(name)
        assert s.name == name and s.source == f"shipped:{name}"
        data = (files("derivation") / "scenes" / f"{name}.toml").read_bytes()
        assert s.digest == hashlib.sha256(data).hexdigest()


def test_paper():
    s = load_scene("paper")
    assert s.flanks == ("a", "b") and s.equations == "consistent"
    assert s.gamma["a"] is s.gamma["b"] and s.gamma["a"].name == "gamma"
    assert s.gamma["a"].value == pytest.approx(4.76 * math.pi / 180, rel=1e-15)
    assert s.gamma["a"].unit == "rad" and s.gamma["a"].key == "wedge.gamma"
    assert (s.m1.value, s.m1.unit, s.m1.free) == (11.8, "kg", False)
    assert (s.m2.value, s.m2.free, s.m2.key) == (200.0, True, "wedge.m2")
    assert s.friction["a"] is s.friction["b"] and s.friction["a"].kind == "velocity"
    assert {k: p.value for k, p in s.friction["a"].params.items()} == {
        "a": 0.161, "b": 0.535, "c": 0.088}
    assert s.drive.kind == "kloss"
    assert {k: p.value for k, p in s.drive.params.items()} == {
        "Fmax": 2178.0, "V0": 7.85, "Vmax": 6.5}
    assert s.load.kind == "constant"
    f2 = s.load.params["F2"]
    assert (f2.value, f2.unit, f2.free) == (-15000.0, "N", True)
    assert {k: p.value for k, p in s.reference.items()} == {"Ft1": 990.0, "Ft2": 8303.7}
    assert s.modes == ("forward", "stick")
    assert (s.run.t_end, s.run.x1, s.run.v1, s.run.rtol, s.run.atol, s.run.method) == (
        1.0, 0.0, 0.0, 1e-6, 1e-9, "dopri5")


def test_paper_params_order_and_free():
    s = load_scene("paper")
    assert [p.name for p in s.params()] == [
        "gamma", "m1", "m2", "friction_a", "friction_b", "friction_c",
        "Fmax", "V0", "Vmax", "F2", "Ft1", "Ft2"]
    assert [p.name for p in s.free_params()] == ["m2", "F2"]
    assert [p.key for p in s.params()][3:6] == ["friction.a", "friction.b", "friction.c"]


def test_paper_literal_same_data():
    lit, paper = load_scene("paper-literal"), load_scene("paper")
    assert lit.equations == "literal" and lit.modes == ("forward",)
    assert [(p.name, p.value, p.free) for p in lit.params()] == [
        (p.name, p.value, p.free) for p in paper.params()]


def test_one_sided():
    s = load_scene("one-sided")
    assert s.flanks == ("a",) and list(s.gamma) == ["a"]
    assert s.gamma["a"].value == pytest.approx(10 * math.pi / 180, rel=1e-15)
    assert s.friction["a"].kind == "constant"
    assert s.friction["a"].params["rho"].value == pytest.approx(6 * math.pi / 180, rel=1e-15)
    assert s.friction["a"].params["rho"].name == "friction_rho"
    assert (s.m1.value, s.m2.value) == (2.0, 20.0)
    assert s.drive.kind == "linear"
    assert {k: p.value for k, p in s.drive.params.items()} == {"F0": 800.0, "V0": 0.5}
    assert s.load.kind == "spring"
    assert {k: p.value for k, p in s.load.params.items()} == pytest.approx(
        {"k": 2e5, "x2_contact": 0.005, "preload": 100.0})
    assert s.load.params["k"].unit == "N/m"
    assert s.reference == {} and s.modes == ("forward", "stick") and s.run.t_end == 0.5
    assert s.free_params() == ()


def test_asymmetric():
    s = load_scene("asymmetric")
    assert s.gamma["a"] is s.gamma["b"]
    fa, fb = s.friction["a"], s.friction["b"]
    assert (fa.kind, fb.kind) == ("velocity", "constant")
    assert fa.params["c"].key == "friction.a.c"
    assert fb.params["rho"].value == pytest.approx(3 * math.pi / 180, rel=1e-15)
    assert [p.name for p in s.params()] == [
        "gamma", "m1", "m2", "friction_a_a", "friction_a_b", "friction_a_c", "friction_b_rho",
        "Fmax", "V0", "Vmax", "F2_before", "F2_after", "t_step"]
    assert {k: p.value for k, p in s.load.params.items()} == {
        "F2_before": 0.0, "F2_after": 3000.0, "t_step": 0.3}
    assert s.m2.value == 100.0 and s.modes == ("forward", "backward", "stick")


def test_seating():
    s, paper = load_scene("seating"), load_scene("paper")
    assert s.equations == "consistent" and s.modes == ("forward", "backward", "stick")
    same = ("gamma", "m1", "friction_a", "friction_b", "friction_c", "Fmax", "V0", "Vmax")
    assert [(p.name, p.value) for p in s.params() if p.name in same] == [
        (p.name, p.value) for p in paper.params() if p.name in same]
    assert s.m2.value == 200.0 and s.free_params() == ()
    switch = s.torque_switch
    assert (switch.name, switch.value, switch.unit, switch.key) == (
        "S1_trip", 1500.0, "N", "drive.torque_switch.S1")
    assert [p.name for p in s.params()].index("S1_trip") == [p.name for p in s.params()].index("Vmax") + 1
    assert s.load.kind == "spring" and s.load.params["k"].value == 5e5
    # self-locking: the lead angle is below the friction angle at standstill, rho(0) = 1/c deg
    gamma_deg, rho0_deg = math.degrees(s.gamma["a"].value), 1 / s.friction["a"].params["c"].value
    assert gamma_deg == pytest.approx(4.76) and rho0_deg == pytest.approx(11.36, abs=0.01) and gamma_deg < rho0_deg
    assert paper.torque_switch is None


def test_torque_switch_free_and_missing_key():
    s = scene(**{"drive.torque_switch.S1": '{ value = "2 kN", free = true }'})
    assert s.torque_switch.value == 2000.0 and s.torque_switch in s.free_params()
    with pytest.raises(SceneError, match=r"t.toml: drive.torque_switch.S1: missing required key \(force, > 0 N\)"):
        parse_scene(scene_text({}) + "[drive.torque_switch]\n", "t.toml")


def test_sliding_mode_keyword():
    s = scene(**{"equations": '"literal"', "modes.include": '["sliding", "forward"]'})
    assert s.modes == ("forward", "sliding")


def test_load_scene_by_path(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(scene_text({}))
    s = load_scene(path)
    assert s.source == str(path) and s == parse_scene(scene_text({}), str(path))
    with pytest.raises(SceneError, match="cannot read.*shipped scenes: asymmetric"):
        load_scene(tmp_path / "missing.toml")


@pytest.mark.parametrize("raw, quantity, si", [
    ("2 kN", "force", 2000.0), ("5 mm", "length", 0.005), ("20 ms", "time", 0.02),
    ("500 g", "mass", 0.5), ("1.5 t", "mass", 1500.0), ("3 N/mm", "stiffness", 3000.0),
    ("2 kN/mm", "stiffness", 2e6), ("40 mm/s", "velocity", 0.04),
    ("90 deg", "angle", math.pi / 2), ("0.5 rad", "angle", 0.5), ("-1e3 N", "force", -1000.0),
    (7, "force", 7.0), (0.25, "angle", 0.25), (3, "dimensionless", 3.0),
])
def test_units_to_si(raw, quantity, si):
    assert units.to_si(raw, quantity) == pytest.approx(si, rel=1e-15)


def test_units_in_scene():
    s = scene(**{"wedge.m1": '"11800 g"', "load.F2": '"-15 kN"', "run.t_end": '"250 ms"',
                 "wedge.gamma": "0.0830776"})
    assert s.m1.value == pytest.approx(11.8) and s.load.params["F2"].value == -15000.0
    assert s.run.t_end == 0.25 and s.gamma["a"].value == 0.0830776


@pytest.mark.parametrize("raw, quantity, message", [
    ("5 kg", "force", "'kg' is a mass unit; expected a force"),
    ("5 furlong", "length", "unknown unit 'furlong'"),
    ("5", "force", "missing unit"),
    ("five N", "force", "'<number> <unit>'"),
    ("0.1", "dimensionless", "plain number"),
    (True, "mass", "expected a mass"),
    ("4.76", "angle", "missing unit; expected an angle: "),
    ("2 deg", "force", "'deg' is an angle unit; expected a force"),
    (True, "angle", "expected an angle: a plain number in rad"),
    (math.nan, "mass", "finite"),
])
def test_units_errors(raw, quantity, message):
    with pytest.raises(units.UnitError, match=message):
        units.to_si(raw, quantity)


def test_modes_canonical_order():
    s = scene(**{"modes.include": '["stick", "backward", "forward"]'})
    assert s.modes == ("forward", "backward", "stick")


def test_defaults():
    s = scene(reference=None, run=None, modes=None)
    assert s.modes == ("forward",) and s.reference == {} and s.description == ""
    assert (s.run.t_end, s.run.x1, s.run.v1, s.run.rtol, s.run.atol, s.run.method,
            s.run.max_steps) == (1.0, 0.0, 0.0, 1e-6, 1e-9, "auto", 100000)


def test_per_flank_slopes_one_sided_and_equal():
    s = scene(**{"wedge.flanks": '["b"]', "wedge.gamma": None, "wedge.gamma_b": '"8 deg"'})
    assert list(s.gamma) == ["b"] and s.gamma["b"].name == "gamma_b"
    s = scene(**{"wedge.gamma": None, "wedge.gamma_a": '"5 deg"', "wedge.gamma_b": '"5 deg"'})
    assert s.gamma["a"] is not s.gamma["b"] and s.gamma["a"].value == s.gamma["b"].value


def test_value_table_fixed_and_default_step():
    s = scene(**{"wedge.m1": '{ value = "2 kg" }', "load": None, "load.law": '"step"',
                 "load.F2_after": '"-5 kN"', "load.t_step": "0"})
    assert (s.m1.value, s.m1.free) == (2.0, False)
    assert s.load.params["F2_before"].value == 0.0 and s.load.params["t_step"].free is False


LOST = {"lost_motion.travel": '"1 mm"', "lost_motion.stem_mass": '"5 kg"', "lost_motion.restitution": "0.5"}

BAD = [
    # lost motion: its keys, ranges, and what it cannot be combined with
    ({**LOST, "lost_motion.mass": '"1 kg"'}, ["lost_motion.mass", "unknown key", "stem_mass"]),
    ({**LOST, "lost_motion.stem_mass": '"0 kg"'}, ["lost_motion.stem_mass", "> 0 kg"]),
    ({**LOST, "lost_motion.travel": '"-1 mm"'}, ["lost_motion.travel", ">= 0"]),
    ({**LOST, "lost_motion.restitution": "1.5"}, ["lost_motion.restitution", "[0, 1]"]),
    ({**LOST, "wedge.clearance": '"0.1 mm"', "impact.restitution": "0.5"},
     ["lost_motion", "rigid flanks without clearance"]),
    ({**LOST, "wedge.flanks": '["b"]'}, ["lost_motion", "flank a"]),
    # unknown, missing, wrong type
    ({"wedge.m_2": '"1 kg"'}, ["wedge.m_2", "unknown key", "did you mean 'm2'",
                               "allowed here: flanks, gamma, gamma_a, gamma_b, clearance, m1, m2"]),
    ({"colour": '"red"'}, ["colour", "unknown key", "allowed here: name"]),
    ({"drive.Vmx": '"6 m/s"'}, ["drive.Vmx", "did you mean 'Vmax'", "Fmax, V0, Vmax"]),
    ({"wedge.m1": None}, ["wedge.m1", "missing required key (mass, > 0 kg)"]),
    ({"drive": None}, ["drive", "missing required table"]),
    ({"": None}, ["name", "missing required key", "[a-z0-9]"]),
    ({"drive.law": None}, ["drive.law", "missing", '"kloss", "constant", "linear"']),
    ({"wedge.m1": "true"}, ["wedge.m1 = true", "expected a mass"]),
    ({"wedge.m1": "[1, 2]"}, ["wedge.m1 = [1, 2]", "expected a mass"]),
    ({"friction.a": '"0.161"'}, ["friction.a", "plain number"]),
    ({"run.method": "3"}, ["run.method = 3", '"dopri5", "rosenbrock23"']),
    ({"description": "1"}, ["description = 1", "expected a string"]),
    ({"wedge": "5"}, ["wedge = 5", "expected a table"]),
    ({"run.max_steps": "1.5"}, ["run.max_steps = 1.5", "integer"]),
    # units and non-finite values
    ({"load.F2": '"5 kg"'}, ["load.F2", "mass unit", "force", "N, kN"]),
    ({"wedge.m2": '"5 lb"'}, ["wedge.m2", "unknown unit 'lb'", "kg, g, t"]),
    ({"wedge.m2": "nan"}, ["wedge.m2 = nan", "finite"]),
    ({"load.F2": "-inf"}, ["load.F2 = -inf", "finite"]),
    # ranges
    ({"wedge.m2": '"-5 kg"'}, ["t.toml: wedge.m2 = -5 kg: must be > 0 kg"]),
    ({"wedge.m1": '"-500 g"'}, ["wedge.m1 = -500 g (= -0.5 kg)", "> 0 kg"]),
    ({"wedge.gamma": '"90 deg"'}, ["wedge.gamma = 90 deg", "in (0, 90) deg"]),
    ({"wedge.gamma": "0"}, ["wedge.gamma = 0 rad (= 0 deg)", "in (0, 90) deg"]),
    ({"wedge.gamma": "4.76"}, ["wedge.gamma = 4.76 rad (= 272.728 deg)", "in (0, 90) deg",
                               "plain numbers are SI (rad); write '4.76 deg'"]),
    ({"friction": None, "friction.law": '"constant"', "friction.rho": '"90 deg"'},
     ["friction.rho = 90 deg", "in [0, 90) deg"]),
    ({"friction.a": "-0.1"}, ["friction.a = -0.1", ">= 0"]),
    ({"friction.b": "0"}, ["friction.b = 0", "> 0"]),
    ({"friction.c": "-1"}, ["friction.c = -1", "> 0"]),
    ({"friction": None, "friction.law": '"constant"', "friction.rho": '"86 deg"'},
     ["friction.rho = 86 deg", "wedge.gamma + friction angle rho = 4.76 + 86 deg",
      "must be < 90 deg", "jams"]),
    ({"friction.c": "0.01"}, ["friction.c = 0.01", "rho(0) = 1/c deg = 4.76 + 100 deg",
                              "must be < 90 deg", "jams"]),
    ({"drive.Fmax": '"0 N"'}, ["drive.Fmax = 0 N", "> 0 N"]),
    ({"drive.V0": '"0 m/s"'}, ["drive.V0 = 0 m/s", "> 0 m/s"]),
    ({"drive.Vmax": '"7.85 m/s"'}, ["drive.Vmax = 7.85 m/s", "in (0, 7.85) m/s",
                                    "below drive.V0"]),
    ({"drive.Vmax": '"0 m/s"'}, ["drive.Vmax = 0 m/s", "in (0, 7.85) m/s"]),
    ({"drive": None, "drive.law": '"linear"', "drive.F0": '"800 N"', "drive.V0": '"-1 m/s"'},
     ["drive.V0 = -1 m/s", "> 0 m/s"]),
    ({"load": None, "load.law": '"step"', "load.F2_after": "0", "load.t_step": '"-1 ms"'},
     ["load.t_step = -1 ms (= -0.001 s)", ">= 0 s"]),
    ({"load": None, "load.law": '"spring"', "load.k": '"0 N/mm"', "load.x2_contact": "0",
      "load.preload": "0"}, ["load.k = 0 N/mm (= 0 N/m)", "> 0 N/m"]),
    ({"load": None, "load.law": '"spring"', "load.k": "1", "load.x2_contact": "0",
      "load.preload": '"-1 N"'}, ["load.preload = -1 N", ">= 0 N"]),
    ({"reference.Ft1": '"0 N"'}, ["reference.Ft1 = 0 N", "> 0 N"]),
    ({"reference.Ft2": None}, ["reference.Ft2", "missing required key", "> 0 N"]),
    # flanks and slopes
    ({"wedge.flanks": "[]"}, ["wedge.flanks = []", 'non-empty list of distinct names from ["a", "b"]']),
    ({"wedge.flanks": '["a", "a"]'}, ["wedge.flanks", "distinct"]),
    ({"wedge.flanks": '["c"]'}, ["wedge.flanks", '["a", "b"]']),
    ({"wedge.flanks": '"a"'}, ["wedge.flanks = \"a\"", "list"]),
    ({"wedge.gamma": None, "wedge.gamma_a": '"4 deg"', "wedge.gamma_b": '"5 deg"'},
     ["wedge.gamma_b = 5 deg", "must equal wedge.gamma_a = 4 deg", "gap", "constant gap between parallel"]),
    ({"wedge.gamma_a": '"4.76 deg"'}, ["wedge.gamma_a", "either wedge.gamma", "not both"]),
    ({"wedge.flanks": '["a"]', "wedge.gamma_b": '"5 deg"', "wedge.gamma": None},
     ["wedge.gamma_b", "flank b is not modelled"]),
    ({"wedge.gamma": None, "wedge.gamma_a": '{ value = "5 deg", free = true }',
      "wedge.gamma_b": '"5 deg"'}, ["wedge.gamma_a", "free slope", "wedge.gamma"]),
    ({"wedge.gamma": None}, ["wedge.gamma", "missing required key", "(0, 90) deg"]),
    # friction tables
    ({**PER_FLANK, "friction.law": '"constant"'}, ["friction", "not both"]),
    ({**PER_FLANK, "friction.b": None}, ["friction.b", "missing required table",
                                         "every modelled flank"]),
    ({**PER_FLANK, "wedge.flanks": '["a"]'}, ["friction.b", "flank b is not modelled"]),
    ({**PER_FLANK, "friction.c.law": '"constant"'}, ["friction.c", "unknown key", "a, b"]),
    ({**PER_FLANK, "friction.b.rho": '"88 deg"'}, ["friction.b.rho = 88 deg", "jams"]),
    ({"friction.law": '"coulomb"'}, ["friction.law = \"coulomb\"", '"constant", "velocity"']),
    # modes and equations
    ({"modes.include": "[]"}, ["modes.include = []", '["forward", "backward", "stick", "sliding"]']),
    ({"modes.include": '["forward", "forward"]'}, ["modes.include", "distinct"]),
    ({"modes.include": '["sideways"]'}, ["modes.include", "forward"]),
    ({"equations": '"exact"'}, ['equations = "exact"', '"consistent", "literal"']),
    ({"equations": '"literal"'}, ["modes.include", 'allows ["forward"] or ["forward", "sliding"] only']),
    ({"equations": '"literal"', "modes.include": '["sliding"]'}, ["modes.include = [\"sliding\"]",
                                                                  'allows ["forward"] or']),
    ({"modes.include": '["forward", "sliding"]'}, ["modes.include", 'needs equations = "literal"',
                                                   "continuous at phi = 0", "never slides"]),
    ({"modes.include": '["forward", "slide"]'}, ["modes.include", '"stick", "sliding"']),
    # torque switch
    ({"drive.torque_switch.S1": '"-5 N"'}, ["drive.torque_switch.S1 = -5 N", "must be > 0 N"]),
    ({"drive.torque_switch.S1": '"0 kN"'}, ["drive.torque_switch.S1 = 0 kN (= 0 N)", "> 0 N"]),
    ({"drive.torque_switch.S1": '"5 kg"'}, ["drive.torque_switch.S1", "mass unit"]),
    ({"drive.torque_switch.S2": '"5 N"'}, ["drive.torque_switch.S2", "unknown key", "allowed here: S1"]),
    ({"drive.torque_switch": '"1500 N"'}, ["drive.torque_switch = \"1500 N\"", "expected a table"]),
    ({"drive.torque_swich.S1": '"5 N"'}, ["drive.torque_swich", "did you mean 'torque_switch'"]),
    ({"equations": '"literal"', "modes.include": '["forward"]', "wedge.flanks": '["a"]'},
     ["wedge.flanks", 'needs ["a", "b"]']),
    # run
    ({"run.t_end": "0"}, ["run.t_end = 0 s", "> 0 s"]),
    ({"run.rtol": "1"}, ["run.rtol = 1", "in [1e-13, 0.01]"]),
    ({"run.rtol": "1e-14"}, ["run.rtol = 1e-14", "in [1e-13, 0.01]"]),
    ({"run.atol": "0"}, ["run.atol = 0", "in [1e-20, 1]"]),
    ({"run.atol": "1e300"}, ["run.atol = 1e+300", "in [1e-20, 1]"]),
    ({"run.method": '"rk4"'}, ['run.method = "rk4"', '"dopri5", "rosenbrock23"']),
    ({"run.max_steps": "0"}, ["run.max_steps = 0", "in [1, 1e+09]"]),
    ({"run.max_steps": "99999999999999999999999"}, ["run.max_steps = 1e+23", "in [1, 1e+09]"]),
    ({"run.t_end": '{ value = "1 s", free = true }'}, ["run.t_end", "model parameters only"]),
    # magnitudes where double arithmetic holds (units.LIMITS)
    ({"wedge.m2": "1e308"}, ["wedge.m2 = 1e+308 kg", "|value| must be <= 1e+09 kg"]),
    ({"wedge.m2": '{ value = 1e308, free = true }'}, ["wedge.m2 = 1e+308 kg", "<= 1e+09 kg"]),
    ({"wedge.m1": '"1e-10 kg"'}, ["wedge.m1 = 1e-10 kg", "|value| must be >= 1e-09 kg"]),
    ({"load.F2": '"1e300 N"'}, ["load.F2 = 1e+300 N", "|value| must be <= 1e+12 N"]),
    ({"load.F2": '"-2e9 kN"'}, ["load.F2 = -2e+09 kN (= -2e+12 N)", "<= 1e+12 N"]),
    ({"load": None, "load.law": '"spring"', "load.k": "1e16", "load.x2_contact": "0",
      "load.preload": "0"}, ["load.k = 1e+16 N/m", "<= 1e+15 N/m"]),
    ({"load": None, "load.law": '"schedule"', "load.variable": '"t"', "load.shape": '"steps"',
      "load.at": '["0.5 s"]', "load.values": '["0 N", "1e13 N"]'}, ["load.values[1] = 1e+13 N", "<= 1e+12 N"]),
    ({"run.t_end": '"1e10 s"'}, ["run.t_end = 1e+10 s", "<= 1e+09 s"]),
    ({"run.v1": '"2e12 m/s"'}, ["run.v1 = 2e+12 m/s", "<= 1e+12 m/s"]),
    # name, value tables
    ({"name": '"Paper"'}, ['name = "Paper"', "[a-z0-9][a-z0-9-]{0,63}"]),
    ({"name": '"-x"'}, ['name = "-x"', "[a-z0-9][a-z0-9-]{0,63}"]),
    ({"wedge.m2": '{ value = "1 kg", fixed = true }'}, ["wedge.m2.fixed", "unknown key",
                                                        "value, free"]),
    ({"wedge.m2": '{ value = "1 kg", free = "yes" }'}, ["wedge.m2.free", "true or false"]),
    ({"wedge.m2": "{ free = true }"}, ["wedge.m2.value", "missing required key"]),
    ({"wedge.m2": '{ value = "-1 kg", free = true }'}, ["wedge.m2 = -1 kg", "> 0 kg"]),
]


@pytest.mark.parametrize("changes, parts", BAD, ids=[", ".join(c) for c, _ in BAD])
def test_bad_input(changes, parts):
    with pytest.raises(SceneError) as err:
        scene(**changes)
    message = str(err.value)
    assert message.startswith("t.toml: ")
    for part in parts:
        assert part in message


def test_bounds_of_free_values_are_rules_for_the_run():
    """A free mass carries units.LIMITS as a rule of its own, so --set and sweeps meet them too."""
    masses = [c for c in scene(**{"wedge.m2": '{ value = "200 kg", free = true }'}).checks if c[1] == "m2"]
    assert ("bound", "m2", "wedge.m2", 1e-9, 1e9, "in [1e-09, 1e+09] kg (where double arithmetic holds)") in masses


def test_invalid_toml():
    with pytest.raises(SceneError, match="t.toml: not a valid UTF-8 TOML file"):
        parse_scene("name = ", "t.toml")
