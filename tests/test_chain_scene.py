"""Chain scene files ([[stage]], [[body]]): what they convert to, and clear refusals of bad input."""
import math

import pytest

from derivation.chain.scene import load_chain, parse_chain
from derivation.chain.selector import decide
from derivation.scene import SceneError, parse_scene
from tests.chains import DEG
from tswm_runtime.bench.chain import worm_and_nut

VALVE = worm_and_nut("valve-chain", drive='torque = "5 N m"')


def test_valve_chain_converts_to_equivalent_wedges():
    """By hand: worm gamma = lead angle, tan(rho') = mu / cos(20 deg), levers r1, r2; Tr 18x4 nut:
    tan(lambda) = 4 / (18 pi), tan(alpha_n) = tan(15 deg) cos(lambda), levers d_m / 2 and 1."""
    v = parse_chain(VALVE, "v.toml").values()
    lam = math.atan(4 / (18 * math.pi))
    assert v.gamma == pytest.approx((4.76 * DEG, lam), rel=1e-14)
    alpha_n = math.atan(math.tan(15 * DEG) * math.cos(lam))
    assert v.rho == pytest.approx((math.atan(0.05 / math.cos(20 * DEG)), math.atan(0.15 / math.cos(alpha_n))), rel=1e-13)
    assert v.lever_in == pytest.approx((0.025, 0.009)) and v.lever_out == pytest.approx((0.08, 1.0))
    assert v.inertia == pytest.approx((0.0069, 0.02, 20.0)) and v.force == pytest.approx((5.0, 0.0, -20000.0))
    assert v.flanks == (("a", "b"), ("a", "b"))


def test_valve_chain_is_decided_from_the_file(tmp_path):
    path = tmp_path / "valve.toml"
    path.write_text(VALVE)
    decision = decide(load_chain(path).values(), 0.0)
    assert decision.outcome == "unique" and decision.modes == ("forward: tractive (a), tractive (a)",)


def test_a_one_stage_chain_reads_like_the_wedge():
    text = '''name = "one"
[[stage]]
kind = "wedge"
gamma = "4.76 deg"
mu = 0.2
flanks = ["a"]
[[body]]
mass = "11.8 kg"
force = "1 kN"
[[body]]
mass = "200 kg"
force = "-5 kN"
'''
    v = parse_chain(text).values()
    assert v.gamma == pytest.approx((4.76 * DEG,)) and v.rho == pytest.approx((math.atan(0.2),))
    assert v.lever_in == v.lever_out == (1.0,) and v.flanks == (("a",),)


def test_the_one_stage_reader_points_to_the_chain_reader():
    with pytest.raises(SceneError, match=r"v.toml: stage: a chain of stages .* read by derivation.chain.scene: tswm derive and tswm simulate"):
        parse_scene(VALVE, "v.toml")


BAD = [
    ('kind = "worm_gear"', 'kind = "gear"', ['stage[1].kind = "gear"', '"wedge", "worm_gear", "power_screw"']),
    ('lead = "4 mm"\n', "", ["stage[2].lead", "missing required key", "> 0 m"]),
    ('lead_angle = "4.76 deg"', 'lead_angle = "95 deg"', ["stage[1].lead_angle = 95 deg", "(0, 90) deg"]),
    ('lead_angle = "4.76 deg"', "lead_angle = 4.76", ["stage[1].lead_angle", "(0, 90) deg", "write '4.76 deg'"]),
    ('flank_angle = "15 deg"', 'flank_angle = "-1 deg"', ["stage[2].flank_angle = -1 deg", "[0, 90) deg"]),
    ("mu = 0.15", "mu = 20", ["stage[2].mu = 20", "in [0, 10)"]),
    ('pressure_angle = "20 deg"', 'pressure_angle = "89.9 deg"', ["stage[1].mu = 0.05", "slope 4.76 deg",
                                                                   "must be < 90 deg (else the stage jams)"]),
    ('mean_diameter = "18 mm"', 'mean_diameter = "2e9 m"', ["stage[2].mean_diameter", "<= 1e+06 m"]),
    ('mean_diameter = "18 mm"', 'mean_diametre = "18 mm"', ["stage[2].mean_diametre", "did you mean 'mean_diameter'"]),
    ("mu = 0.05", 'mu = 0.05\nflanks = ["c"]', ["stage[1].flanks", '["a", "b"]']),
    ('mass = "20 kg"', 'inertia = "20 kg m^2"', ["body[2].inertia", "body 2 translates", "give mass and force"]),
    ('inertia = "0.02 kg m^2"', 'inertia = "0.02 kg"', ["body[1].inertia", "mass unit"]),
    ('torque = "5 N m"', 'torque = "5 N"', ["body[0].torque", "force unit"]),
    ('inertia = "0.0069 kg m^2"', 'inertia = "0 kg m^2"', ["body[0].inertia = 0 kg m^2", "> 0 kg m^2"]),
    ('[[body]]\nmass = "20 kg"\nforce = "-20 kN"\n', "", ["body", "expected 3 to 3 [[body]] tables (2 given)"]),
    ('kind = "worm_gear"\nlead_angle = "4.76 deg"\npressure_angle = "20 deg"\nworm_radius = "25 mm"\n'
     'wheel_radius = "80 mm"', 'kind = "wedge"\ngamma = "4.76 deg"',
     ['stage[2].kind = "power_screw"', "takes a body in rotation", "stage[1] (wedge) drives body 1 in translation"]),
    ('name = "valve-chain"', 'name = "valve-chain"\nwedge = 1', ["wedge", "unknown key", "stage, body"]),
]


