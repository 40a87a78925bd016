"""The mode machine against closed forms: a linear drive, constant friction and a step load.

With F1 = F0 (1 - v1/V0), a constant F2 and constant rho, every sliding mode is the
linear ODE a1 = alpha - beta v1, so v1(t), x1(t), the flank-switch time (phi = 0 at a
known speed), the time of rest and the stick statics all have closed forms, written
here by hand from the force balance (independently of the generated code).
"""
import math

import numpy as np
import pytest

from tswm_runtime.reference.paper_gear import cones
from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN, simulate

SCENE = """
name = "closed-form"
[wedge]
flanks = ["a", "b"]
gamma = { value = "10 deg", free = true }
m1 = { value = "2 kg", free = true }
m2 = { value = "20 kg", free = true }
[friction]
law = "constant"
rho = { value = "6 deg", free = true }
[drive]
law = "linear"
F0 = { value = "800 N", free = true }
V0 = { value = "0.5 m/s", free = true }
[load]
law = "step"
F2_before = { value = "0 N", free = true }
F2_after = { value = "0 N", free = true }
t_step = { value = "10 s", free = true }
[modes]
include = ["forward", "backward", "stick"]
[run]
t_end = "1 s"
"""
CONSTANT_DRIVE = 1e12  # V0 for a drive force that is constant to 1e-12 relative
TIGHT = dict(rtol=1e-10, atol=1e-13)


class Mode:
    """Hand-written closed form of sliding on flank f (+1 a, -1 b) in direction s."""

    def __init__(self, f, s, gamma, rho, m1, m2, F0, V0, F2):
        psi = math.tan(gamma + f * s * rho)
        m_eff = m1 + psi * m2 * math.tan(gamma)
        self.beta = F0 / (V0 * m_eff)
        self.alpha = (F0 + psi * F2) / m_eff
        self.v_inf = self.alpha / self.beta
        self.psi, self.m_eff, self.F2 = psi, m_eff, F2
        self.m1, self.m2, self.gamma, self.F0, self.V0 = m1, m2, gamma, F0, V0

    def v(self, t, v0):
        return self.v_inf + (v0 - self.v_inf) * np.exp(-self.beta * t)

    def x(self, t, v0):
        return self.v_inf * t + (v0 - self.v_inf) * (1 - np.exp(-self.beta * t)) / self.beta

    def time_to(self, v, v0):
        return -math.log((v - self.v_inf) / (v0 - self.v_inf)) / self.beta

    def S2(self, v):
        F1 = self.F0 * (1 - v / self.V0)
        return self.F2 - self.m2 * math.tan(self.gamma) * (F1 + self.psi * self.F2) / self.m_eff


def params(rho=math.radians(6), **kw):
    base = dict(gamma=math.radians(10), friction_rho=rho, m1=2.0, m2=20.0, F0=800.0, V0=0.5,
                F2_before=0.0, F2_after=0.0, t_step=10.0)
    base.update(kw)
    return base


def mode_of(p, f, s, F2):
    return Mode(f, s, p["gamma"], p["friction_rho"], p["m1"], p["m2"], p["F0"], p["V0"], F2)


@pytest.fixture(scope="module")
def model(scene_module):
    return scene_module(SCENE)


@pytest.mark.parametrize("method", ["dopri5", "rosenbrock23", "auto"])
def test_assisting_load_switches_flank_at_the_closed_form_time(model, method):
    p = params(F2_before=200.0, F2_after=200.0)
    v0 = 0.1
    a, b = mode_of(p, 1, 1, 200.0), mode_of(p, -1, 1, 200.0)
    F1_star = p["m1"] * 200.0 / (p["m2"] * math.tan(p["gamma"]))   # phi = 0
    v_star = p["V0"] * (1 - F1_star / p["F0"])
    assert v0 < v_star < a.v_inf, "the scene must reach the switch"
    t_star = a.time_to(v_star, v0)
    r = simulate(model, p, v1=v0, method=method, **{**TIGHT, "rtol": max(TIGHT["rtol"], METHOD_RTOL_MIN[method][0])})
    assert r.status == "finished", r.message
    assert [(e.guard, e.from_mode, e.to_mode) for e in r.events] == [("phi", "fwd_a", "fwd_b")]
    accuracy = 1e-6 if method == "rosenbrock23" else 1e-8   # ode23s is of order 2 (2749 steps here)
    assert r.events[0].t == pytest.approx(t_star, rel=accuracy)
    t_end = 1.0
    v_end = b.v(t_end - t_star, v_star)
    x_end = a.x(t_star, v0) + b.x(t_end - t_star, v_star)
    assert r.v1[-1] == pytest.approx(v_end, rel=accuracy)
    assert r.x1[-1] == pytest.approx(x_end, rel=accuracy)
    before = r.t < t_star
    np.testing.assert_allclose(r.v1[before], a.v(r.t[before], v0), rtol=accuracy)
    assert [ph.regime for ph in r.phases] == ["tractive", "inverse-tractive"]
    # S2 = 0 at the switch (the contact force vanishes), and S2 is continuous there.
    assert a.S2(v_star) == pytest.approx(0.0, abs=1e-9)
    assert r.S2_max == pytest.approx(max([a.S2(v0), b.S2(r.v1[-1])], key=abs), rel=1e-7)


