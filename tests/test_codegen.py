"""Generated modules: fresh, deterministic, SymPy-free, and equal to hand-written formulas."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from derivation.codegen import body_is_intact, generate_module, module_name
from derivation.model import build_model
from derivation.scene import load_scene, shipped_scenes
from tswm_runtime.jit import signatures
from tswm_runtime.cli import main
from tswm_runtime.model.contract import check_module, load_module
from tswm_runtime.reference.paper_gear import kloss, rho as rho_paper
from hard_cases.reference import printed as hand_literal

GENERATED = Path(__file__).resolve().parents[1] / "generated"
G = math.radians(4.76)
M1 = 11.8


@pytest.mark.parametrize("name", shipped_scenes())
def test_checked_in_module_is_fresh_and_deterministic(name):
    model = build_model(load_scene(name))
    source = generate_module(model)
    assert source == generate_module(model)
    checked_in = (GENERATED / f"{module_name(name)}.py").read_text()
    assert source == checked_in, f"generated/{module_name(name)}.py is stale: run `tswm generate {name}`"


SYMPY_FREE_PROBE = """
import importlib, json, sys
sys.modules["sympy"] = None
modes = {}
for name in sys.argv[1:]:
    try:
        modes[name] = len(importlib.import_module(f"generated.{name}").MODES)
    except Exception as error:
        modes[name] = repr(error)
