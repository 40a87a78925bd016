"""A chain scene's values are run-time parameters: the generated code depends on the chain's structure only,
and `tswm simulate --set`, `tswm.simulate(params)` and the run's p take any value by name, with units,
checked as the scene reader checks them."""
from __future__ import annotations

import math

import numpy as np
import pytest

from tests.chains import DEG, TIGHT, HandChain, assert_like_hand, structure, wedges


def _source(text: str) -> str:
    from derivation.chain.codegen import generate_chain_module
    from derivation.chain.scene import parse_chain

    return generate_chain_module(parse_chain(text, "t.toml"))


@pytest.mark.heavy
def test_the_generated_code_depends_on_the_structure_only():
    """Two value sets of one structure (other slopes, friction, masses, forces, a spring's stiffness 0 or not)
    give one module but for the scene's own lines (name, values, run); another flank set or a spring
    missing gives another."""
    base = structure(_source(wedges("a", (30.0, 5.0), (0.1, 0.15), (1.0, 1.0, 1.0), (0.0, 0.0, -50.0))))
    other = structure(_source(wedges("b", (20.0, 8.0), (0.3, 0.0), (2.0, 3.0, 4.0), (5.0, 1.0, 7.0), spring=1e3,
                                     v0=-2.0, t_end=1.5)))
    assert base[0] == other[0] and base[1] != other[1]
    text = wedges("a", (30.0, 5.0), (0.1, 0.15), (1.0, 1.0, 1.0), (0.0, 0.0, -50.0))
    one_flank = text.replace('mu = 0.1\n', 'mu = 0.1\nflanks = ["a"]\n', 1)
    assert structure(_source(one_flank))[0] != base[0]


def _with_motor(name: str, top: float, stall: float) -> str:
    """One wedge (30 deg, mu 0.1) between body 0, driven by a falling motor table (stall force ``stall`` at
    rest, 0 at speed ``top``), and body 1 under a 10 N load, from rest."""
    return wedges(name, (30.0,), (0.1,), (1.0, 1.0), (0.0, -10.0), v0=0.0, t_end=0.2).replace(
        'force = "0.0 N"\n', f'force = "0.0 N"\nmotor = {{ speed = [0.0, {top!r}], torque = [{stall!r}, 0.0] }}\n', 1)


def test_chains_differing_only_in_their_motor_table_share_one_module_and_run_each_its_own(chain_module):
    """Two chains whose motor tables differ in their values only (2 points each) give one structure digest and
    one compiled module, and each runs with its own table: the stall force breaks the chain away from rest
    exactly when it exceeds the load's force through the wedge, 10 N tan(30 deg + atan 0.1) by hand; 1 %
    above it the chain slides as the hand model (Newton per body, scipy at rtol 1e-12) with that table, 1 %
    below it the chain rests."""
    from tswm_runtime.simulation.chain import simulate_chain

    needed = 10.0 * math.tan(30.0 * DEG + math.atan(0.1))
    tables = {"breaks-away": (50.0, 1.01 * needed), "holds": (80.0, 0.99 * needed)}
    texts = {name: _with_motor(name, *table) for name, table in tables.items()}
    (digest, own), (other, other_own) = (structure(_source(text)) for text in texts.values())
    assert digest == other and own != other_own
    away, held = (chain_module(text) for text in texts.values())
    assert away.motor_torque is held.motor_torque
    top, stall = tables["breaks-away"]
    hand = HandChain((30.0,), (0.1,), (1.0, 1.0), (0.0, -10.0), motor=((0.0, top), (stall, 0.0), 1.0))
    moving = simulate_chain(away, **TIGHT)
    assert_like_hand(moving, hand, 0.0, 0.2)
    assert [p.regime for p in moving.stages[0].phases] == ["tractive"] and moving.q0[-1] > 0.0
    resting = simulate_chain(held, **TIGHT)
    assert resting.status == "finished"
    assert [p.regime for p in resting.stages[0].phases] == ["resting"]
    assert np.all(resting.q0 == 0.0)


@pytest.fixture(scope="module")
def mov():
    from tswm_runtime.model.contract import load_module

    return load_module("mov")


def test_the_motor_torque_is_np_interp_of_the_table_in_p(mov):
    """The shipped mov's motor_torque equals numpy's np.interp of its table times (U / U_n)^2 exactly, at 200001
    speeds over and beyond the table, at each point and its neighbours and at +-inf (NaN stays NaN), and
    follows the table in p: other torques in p's slots give other torques."""
    from tswm_runtime.chains.run import latches

    p = latches(mov, np.zeros(2), voltage=0.9)
    speed, torque = np.array(mov.MOTOR_SPEED), np.array(mov.MOTOR_TORQUE)
    v = np.concatenate([np.linspace(-10.0, 330.0, 200001), speed, np.nextafter(speed, -np.inf),
                        np.nextafter(speed, np.inf), [np.inf, -np.inf]])
    assert np.array_equal([mov.motor_torque(x, p) for x in v], 0.9**2 * np.interp(v, speed, torque))
    assert math.isnan(mov.motor_torque(math.nan, p))
    p[mov.P_MOTOR_TORQUE:mov.P_MOTOR_TORQUE + mov.MOTOR_POINTS] = torque[::-1]
    assert np.array_equal([mov.motor_torque(x, p) for x in v[:2001]], 0.9**2 * np.interp(v[:2001], speed, torque[::-1]))