def test_self_locking_wedge_stops_and_sticks(model):
    p = params(gamma=math.radians(4), rho=math.radians(8), F0=100.0, V0=CONSTANT_DRIVE,
               F2_before=-3000.0, F2_after=-3000.0)
    v0 = 0.2
    a = mode_of(p, 1, 1, -3000.0)
    decel = a.alpha  # beta ~ 0: constant deceleration
    assert decel < 0
    t_rest = v0 / -decel
    cone_f, cone_b = cones(100.0, -3000.0, p["gamma"], p["friction_rho"])
    assert cone_f > 0 and cone_b > 0, "the statics must hold the wedge"
    r = simulate(model, p, v1=v0, **TIGHT)
    assert r.status == "finished", r.message
    assert [(e.guard, e.to_mode) for e in r.events] == [("v1", "stick")]
    assert r.events[0].t == pytest.approx(t_rest, rel=1e-9)
    at_rest = r.t > t_rest
    assert np.all(r.v1[at_rest] == 0.0)
    np.testing.assert_allclose(r.x1[at_rest], v0 ** 2 / (2 * -decel), rtol=1e-9)
    np.testing.assert_allclose(r.S1[at_rest], 100.0, rtol=1e-9)     # statics: S1 = F1, S2 = F2
    np.testing.assert_allclose(r.S2[at_rest], -3000.0, rtol=1e-12)
    assert len(r.events) == 1, "no chattering at v1 = 0"


def test_non_locking_wedge_reverses_into_backward_sliding(model):
    p = params(gamma=math.radians(20), rho=math.radians(5), F0=100.0, V0=CONSTANT_DRIVE,
               F2_before=-3000.0, F2_after=-3000.0)
    v0 = 0.5
    fwd, bwd = mode_of(p, 1, 1, -3000.0), mode_of(p, 1, -1, -3000.0)
    t_rest = v0 / -fwd.alpha
    assert cones(100.0, -3000.0, p["gamma"], p["friction_rho"])[1] < 0, "the load must win backward"
    r = simulate(model, p, v1=v0, **TIGHT)
    assert r.status == "finished", r.message
    assert [(e.guard, e.to_mode) for e in r.events] == [("v1", "bwd_a")]
    assert r.events[0].t == pytest.approx(t_rest, rel=1e-9)
    assert r.v1[-1] == pytest.approx(bwd.alpha * (1.0 - t_rest), rel=1e-8)
    assert r.phases[-1].regime == "backward on flank a"


def test_load_step_breaks_a_stuck_wedge_away_at_the_step_time(model):
    p = params(gamma=math.radians(4), rho=math.radians(8), F0=500.0, V0=CONSTANT_DRIVE,
               F2_before=-3000.0, F2_after=-1000.0, t_step=0.1)
    assert min(cones(500.0, -3000.0, p["gamma"], p["friction_rho"])) > 0
    assert cones(500.0, -1000.0, p["gamma"], p["friction_rho"])[0] < 0
    after = mode_of(p, 1, 1, -1000.0)
    r = simulate(model, p, v1=0.0, **TIGHT)
    assert r.status == "finished", r.message
    assert r.phases[0].regime == "stick"
    # The step and the cone it breaks coincide; either guard may report the instant.
    [event] = r.events
    assert (event.from_mode, event.to_mode) == ("stick", "fwd_a")
    assert event.guard in ("load_step", "cone_forward")
    assert 0.1 <= event.t <= 0.1 + 1e-15      # hit, not stepped over
    assert r.v1[-1] == pytest.approx(after.alpha * 0.9, rel=1e-9)


def test_start_exactly_on_phi_zero_enters_the_right_flank_without_an_event(model):
    p = params()
    v0 = 0.2
    F1 = p["F0"] * (1 - v0 / p["V0"])
    F2 = p["m2"] * F1 * math.tan(p["gamma"]) / p["m1"]       # phi(v0) = 0
    p.update(F2_before=F2, F2_after=F2)
    b = mode_of(p, -1, 1, F2)
    assert b.alpha - b.beta * v0 > 0, "v1 grows, F1 falls: phi turns negative, flank b"
    r = simulate(model, p, v1=v0, **TIGHT)
    assert r.status == "finished", r.message
    assert r.events == [] and r.mode_names[r.mode[0]] == "fwd_b"
    assert r.v1[-1] == pytest.approx(b.v(1.0, v0), rel=1e-8)