@pytest.mark.parametrize("old, new, parts", BAD, ids=[n[:30] for _, n, _ in BAD])
def test_bad_chain_input(old, new, parts):
    assert old in VALVE
    with pytest.raises(SceneError) as err:
        parse_chain(VALVE.replace(old, new, 1), "v.toml")
    message = str(err.value)
    assert message.startswith("v.toml: ")
    for part in parts:
        assert part in message, message


def test_stages_must_be_tables():
    with pytest.raises(SceneError, match=r"v.toml: stage = 3: expected 1 to 4 \[\[stage\]\] tables"):
        parse_chain('name = "x"\nstage = 3\n', "v.toml")
    with pytest.raises(SceneError, match=r"v.toml: stage: missing: expected 1 to 4"):
        parse_chain('name = "x"\n', "v.toml")


def test_at_most_four_stages():
    stage = '[[stage]]\nkind = "wedge"\ngamma = "10 deg"\nmu = 0.1\n'
    body = '[[body]]\nmass = "1 kg"\n'
    with pytest.raises(SceneError, match=r"stage: expected 1 to 4 \[\[stage\]\] tables \(5 given\)"):
        parse_chain('name = "long"\n' + stage * 5 + body * 6, "v.toml")


@pytest.mark.heavy
def test_cli_derive_of_a_chain_writes_its_document(tmp_path, capsys):
    from tswm_runtime.cli import main

    path = tmp_path / "valve.toml"
    path.write_text(VALVE.replace('name = "valve-chain"', 'name = "valve-chain"\ndescription = "\\\\input{x} $y$ 50%"'))
    assert main(["derive", str(path), "--markdown", str(tmp_path / "v.md"), "--latex", str(tmp_path / "v.tex")]) == 0
    out = capsys.readouterr().out
    assert "2 stages (tswm simulate runs it)" in out
    assert "stage 2: power_screw, gamma 4.04611 deg, rho' 8.82559 deg, self-locking" in out
    assert "8 sliding modes" in out and "unique: forward: tractive (a), tractive (a)" in out
    md, tex = (tmp_path / "v.md").read_text(), (tmp_path / "v.tex").read_text()
    for text in (md, tex):
        assert "Resting chain" in text and "statically undetermined" in text and "agrees exactly" in text
    assert "\\textbackslash{}input\\{x\\} \\$y\\$ 50\\%" in tex and "\\input{x}" not in tex
    assert "\\Psi_{1}" in md


def test_cli_derive_of_a_bad_chain_names_the_key(tmp_path, capsys):
    from tswm_runtime.cli import main

    path = tmp_path / "bad.toml"
    path.write_text(VALVE.replace("mu = 0.05", "mu = -1"))
    assert main(["derive", str(path)]) == 2
    assert "stage[1].mu = -1: must be in [0, 10)" in capsys.readouterr().err


CLEARANCE_BAD = [
    ('clearance = "-0.1 mm"\nrestitution = 0.5', "", ["stage[2].clearance = -0.1 mm", "must be >= 0 m"]),
    ('clearance = "0.1 mm"\nrestitution = 0.5', 'gap_2 = "0.2 mm"',
     ["run.gap_2 = 0.2 mm", "must be in [0, 0.0001] m (below stage[2].clearance)"]),
    ('clearance = "0.1 mm"\nrestitution = 0.5', 'gap_2 = "-0.001 mm"', ["run.gap_2 = -0.001 mm", "in [0, 0.0001] m"]),
    ('clearance = "0.1 mm"', "", ["stage[2].restitution", "missing required key", "in [0, 1]"]),
    ('clearance = "0.1 mm"\nrestitution = 1.5', "", ["stage[2].restitution = 1.5", "must be in [0, 1]"]),
    ("", 'gap_2 = "0.05 mm"', ["run.gap_2", "needs a clearance in stage 2: give stage[2].clearance"]),
    ("restitution = 0.5", "", ["stage[2].restitution", "needs a clearance in stage 2"]),
    ("", 'gap_3 = "0.05 mm"', ["run.gap_3", "unknown key", "gap_1, gap_2"]),
    ('clearance = { value = "0.1 mm", free = true }\nrestitution = 0.5', "", ["stage[2].clearance", "free parameters"]),
    ('clearance = "0 mm"\nrestitution = 0.5', "", ['stage[2].clearance = "0 mm"', "must be > 0 in a chain"]),
]