def test_values_set_by_name_reach_the_run_with_their_units(mov):
    """mu_1 = 0.08 and force_2 = -5 kN through tswm.simulate: p holds them in SI, the worm's derived Psi_t is
    the closed form tan(lambda + atan(mu / cos alpha_n)) (lambda 4.76 deg, alpha_n 20 deg), and the torque
    the trip thrust needs is the thrust times prod Psi_t r_in / r_out by hand (r 25 mm / 80 mm, d_m 16 mm,
    the nut's Psi_t from its own closed form); the default run differs."""
    import tswm_runtime as tswm

    result = tswm.simulate("mov", {"mu_1": "0.08", "force_2": "-5 kN"})
    p = result.p
    assert p[mov.P_VALUES + mov.PARAM_NAMES.index("mu_1")] == 0.08
    assert p[mov.P_VALUES + mov.PARAM_NAMES.index("force_2")] == -5000.0
    worm = math.tan(4.76 * DEG + math.atan(0.08 / math.cos(20 * DEG)))
    lam = math.atan(0.004 / (math.pi * 0.016))
    alpha_n = math.atan(math.tan(15 * DEG) * math.cos(lam))
    nut = math.tan(lam + math.atan(0.15 / math.cos(alpha_n)))
    assert p[mov.P_PSI] == pytest.approx(worm, rel=1e-14) and p[mov.P_PSI + 2] == pytest.approx(nut, rel=1e-14)
    a = result.answers
    assert a["needed"] == pytest.approx(a["trip"]["thrust"] * worm * 0.025 / 0.08 * nut * 0.008, rel=1e-13)
    assert a["trip"]["t"] != tswm.simulate("mov").answers["trip"]["t"]


def test_mov_with_no_switch_delay_trips_at_the_setting_and_its_stall_margin_is_the_closed_form():
    """The thrust switch on the stem with no delay cuts the motor where the thrust reaches its 20 kN setting;
    the torque that thrust needs through the worm (lambda 4.76 deg, alpha_n 20 deg, mu 0.05, r 25 mm / 80 mm)
    and the Tr 18x4 nut (d_m 16 mm, mu 0.15) is 20 kN x prod Psi_t r_in / r_out by hand, the pull-out torque
    at U/U_n = 0.9 the motor table's 54.45 N m x 0.81, and the stall margin their ratio."""
    import tswm_runtime as tswm

    a = tswm.simulate("mov", {"switch_delay": 0.0, "voltage": 0.9}).answers
    worm = math.tan(4.76 * DEG + math.atan(0.05 / math.cos(20 * DEG)))
    lam = math.atan(0.004 / (math.pi * 0.016))
    nut = math.tan(lam + math.atan(0.15 / math.cos(math.atan(math.tan(15 * DEG) * math.cos(lam)))))
    needed = 20e3 * worm * 0.025 / 0.08 * nut * 0.008
    assert a["trip"]["thrust"] == pytest.approx(20e3, rel=1e-9)
    assert a["needed"] == pytest.approx(needed, rel=1e-9)
    assert a["pull_out"] == pytest.approx(54.45 * 0.81, rel=1e-14)
    assert a["stall_margin"] == pytest.approx(54.45 * 0.81 / needed, rel=1e-9)


@pytest.mark.parametrize("item, message", [
    ("F_2=1", "parameter 'F_2': chain scene 'mov' has no such value (values: lead_angle_1, "),
    ("mu_1=-0.1", "parameter mu_1 = -0.1: must be >= 0 and < 10 (stage[1].mu in the scene file)"),
    ("lead_angle_1=90 deg", "parameter lead_angle_1 = 90 deg: must be > 0 deg and < 90 deg (stage[1].lead_angle in the "
                            "scene file)"),
    ("lead_angle_1=88 deg", "parameters derived gamma_1 = 88 deg and derived rho_1 = 3.04577253 deg: must keep slope "
                            "+ effective friction angle < 90 deg, else the stage jams (stage[1] in the scene file)"),
    ("force_2=1 kg", "parameter force_2 = '1 kg': 'kg' is a mass unit"),
    ("switch_hysteresis=30 kN", "parameter switch_hysteresis = 30000 N: must be < switch_setting (switch_setting = "
                                "20000 N; switch.hysteresis in the scene file)"),
    ("switch_hysteresis=-1 N", "parameter switch_hysteresis = -1 N: must be >= 0 N and < switch_setting "
                               "(switch.hysteresis in the scene file)"),
    ("voltage=3", "voltage = 3.0: must be U / U_n in (0, 2]"),
])
def test_tswm_simulate_refuses_a_bad_value_naming_it(capsys, item, message):
    from tswm_runtime.cli import main

    assert main(["simulate", "mov", "--set", item]) == 2
    assert message in capsys.readouterr().err