def test_over_heavy_body_two_is_reported_inconsistent_naming_the_masses(model):
    p = params(gamma=math.radians(4.76), rho=math.radians(12), m2=5000.0, F0=100.0,
               V0=CONSTANT_DRIVE, F2_before=30000.0, F2_after=30000.0)
    b = mode_of(p, -1, 1, 30000.0)
    assert b.m_eff < 0, "D = m1 + m2 tan(gamma) tan(gamma - rho) must be negative"
    r = simulate(model, p, v1=0.1)
    assert r.status == "inconsistent"
    assert "fwd_b" in r.message and "m2 = 5000" in r.message and "m1 = 2" in r.message
    assert f"{b.m_eff:.6g}" in r.message


@pytest.mark.parametrize("method", ["dopri5", "rosenbrock23", "auto"])
def test_error_over_a_flank_switch_falls_in_proportion_to_rtol(model, method):
    """Errors of x1 and of the time at the switch against the closed form as rtol shrinks,
    and of x1(t_end) after the equilibrium tail (held: integration.steady).

    Error-per-step control of an order-p pair gives a global error ~ rtol^(p/(p+1)) for
    the lower-order solution and ~ rtol^1 with local extrapolation: DOPRI5 advances
    with its 5th-order solution (rate 1); ode23s advances with its 2nd-order one (rate 2/3
    alone), so its step tolerance is tightened below rtol 1e-3 (control.proportional_tolerance)
    to bring it to rate 1 too.
    """
    rate = 1.0
    p = params(F2_before=200.0, F2_after=200.0)
    a, b = mode_of(p, 1, 1, 200.0), mode_of(p, -1, 1, 200.0)
    v_star = p["V0"] * (1 - p["m1"] * 200.0 / (p["m2"] * math.tan(p["gamma"]) * p["F0"]))
    t_star = a.time_to(v_star, 0.1)
    x_end = a.x(t_star, 0.1) + b.x(1.0 - t_star, v_star)
    rtols = np.array([1e-4, 1e-5, 1e-6, 1e-7, 1e-8])
    runs = [simulate(model, p, v1=0.1, method=method, rtol=r, atol=r * 1e-3) for r in rtols]
    x_switch = a.x(t_star, 0.1)
    for errors in (np.array([abs(r.events[0].x1 - x_switch) / x_switch for r in runs]),
                   np.array([abs(r.events[0].t - t_star) / t_star for r in runs])):
        slope = np.polyfit(np.log(rtols), np.log(errors), 1)[0]
        assert np.all(np.diff(errors) < 0)
        assert slope == pytest.approx(rate, abs=0.15)
    assert all(abs(r.x1[-1] - x_end) / x_end < rtol for r, rtol in zip(runs, rtols))


@pytest.fixture(scope="module")
def one_sided_forward(scene_module):
    """The scene on flank a alone, sliding forward only: one module for both undeclared modes."""
    return scene_module(SCENE.replace('name = "closed-form"', 'name = "closed-form-one-sided-forward"')
                        .replace('flanks = ["a", "b"]', 'flanks = ["a"]')
                        .replace('include = ["forward", "backward", "stick"]', 'include = ["forward"]'))


def test_forward_only_scene_stops_at_rest_asking_for_stick(one_sided_forward):
    model = one_sided_forward
    p = params(gamma=math.radians(4), rho=math.radians(8), F0=100.0, V0=CONSTANT_DRIVE,
               F2_before=-3000.0, F2_after=-3000.0)
    t_rest = 0.2 / -mode_of(p, 1, 1, -3000.0).alpha
    r = simulate(model, p, v1=0.2, **TIGHT)
    assert r.status == "undeclared-mode"
    assert r.t_stop == pytest.approx(t_rest, rel=1e-9)
    assert "v1 reached 0 at t = " in r.message and "add 'stick'" in r.message
    assert [(e.guard, e.to_mode) for e in r.events] == [("v1", None)]


def test_one_sided_scene_names_lift_off_when_its_contact_force_vanishes(one_sided_forward):
    model = one_sided_forward
    p = params(F2_before=500.0, F2_after=500.0)     # assisting: phi = 0 at v_star below v_inf
    a = mode_of(p, 1, 1, 500.0)
    v_star = p["V0"] * (1 - p["m1"] * 500.0 / (p["m2"] * math.tan(p["gamma"]) * p["F0"]))
    assert 0.1 < v_star < a.v_inf
    r = simulate(model, p, v1=0.1, **TIGHT)
    assert r.status == "undeclared-mode" and "lift off" in r.message and "[wedge] flanks" in r.message
    assert r.t_stop == pytest.approx(a.time_to(v_star, 0.1), rel=1e-9)