def test_clearances_in_two_stages_are_kept_and_two_starting_open_are_refused_naming_the_key():
    """A clearance per stage: both are kept in stage order with their own keys; each is checked on its own; two
    stages starting open (0 < gap_k < clearance) are refused naming the second's run.gap_k and its value (one open
    stage at a time is modelled), while one open and one on a flank (0 or its clearance) is fine."""
    text = VALVE.replace("mu = 0.05", 'mu = 0.05\nclearance = "0.2 mm"\nrestitution = 0.3')
    two = text.replace("mu = 0.15", 'mu = 0.15\nclearance = "0.1 mm"\nrestitution = 0.5')
    chain = parse_chain(two, "v.toml")
    assert [(c.stage, c.clearance.value, c.restitution.value, c.gap.value) for c in chain.clearances] == [
        (1, 2e-4, 0.3, 0.0), (2, 1e-4, 0.5, 0.0)]
    assert [c.gap.key for c in chain.clearances] == ["run.gap_1", "run.gap_2"]
    with pytest.raises(SceneError) as err:
        parse_chain(two.replace('clearance = "0.1 mm"', 'clearance = "-0.1 mm"'), "v.toml")
    assert "stage[2].clearance = -0.1 mm" in str(err.value) and "must be >= 0 m" in str(err.value)
    with pytest.raises(SceneError) as err:
        parse_chain(two + '[run]\ngap_1 = "0.1 mm"\ngap_2 = "0.05 mm"\n', "v.toml")
    message = str(err.value)
    assert message.startswith('v.toml: run.gap_2 = "0.05 mm": stage 1 starts open already (run.gap_1)'), message
    assert "one open stage at a time is modelled" in message
    one_open = parse_chain(two + '[run]\ngap_1 = "0.1 mm"\ngap_2 = "0.1 mm"\n', "v.toml")
    assert [c.gap.value for c in one_open.clearances] == pytest.approx([1e-4, 1e-4])
    assert [c.stage for c in parse_chain(text, "v.toml").clearances] == [1]


def test_a_spring_between_two_clearances_is_refused_naming_it():
    """A body between two stages with a clearance follows both stages' backlash: a spring on it is refused."""
    from tests.chains import wedges

    text = wedges("mid-spring", (30.0, 40.0), (0.1, 0.1), (1.0, 2.0, 3.0), (1.0, 0.0, 0.0))
    text = text.replace('mu = 0.1\n', 'mu = 0.1\nclearance = "1 mm"\nrestitution = 0.5\n')
    text = text.replace('mass = "2.0 kg"\nforce = "0.0 N"\n', 'mass = "2.0 kg"\nforce = "0.0 N"\nstiffness = "10 N/m"\n')
    with pytest.raises(SceneError, match=r"body\[1\]\.stiffness.*between two stages with a clearance"):
        parse_chain(text, "v.toml")


@pytest.mark.parametrize("stage, run, parts", CLEARANCE_BAD, ids=[s[:24] + r for s, r, _ in CLEARANCE_BAD])
def test_a_bad_stage_clearance_is_refused_naming_key_and_value(stage, run, parts):
    text = VALVE.replace("mu = 0.15", f"mu = 0.15\n{stage}") + f"[run]\n{run}\n"
    with pytest.raises(SceneError) as err:
        parse_chain(text, "v.toml")
    message = str(err.value)
    assert message.startswith("v.toml: ")
    for part in parts:
        assert part in message, message


def test_cli_refuses_a_bad_stage_clearance_with_exit_2(tmp_path, capsys):
    from tswm_runtime.cli import main

    path = tmp_path / "gap.toml"
    path.write_text(VALVE.replace("mu = 0.15", 'mu = 0.15\nclearance = "-0.1 mm"\nrestitution = 0'))
    assert main(["simulate", str(path)]) == 2
    assert "stage[2].clearance = -0.1 mm (= -0.0001 m): must be >= 0 m" in capsys.readouterr().err
    path.write_text(VALVE.replace("mu = 0.05", 'mu = 0.05\nclearance = "0.1 mm"\nrestitution = 0').replace(
        "mu = 0.15", 'mu = 0.15\nclearance = "0.1 mm"\nrestitution = 0'))
    path.write_text(path.read_text() + '[run]\ngap_1 = "0.05 mm"\ngap_2 = "0.05 mm"\n')
    assert main(["simulate", str(path)]) == 2
    assert "run.gap_2 = \"0.05 mm\": stage 1 starts open already" in capsys.readouterr().err
    path.write_text(VALVE.replace("mu = 0.15", 'mu = 0.15\nclearance = "0.1 mm"\nrestitution = 0') +
                    '[run]\ngap_2 = "0.2 mm"\n')
    assert main(["simulate", str(path)]) == 2
    assert "run.gap_2 = 0.2 mm" in capsys.readouterr().err