print(json.dumps(modes))
"""


@pytest.fixture(scope="module")
def imported_without_sympy():
    """{module name: its number of modes, or the error}: every shipped module imported with SymPy
    blocked, all in one Python process (one numba import, not one per scene)."""
    names = [module_name(name) for name in shipped_scenes()]
    run = subprocess.run([sys.executable, "-c", SYMPY_FREE_PROBE, *names], capture_output=True, text=True,
                         cwd=GENERATED.parent)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


@pytest.mark.parametrize("name", shipped_scenes())
def test_module_follows_contract_and_imports_no_sympy(name, imported_without_sympy):
    module = load_module(name)
    assert check_module(module) is module
    assert (module.RHS_SIG, module.JAC_SIG, module.GUARDS_SIG) == (
        signatures.RHS_SIG, signatures.JAC_SIG, signatures.GUARDS_SIG)
    source = (GENERATED / f"{module_name(name)}.py").read_text()
    imports = {line.split()[1] for line in source.splitlines() if line.startswith(("import ", "from "))}
    scene = load_scene(name)
    arrays = {"numpy"} if "schedule" in (scene.drive.kind, scene.load.kind) else set()   # a schedule's data
    assert imports == {"math", "numba"} | arrays
    assert imported_without_sympy[module_name(name)] == len(module.MODES)


def test_hand_edited_module_is_refused_unless_forced(tmp_path, capsys):
    assert main(["generate", "paper", "-o", str(tmp_path)]) == 0
    path = tmp_path / "paper.py"
    assert body_is_intact(path.read_text())
    path.write_text(path.read_text().replace("return F2", "return 2 * F2"))
    assert main(["generate", "paper", "-o", str(tmp_path)]) == 2
    assert "edited by hand" in capsys.readouterr().err and "return 2 * F2" in path.read_text()
    assert main(["generate", "paper", "-o", str(tmp_path), "--force"]) == 0
    assert path.read_text() == (GENERATED / "paper.py").read_text()


# ---- the paper scene against formulas written out by hand -------------------------------

def hand_sliding(f, s, F1, F2, rho, m1, m2, gamma):
    psi = math.tan(gamma + f * s * rho)
    a = (F1 + psi * F2) / (m1 + psi * m2 * math.tan(gamma))
    return a, F1 - m1 * a, F2 - m2 * math.tan(gamma) * a     # reactions by their definition


speeds = st.one_of(st.sampled_from([0.0, 7.85, -0.5, 6.5, 1e-12]), st.floats(-3.0, 9.0))


@settings(max_examples=150, deadline=None)
@given(v=speeds, m2=st.floats(50, 400), F2=st.floats(-20000, 5000))
def test_paper_module_equals_hand_formulas(v, m2, F2):
    m = load_module("paper")
    y, p = np.array([v]), np.array([m2, F2])
    F1, rho = kloss(v), rho_paper(v)
    assert m.drive_force(0.0, y, p) == pytest.approx(F1, rel=1e-12, abs=1e-9)
    assert m.friction_angle(0.0, y, p) == pytest.approx(rho, rel=1e-12)
    assert m.switching(0.0, y, p) == pytest.approx(F1 * math.tan(G) / M1 - F2 / m2, rel=1e-9, abs=1e-9)
    for mode, f in ((0, 1), (1, -1)):
        a, S1, S2 = hand_sliding(f, 1, F1, F2, rho, M1, m2, G)
        assert m.accel(mode, 0.0, y, p) == pytest.approx(a, rel=1e-9, abs=1e-9)
        assert m.reactions(mode, 0.0, y, p) == pytest.approx((S1, S2), rel=1e-9, abs=1e-6)
    cone_f, cone_b, fn = m.stick_conditions(0.0, y, p)
    normal, tangential = F1 * math.sin(G) - F2 * math.cos(G), F1 * math.cos(G) + F2 * math.sin(G)
    assert (cone_f, cone_b, fn) == pytest.approx(
        (math.tan(rho) * abs(normal) - tangential, math.tan(rho) * abs(normal) + tangential, normal), abs=1e-6)
    assert m.load_factors(S1, S2, p) == pytest.approx((abs(S1) / 990, abs(S2) / 8303.7))


@settings(max_examples=50, deadline=None)
@given(v=st.floats(0.0, 7.0), m2=st.floats(50, 400))
def test_paper_module_on_switching_surface(v, m2):
    """phi = 0: no contact force, and both flanks give a1 = F1/m1."""
    m = load_module("paper")
    F2 = m2 * kloss(v) * math.tan(G) / M1
    y, p = np.array([v]), np.array([m2, F2])
    assert m.switching(0.0, y, p) == pytest.approx(0.0, abs=1e-9)
    for mode in (0, 1):
        assert m.accel(mode, 0.0, y, p) == pytest.approx(kloss(v) / M1, rel=1e-9)
        assert m.reactions(mode, 0.0, y, p) == pytest.approx((0.0, 0.0), abs=1e-7)


def test_literal_reaction_is_finite_where_psi2_vanishes():
    """Printed eq. (9) divides by Psi_2 = tan(gamma - rho), zero where rho(v) = gamma."""
    from scipy.optimize import brentq
    m = load_module("paper_literal")
    v = brentq(lambda v: rho_paper(v) - G, 0.01, 5.0)
    p = np.array([200.0, -5000.0])
    S2 = m.reactions(1, 0.0, np.array([v]), p)[1]
    limit = (-kloss(v) * 200 * math.tan(G) + (-5000.0) * M1) / M1     # S1/Psi as Psi -> 0
    assert math.isfinite(S2) and S2 == pytest.approx(limit, rel=1e-6)


def test_asymmetric_module_all_modes_equal_hand_formulas():
    m = load_module("asymmetric")
    rho_b = math.radians(3)
    for v in (-2.0, -0.3, 0.4, 5.0):
        y = np.array([v])
        for t, F2 in ((0.1, 0.0), (0.5, 3000.0)):
            # The step load reads its latched piece (p's only slot): 0 before t_step = 0.3 s, 1 after.
            p = np.array([1.0 if t >= 0.3 else 0.0])
            assert m.LATCH_NAMES == ("load_piece",) and m.load_force(t, y, p) == F2
            for mode, name in enumerate(m.MODES[:4]):
                f, s = m.MODE_FLANK[mode], m.MODE_DIRECTION[mode]
                rho = rho_paper(v) if f == 1 else rho_b
                a, S1, S2 = hand_sliding(f, s, kloss(v), F2, rho, M1, 100.0, G)
                assert m.accel(mode, t, y, p) == pytest.approx(a, rel=1e-9, abs=1e-9), name
                assert m.reactions(mode, t, y, p) == pytest.approx((S1, S2), rel=1e-9, abs=1e-6)


def finite_difference_jacobian(m, mode, t, y, p, h=1e-6):
    n = len(y)
    J = np.zeros((n, n))
    f = lambda t, y: np.array([y[1], m.accel(mode, t, y, p)] if n == 2 else [m.accel(mode, t, y, p)])
    for j in range(n):
        e = np.zeros(n)
        e[j] = h * max(1.0, abs(y[j]))
        J[:, j] = (f(t, y + e) - f(t, y - e)) / (2 * e[j])
    dt = h * max(1.0, t)
    return J, (f(t + dt, y) - f(t - dt, y)) / (2 * dt)


def parameters(m, t=0.2, y=(0.0,), t_trip=math.inf):
    """p at (t, y): free parameters at their defaults, then the latches by hand: the trip
    time, and a piecewise load's piece (its breakpoints passed, from the scene's values)."""
    values = {**m.FIXED, **dict(zip(m.PARAM_NAMES, m.PARAM_DEFAULTS))}
    x2 = y[0] * math.tan(values["gamma"]) if len(m.STATES) == 2 else None
    latches = []
    for name in m.LATCH_NAMES:
        if name == "t_trip":
            latches.append(t_trip)
        elif "t_step" in values:
            latches.append(float(t >= values["t_step"]))
        elif "x2_contact" in values:
            latches.append(float(x2 >= values["x2_contact"]))
        else:  # a schedule: in x2 when x1 is a state (a law reads it), else in t
            at = [values[k] for k in sorted(values) if k.startswith("load_at")]
            latches.append(float(sum((x2 if x2 is not None else t) >= a for a in at)))
    return np.array([*m.PARAM_DEFAULTS, *latches], dtype=float)


@pytest.mark.parametrize("name,states,latches", [("paper", [[0.7], [3.0], [7.0]], ()),
                                                 ("one_sided", [[0.001, 0.2], [0.1, 0.3], [0.2, -0.1]], ()),
                                                 ("asymmetric", [[-1.0], [2.0]], ()),
                                                 ("paper_literal", [[1.0], [5.0]], ()),
                                                 ("seating", [[0.5, 3.0], [1.16, 7.0], [1.16, -0.5]], ()),
                                                 ("seating", [[1.16, 7.0], [1.2, 0.5]], (0.1,)),
                                                 # x2 = 8, 25, 58 mm: before, on and past the schedule's ramp (20 to 50 mm)
                                                 ("valve_travel", [[0.1, 1.0], [0.3, 2.0], [0.7, 0.5]], ())])
def test_jacobian_matches_finite_differences(name, states, latches):
    m = load_module(name)
    for y in map(np.array, states):
        p = parameters(m, 0.2, y, *latches)
        assert len(p) == len(m.PARAM_NAMES) + len(m.LATCH_NAMES)
        for mode in range(len(m.MODES)):
            if m.MODE_DIRECTION[mode] and np.sign(y[-1]) != m.MODE_DIRECTION[mode]:
                continue
            J, dfdt = np.zeros((len(y), len(y))), np.zeros(len(y))
            m.jac(mode, 0.2, y, p, J, dfdt)
            J_fd, dfdt_fd = finite_difference_jacobian(m, mode, 0.2, y, p)
            assert J == pytest.approx(J_fd, rel=1e-5, abs=1e-6), (name, mode, y)
            assert dfdt == pytest.approx(dfdt_fd, abs=1e-6)


NEW_VARIANT = """
name = "steep-wedge"
description = "a steep wedge near jamming, written by a test"
[wedge]
flanks = ["a", "b"]
gamma = {{ value = "80 deg", free = true }}
m1 = "0.5 kg"
m2 = "2 kg"
[friction]
law = "constant"
rho = "9.9 deg"
[drive]
law = "linear"
F0 = "100 N"
V0 = "2 m/s"
[load]
law = "spring"
k = "1000 N/m"
x2_contact = "0.01 m"
preload = "5 N"
[modes]
include = ["forward", "backward", "stick"]
"""


def test_new_scene_file_generates_compiles_and_evaluates(tmp_path):
    scene = tmp_path / "steep.toml"
    scene.write_text(NEW_VARIANT.format())
    assert main(["generate", str(scene), "-o", str(tmp_path)]) == 0
    m = load_module(tmp_path / "steep_wedge.py")
    assert m.MODES == ("fwd_a", "fwd_b", "bwd_a", "bwd_b", "stick") and m.STATES == ("x1", "v1")
    gamma, rho = math.radians(80), math.radians(9.9)       # gamma + rho = 89.9 deg
    x1, v = 0.01, 0.5
    x2 = x1 * math.tan(gamma)
    assert m.LATCH_NAMES == ("load_piece",) and x2 > 0.01  # the spring is pressed: piece 1
    y, p = np.array([x1, v]), np.array([gamma, 1.0])
    F1 = 100 * (1 - v / 2)
    F2 = -(5 + 1000 * (x2 - 0.01))
    for mode in range(4):
        a, S1, S2 = hand_sliding(m.MODE_FLANK[mode], m.MODE_DIRECTION[mode], F1, F2, rho, 0.5, 2.0, gamma)
        assert m.accel(mode, 0.0, y, p) == pytest.approx(a, rel=1e-9)
        assert m.reactions(mode, 0.0, y, p) == pytest.approx((S1, S2), rel=1e-9)
    D, jam = m.consistency_sliding(0.0, y, p, 1.0)      # fwd_a: rho_sign = +1
    assert jam == pytest.approx(math.cos(gamma + rho)) and 0 < jam < 2e-3
    assert m.consistency_sliding(0.0, y, p, -1.0)[1] == pytest.approx(math.cos(gamma - rho))
    g = np.zeros(len(m.GUARDS))
    m.guards(0, 0.0, y, p, g)
    assert g[m.GUARDS.index("load_contact")] == pytest.approx(x2 - 0.01)


@pytest.mark.parametrize("name", shipped_scenes())
def test_observe_gives_the_reactions_and_constants_fit(name):
    m = load_module(name)
    assert m.OBSERVABLES == ("S1", "S2")
    assert len(m.MODE_DECLARED) == len(m.MODES) == len(m.GUARD_DIRECTIONS)
    assert all(len(row) == len(m.GUARDS) for row in m.GUARD_DIRECTIONS)
    p, out = parameters(m), np.zeros(2)
    for mode in range(len(m.MODES)):
        for v in (0.5, 4.0):
            y = np.array([{"x1": 0.05, "v1": v, "gap": 1e-4}.get(s, 0.0) for s in m.STATES])
            m.observe(mode, 0.1, y, p, out)
            assert tuple(out) == m.reactions(mode, 0.1, y, p)
            assert all(math.isfinite(x) for x in out)


def test_paper_literal_has_an_undeclared_slide_mode_at_constant_speed():
    m = load_module("paper_literal")
    assert m.MODES == ("fwd_a", "fwd_b", "slide_fwd") and m.MODE_DECLARED == (True, True, False)
    assert (m.MODE_FLANK[2], m.MODE_DIRECTION[2], m.MODE_REGIME[2]) == (0, 1, "sliding along phi = 0")
    assert m.GUARDS == ("phi", "v1", "D", "slide_exit_a", "slide_exit_b") and m.LATCH_NAMES == ()
    assert m.accel(2, 0.0, np.array([3.0]), parameters(m)) == 0.0
    assert load_module("paper").MODE_DECLARED == (True, True, True)


LITERAL_SLIDING = """
name = "literal-spring"
equations = "literal"
[wedge]
flanks = ["a", "b"]
gamma = "4.76 deg"
m1 = "11.8 kg"
m2 = { value = "200 kg", free = true }
[friction]
law = "velocity"
a = 0.161
b = 0.535
c = 0.088
[drive]
law = "kloss"
Fmax = "2178 N"
V0 = "7.85 m/s"
Vmax = "6.5 m/s"
[load]
law = "spring"
k = "2e5 N/m"
x2_contact = "1 mm"
preload = "100 N"
[modes]
include = ["forward", "sliding"]
"""


@pytest.mark.heavy
def test_literal_slide_mode_equals_filippov_by_hand(tmp_path):
    scene = tmp_path / "literal.toml"
    scene.write_text(LITERAL_SLIDING)
    assert main(["generate", str(scene), "-o", str(tmp_path)]) == 0
    m = load_module(tmp_path / "literal_spring.py")
    assert m.MODES == ("fwd_a", "fwd_b", "slide_fwd") and m.MODE_DECLARED == (True, True, True)
    assert m.GUARDS == ("phi", "v1", "D", "load_contact", "slide_exit_a", "slide_exit_b")
    assert [row[-2:] for row in m.GUARD_DIRECTIONS] == [(-1, -1)] * 3
    p, t, m2 = np.array([200.0, 1.0]), 0.1, 200.0   # m2, then the spring's piece: pressed at every x1 below
    for x1, v in ((0.05, 3.0), (0.3, 6.9), (0.02, 0.4)):
        y = np.array([x1, v])
        F1, F2 = kloss(v), -(100 + 2e5 * (x1 * math.tan(G) - 1e-3))
        hand = [hand_literal(f, F1, F2, rho_paper(v), M1, m2, G) for f in (1, -1)]
        for mode in (0, 1):
            assert m.accel(mode, t, y, p) == pytest.approx(hand[mode][0], rel=1e-9)
        # d phi/dt = dF1/dv1 a1 / m1 + k tan(gamma)^2 v1 / m2 for phi = F1/m1 - F2 tan(gamma)/m2 ...
        slip, slip_max = 7.85 - v, 1.35
        dF1 = -2 * 2178 * slip_max * (slip_max ** 2 - slip ** 2) / (slip ** 2 + slip_max ** 2) ** 2
        rate_a, rate_b = (dF1 * a / M1 + 2e5 * math.tan(G) ** 2 * v / m2 for a, _, _ in hand)
        # ... and by central differences of the module's own phi along the flow
        h = 1e-6

        def rate(a):
            step = np.array([v, a]) * h
            return (m.switching(t, y + step, p) - m.switching(t, y - step, p)) / (2 * h)

        assert (rate(hand[0][0]), rate(hand[1][0])) == pytest.approx((rate_a, rate_b), rel=1e-6)
        lam = rate_b / (rate_b - rate_a)
        a1 = lam * hand[0][0] + (1 - lam) * hand[1][0]
        assert m.accel(2, t, y, p) == pytest.approx(a1, rel=1e-9)
        assert rate(m.accel(2, t, y, p)) == pytest.approx(0.0, abs=1e-6 * abs(rate_a))      # d phi/dt = 0
        S = [lam * hand[0][i] + (1 - lam) * hand[1][i] for i in (1, 2)]
        assert m.reactions(2, t, y, p) == pytest.approx(S, rel=1e-9)
        out = np.zeros(2)
        m.observe(2, t, y, p, out)
        assert out == pytest.approx(S, rel=1e-9)
        g = np.zeros(len(m.GUARDS))
        m.guards(2, t, y, p, g)
        assert g[-2:] == pytest.approx([-rate_a, rate_b], rel=1e-9)
        assert g[1] == v and tuple(g[[0, 2]]) == (1.0, 1.0)       # phi and D are inactive while sliding
        m.guards(0, t, y, p, g)
        assert tuple(g[-2:]) == (1.0, 1.0)                         # the exits only while sliding
        J, dfdt = np.zeros((2, 2)), np.zeros(2)
        m.jac(2, t, y, p, J, dfdt)
        J_fd, dfdt_fd = finite_difference_jacobian(m, 2, t, y, p)
        assert J == pytest.approx(J_fd, rel=1e-5, abs=1e-6) and dfdt == pytest.approx(dfdt_fd, abs=1e-6)


def test_seating_torque_switch_equals_hand_formulas():
    m = load_module("seating")
    assert m.LATCH_NAMES == ("t_trip", "load_piece") and m.PARAM_NAMES == () and m.MODE_DECLARED == (True,) * 5
    assert m.GUARDS[-1] == "torque_switch" and all(row[-1] == -1 for row in m.GUARD_DIRECTIONS)
    trip = m.GUARDS.index("torque_switch")
    k, x2c, m2 = 5e5, 0.095, 200.0
    for x1, v in ((0.5, 3.0), (1.145, 7.8)):
        y = np.array([x1, v])
        F2 = -k * max(0.0, x1 * math.tan(G) - x2c)
        for t_trip, t, F1 in ((math.inf, 0.1, kloss(v)), (0.15, 0.1, kloss(v)), (0.05, 0.1, 0.0)):
            p = np.array([t_trip, float(x1 * math.tan(G) >= x2c)])  # latches: trip time, spring piece
            assert m.drive_force(t, y, p) == pytest.approx(F1, rel=1e-12, abs=1e-12)
            g = np.zeros(len(m.GUARDS))
            for mode in range(len(m.MODES)):
                f, s = m.MODE_FLANK[mode], m.MODE_DIRECTION[mode]
                S1 = hand_sliding(f, s, F1, F2, rho_paper(v), M1, m2, G)[1] if s else F1
                assert m.reactions(mode, t, y, p)[0] == pytest.approx(S1, rel=1e-9, abs=1e-6)
                m.guards(mode, t, y, p, g)
                assert g[trip] == (pytest.approx(1500.0 - S1, rel=1e-9, abs=1e-6) if t < t_trip else 1.0)
    # After the trip, stopped in the seat, the gear self-locks: both stick cones hold.
    y, p = np.array([1.18, 0.0]), np.array([0.2, 1.0])
    F2 = -k * (1.18 * math.tan(G) - x2c)
    normal, tangential = -F2 * math.cos(G), F2 * math.sin(G)
    rho0 = rho_paper(0.0)
    cones = m.stick_conditions(0.3, y, p)[:2]
    assert cones == pytest.approx((math.tan(rho0) * normal - tangential, math.tan(rho0) * normal + tangential))
    assert min(cones) > 0


def test_fixed_parameters_are_named_constants_not_anonymous_literals():
    """Fixed parameters appear once, as module constants with their scene key, written as the
    scene gives them (4.76 deg as math.radians(4.76)) and equal to the SI value bit for bit; no
    function body carries their value (or tan(gamma)) as a bare number."""
    import re

    source = (Path(__file__).parents[1] / "generated" / "paper_runup.py").read_text()
    constants, _, functions = source.partition("\n@njit")
    m = load_module("paper_runup")
    for name, value in m.FIXED.items():
        written = re.search(rf"^{name} = (.+?)  # ", constants, re.M)[1]
        assert eval(written, {"math": math}) == value == getattr(m, name), name
    assert re.search(r"^gamma = math.radians\(4.76\)  # wedge.gamma", constants, re.M)
    for number in (repr(11.8), repr(math.tan(m.FIXED["gamma"]))):
        assert number not in functions, number
    assert repr(m.FIXED["gamma"]) not in constants.partition("FIXED = ")[2].partition("\n")[2]
    assert m.tan_gamma == math.tan(m.FIXED["gamma"])


def test_values_with_units_are_written_as_given_and_inert():
    """A value given with a unit is printed from its number and the unit table only, and only
    where that gives the SI double exactly; else the SI value."""
    from derivation.codegen import GenerationError, source_form

    assert source_form(math.radians(4.76), (4.76, "deg"), "gamma") == "math.radians(4.76)"
    assert source_form(-20000.0, (-20.0, "kN"), "F2") == "-20.0 * 1000.0"
    assert source_form(0.2 * 1e-3, (0.2, "mm"), "clearance") == "0.2 * 0.001"
    assert source_form(0.1, (7.0, "deg"), "gamma") == "0.1"          # the form would not give the value
    assert source_form(5.0, None, "m1") == "5.0"
    with pytest.raises(GenerationError, match="gamma"):
        source_form(math.inf, (math.inf, "deg"), "gamma")


def test_mirror_modes_share_one_function_with_the_sign_of_rho():
    """fwd_b is fwd_a with -rho for rho, bwd_a is fwd_b, bwd_b is fwd_a: one set of functions
    taking rho_sign, no near-copies; the dispatch passes each mode's sign (each mode's a1, S1, S2
    against hand formulas: test_new_scene_file_generates_compiles_and_evaluates)."""
    import re

    m = load_module("seating")
    source = (Path(__file__).parents[1] / "generated" / "seating.py").read_text()
    for prefix in ("outputs", "accel", "reactions", "consistency"):
        assert f"def {prefix}_sliding(t, y, p, rho_sign):" in source
        assert not re.search(rf"def {prefix}_(fwd|bwd)_", source), prefix
    assert "def jac_sliding(t, y, p, J, dfdt, rho_sign):" in source and "def jac_fwd" not in source
    assert m.MODE_FLANK[:4] == (1, -1, 1, -1) and m.MODE_DIRECTION[:4] == (1, 1, -1, -1)
    accel = source[source.index("def accel(mode"):]
    for mode, sign in enumerate((1.0, -1.0, -1.0, 1.0)):
        assert accel.split(f"mode == {mode}:\n")[1].split("\n")[0].strip() == f"return accel_sliding(t, y, p, {sign})"


def test_generator_digest_covers_exactly_what_code_generation_reads():
    """Every derivation module that codegen imports is hashed; the document writer is not,
    so editing the LaTeX writer does not make the checked-in modules stale."""
    import subprocess
    import sys

    from derivation.codegen import GENERATOR_SOURCES

    script = ("import sys, derivation.codegen\n"
              "print(' '.join(sorted(m.split('.')[1] for m in sys.modules if m.startswith('derivation.'))))")
    loaded = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.split()
    assert {f"{name}.py" for name in loaded} <= set(GENERATOR_SOURCES)
    assert not {"document.py", "latex.py", "audit.py"} & set(GENERATOR_SOURCES)
