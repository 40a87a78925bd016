"""Which side of a stage drives (Modelica issue #108): docs/examples/msl108.toml against a closed form by hand.

The hand model: worm (J_0, motor torque T_0(w) = T_s (1 - w / w_s)) and wheel (J_1, torque T_1), the wheel
turning at i w with i = r_1 tan(gamma) / r_2. The mesh's tangential force on the wheel along its motion,
R (at r_2), holds the worm back with Psi R (at r_1): the worm's P = W tan(gamma + rho') of the handbook,
Psi = tan(gamma + rho') while the worm drives (flank a) and tan(gamma - rho') while the wheel does
(flank b), tan(rho') = mu / cos(alpha_n). Newton per body, k = r_1 / r_2:
    J_0 w' = T_0 - Psi R r_1,    J_1 i w' = T_1 + R r_2,
so w' = (T_0 + Psi k T_1) / (J_0 + Psi k i J_1), linear in w: w(t) = w_inf + (w_start - w_inf) e^(-B t),
and R r_2 (J_0 + Psi k i J_1) = J_1 i T_0 - J_0 T_1: the worm drives (R > 0) iff J_1 i T_0 > J_0 T_1, for
either Psi. The switch is where T_0(w) = J_0 T_1 / (J_1 i)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from tests.chains import DEG, EXAMPLES
from tswm_runtime.simulation.chain import simulate_chain

J0, J1, T1, TS, WS, W0, T_END = 0.001, 2.0, -10.0, 2.0, 150.0, 250.0, 3.0
I_RATIO, K = 0.02 * math.tan(20 * DEG) / 0.08, 0.02 / 0.08
RHO = math.atan(0.05 / math.cos(20 * DEG))
PSI_T, PSI_I = math.tan(20 * DEG + RHO), math.tan(20 * DEG - RHO)


def phase(psi: float, w_start: float):
    """(w_inf, B) of w' = A - B w in the regime of FTF psi, and w(t) from w_start."""
    d = J0 + psi * K * I_RATIO * J1
    b = TS / WS / d
    w_inf = (TS + psi * K * T1) / d / b
    return w_inf, b, lambda t: w_inf + (w_start - w_inf) * np.exp(-b * t)


def hand() -> dict:
    """The switch speed and time, and w(t) over the run: the wheel drives from W0 down to the switch, then
    the worm."""
    t0_switch = J0 * T1 / (J1 * I_RATIO)
    w_switch = WS * (1 - t0_switch / TS)
    w_inf_i, b_i, before = phase(PSI_I, W0)
    t_switch = math.log((W0 - w_inf_i) / (w_switch - w_inf_i)) / b_i
    after = phase(PSI_T, w_switch)[2]
    return {"motor_at_switch": t0_switch, "w_switch": w_switch, "t_switch": t_switch,
            "w": lambda t: np.where(t < t_switch, before(t), after(t - t_switch))}


def test_the_hand_case_is_not_obvious_from_the_torques():
    """At the switch the motor still brakes (T_0 < 0) and the load resists (T_1 < 0): neither external torque
    says which side drives. Before it the wheel would decelerate slower than the worm were the mesh cut."""
    h = hand()
    assert h["motor_at_switch"] == pytest.approx(-0.054950, rel=1e-4) and h["w_switch"] == pytest.approx(154.121, rel=1e-5)
    motor_at_start = TS * (1 - W0 / WS)
    assert motor_at_start < 0 and motor_at_start / J0 < T1 / (I_RATIO * J1)   # the worm alone slows faster


def test_the_wheel_drives_then_the_worm_as_the_closed_form(chain_module):
    """msl108.toml: stage 1 inverse-tractive on flank b (the wheel's inertia drives the braking worm), then
    tractive on flank a at the closed form's switch time (1.0503 s), and the worm's speed over the whole run
    as the closed form's exponentials, to 1e-8."""
    module = chain_module((EXAMPLES / "msl108.toml").read_text())
    result = simulate_chain(module)
    h = hand()
    stage = result.stages[0]
    assert result.status == "finished"
    assert [(p.regime, p.flank) for p in stage.phases] == [("inverse-tractive", "b"), ("tractive", "a")]
    assert stage.switches[0] == pytest.approx(h["t_switch"], rel=1e-9) and h["t_switch"] == pytest.approx(1.0503, abs=1e-4)
    assert np.allclose(result.v0, h["w"](result.t), rtol=1e-8, atol=0.0)
    assert [e["outcome"] for e in result.events] == ["unique", "unique"]


def test_the_derived_switching_function_holds_no_friction_angle_of_its_own_stage():
    """The derivation's switching function phi_i (N_i's sign): for one stage it is free of rho_1 in both
    regimes, F_0 M_1 r_in tan(gamma) - F_1 M_0 r_out up to sign; in a two-stage chain phi_1 holds rho_2 and
    phi_2 holds rho_1 (the other stage's Psi), never its own."""
    from derivation.chain import dynamics as dyn

    one = dyn.symbols(1)
    hand_phi = one.force[0] * one.inertia[1] * one.lever_in[0] * sp.tan(one.gamma[0]) \
        - one.force[1] * one.inertia[0] * one.lever_out[0]
    for regime, sign in ((dyn.TRACTIVE, 1), (dyn.INVERSE, -1)):
        assert sp.simplify(dyn.sliding(1, (regime,)).switching[0] - sign * hand_phi) == 0
    two = dyn.symbols(2)
    for regimes in ((dyn.TRACTIVE, dyn.TRACTIVE), (dyn.INVERSE, dyn.TRACTIVE)):
        phi = dyn.sliding(1, regimes).switching
        assert two.rho[0] not in phi[0].free_symbols and two.rho[1] in phi[0].free_symbols
        assert two.rho[1] not in phi[1].free_symbols and two.rho[0] in phi[1].free_symbols


@pytest.mark.heavy
def test_tswm_simulate_and_derive_print_the_example(tmp_path, capsys, monkeypatch):
    """The CLI says "1 stage" (not "1 stages"), the regimes and the closed form's switch time."""
    from tswm_runtime.cli import main

    monkeypatch.setenv("TSWM_CACHE", str(tmp_path / "cache"))
    path = str(EXAMPLES / "msl108.toml")
    assert main(["derive", path]) == 0
    assert "msl108.toml): 1 stage (tswm simulate runs it)" in capsys.readouterr().out
    assert main(["simulate", path]) == 0
    out = capsys.readouterr().out
    assert out.startswith("chain msl108-overrun (1 stage, ")
    assert f"    switches at: {hand()['t_switch']:.9g} s" in out
    assert "    inverse-tractive  b  0 s .. " in out and "t = 0 s, start: (start) -> forward: inverse-tractive (b)" in out