def test_a_chain_value_out_of_range_is_refused_as_a_scene_parameter_is(capsys):
    """mu_2 = 12 (the scene reader's range for a stage's mu: [0, 10)) through tswm.simulate and through
    `tswm simulate --set` (exit 2): one message naming the value with its unit, the range and the scene
    file's key, in the form a single-stage scene's free parameter gets (m2 = 0 kg for paper-runup)."""
    import tswm_runtime as tswm
    from tswm_runtime.cli import main
    from tswm_runtime.simulation.simulate import SimulationInputError

    expected = "parameter mu_2 = 12: must be >= 0 and < 10 (stage[2].mu in the scene file)"
    with pytest.raises(SimulationInputError) as refused:
        tswm.simulate("mov", {"mu_2": 12})
    assert str(refused.value) == expected
    assert main(["simulate", "mov", "--set", "mu_2=12"]) == 2
    assert capsys.readouterr().err.strip() == f"tswm simulate: error: {expected}"
    with pytest.raises(SimulationInputError) as single:
        tswm.simulate("paper-runup", {"m2": 0.0})
    assert str(single.value) == "parameter m2 = 0 kg: must be > 0 kg (wedge.m2 in the scene file)"


def test_tswm_simulate_prints_the_values_it_set(capsys):
    from tswm_runtime.cli import main

    assert main(["simulate", "mov", "--set", "mu_1=0.08", "--set", "force_2=-5 kN", "--set", "voltage=0.9"]) == 0
    assert "  values set: mu_1 = 0.08, force_2 = -5000 N, voltage = 0.9\n" in capsys.readouterr().out


def test_modes_that_differ_in_a_stages_regime_share_their_functions():
    """The shipped mov module: its 8 sliding modes (2 directions x 2 regimes x 2 stages) call one accel, one
    contact and one stage_forces function, each a sum of coefficients from p times the body forces (no
    trigonometry per call), one block of coefficients per combination of the stages' friction-angle signs."""
    import re
    from pathlib import Path

    source = (Path(__file__).resolve().parents[1] / "generated" / "mov.py").read_text()
    for name in ("accel", "contact", "stage_forces"):
        (body,) = re.findall(rf"^def {name}_\d+\(t, y, p, direction, k\):\n(.*?)\n\n", source, re.M | re.S)
        assert "math." not in body and "body_forces(t, y, p, direction)" in body
        assert sorted(re.findall(rf"^D_{name}_0_([pm]{{2}})_0 = ", source, re.M)) == ["mm", "mp", "pm", "pp"]


def test_the_coefficient_sums_are_the_modes_expressions():
    """The shipped mov module at its scene's values with the seat pressed, in every sliding mode, at a state off
    the start: a_0, D, jam, each N_k and every stage force equal the derivation's
    expressions for that mode (derivation/chain/dynamics.py, evaluated in SymPy from the body forces and p's
    wedge numbers) to 1e-12 relative."""
    import sympy as sp

    import generated.mov as m
    from derivation.chain import dynamics as dyn
    from derivation.chain.codegen import _jam
    from tswm_runtime.chains.run import latches

    sym = dyn.symbols(m.STAGES)
    y = np.array([0.3, 0.0])
    p = latches(m, y)
    p[m.P_SEATED] = 1.0
    numbers = {**{s: p[m.P_GAMMA + k] for k, s in enumerate(sym.gamma)}, **{s: p[m.P_RHO + k] for k, s in enumerate(sym.rho)},
               **{s: p[m.P_LEVER_IN + k] for k, s in enumerate(sym.lever_in)},
               **{s: p[m.P_LEVER_OUT + k] for k, s in enumerate(sym.lever_out)},
               **dict(zip(sym.inertia, (p[m.V_inertia_0], p[m.V_inertia_1], p[m.V_mass_2])))}
    code = type("Code", (), {"sym": sym})()
    g, forces = np.empty(len(m.GUARDS)), np.empty(3 * m.STAGES)
    for mode, (direction, regimes) in enumerate(zip(m.MODE_DIRECTION, m.MODE_REGIMES)):
        y[1] = 0.1 * direction
        values = {**numbers, **dict(zip(sym.force, m.body_forces(0.0, y, p, float(direction))))}
        expected = dyn.sliding(direction, regimes)
        m.guards(mode, 0.0, y, p, g)
        m.stage_forces(mode, 0.0, y, p, forces)
        got = [m.accel(mode, 0.0, y, p), g[0], g[1], *g[2:2 + m.STAGES], *forces]
        want = [expected.accel, expected.denominator, _jam(code, expected), *expected.normal,
                *(e for pair in zip(expected.on_input, expected.on_output, expected.normal) for e in pair)]
        want = [float(sp.sympify(e).subs(values)) for e in want]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * max(map(abs, want)))
