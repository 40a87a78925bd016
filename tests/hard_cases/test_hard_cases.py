"""Hard cases for the hybrid runtime, each with the behaviour expected of it.

Every case must finish (or stop with the status named), without chattering, and agree
with an independent reference where one exists (``reference``: hand formulas, DOP853).
"""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hard_cases import reference as ref
from tswm_runtime.reference import paper_gear as gear
from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN, simulate

PAPER = Path(__file__).parents[2] / "derivation" / "scenes" / "paper.toml"
TABLE3 = [(m2, F2) for m2 in (100.0, 200.0, 300.0) for F2 in (-5000.0, -10000.0, -15000.0)]


@pytest.mark.parametrize("m2, F2", TABLE3)
def test_table3_as_printed_sticks_in_the_consistent_model(m2, F2):
    """Load from t = 0: the starting force F1(0) = 727.6 N is below the breakaway force
    against every Table 3 load (1445 N for F2 = -5000 N), so the gear never moves: one
    stick phase, S1 = F1(0), S2 = F2 from statics. The paper's dynamic numbers for these
    scenes cannot come from the consistent model; its report says so."""
    assert gear.kloss(0.0) < gear.breakaway_F1(F2)
    r = simulate("paper", {"m2": m2, "F2": F2})
    assert r.status == "finished", r.message
    assert [ph.regime for ph in r.phases] == ["stick"] and r.events == []
    assert r.S1_max == pytest.approx(gear.kloss(0.0), rel=1e-12)
    assert r.S2_max == pytest.approx(F2, rel=1e-12)
    assert np.all(r.v1 == 0.0)


@pytest.mark.parametrize("F2", [-5000.0, -15000.0])
def test_run_up_then_load_stays_tractive_and_matches_the_reference(F2):
    """Free run-up, load applied at 0.3 s: phi > 0 throughout (F2 < 0), so the gear
    stays tractive (no flank switch) and slows to a new equilibrium speed."""
    r = simulate("paper-runup", {"F2_after": F2}, rtol=1e-10, atol=1e-12)
    assert r.status == "finished", r.message
    assert [ph.regime for ph in r.phases] == ["tractive"]
    assert [e.guard for e in r.events] == ["load_step"] and 0.3 <= r.events[0].t <= 0.3 + 1e-15
    _, v_free, sw1 = ref.run_flanks(1e-12, 0.0, 0.3, 0.0, 200.0, switches=False)
    t_ref, v_ref, sw2 = ref.run_flanks(v_free[-1], 0.3, 1.0, F2, 200.0, t_eval=[0.5, 1.0])
    assert sw1 == [] and sw2 == []
    assert r.v1[-1] == pytest.approx(v_ref[-1], rel=1e-8)
    assert r.S2_max == pytest.approx(min(gear.reactions(v, 1, F2, 200.0)[1] for v in np.linspace(v_ref[-1], v_free[-1], 2001)),
                                     rel=1e-5)


def test_no_load_run_up_reports_no_flank_switch():
    """F2 = 0: phi = F1 tan(gamma) / m1 tends to 0+ as v1 tends to V0. Generic solvers
    see spurious phi crossings in the numerical noise about V0; tswm must see none."""
    for method in ("dopri5", "rosenbrock23"):
        for rtol in (1e-3, 1e-4, 1e-6, 1e-8):
            r = simulate("paper", {"F2": 0.0}, method=method, rtol=rtol, atol=rtol * 1e-3)
            assert r.status == "finished" and r.events == [], (method, rtol, r.events)
            r = simulate("paper-runup", method=method, rtol=rtol, atol=rtol * 1e-3)
            assert [e.guard for e in r.events] == ["load_step"], (method, rtol, r.events)
    t_ref, v_ref, switches = ref.run_flanks(1e-9, 0.0, 1.0, 0.0, 200.0, t_eval=[0.02, 0.05, 1.0],
                                           switches=False)
    r = simulate("paper", {"F2": 0.0}, v1=1e-9, rtol=1e-10, atol=1e-13, points=101)
    assert switches == []
    np.testing.assert_allclose(np.interp([0.02, 0.05, 1.0], r.t, r.v1)[[2]], v_ref[[2]], rtol=1e-9)
    assert r.v1[2] == pytest.approx(v_ref[0], rel=1e-7)


@pytest.mark.parametrize("method", ["dopri5", "rosenbrock23"])
def test_decelerating_gear_comes_to_rest_and_self_locks(method):
    """Moving at 2 m/s against F2 = -15000 N: the drive cannot hold the speed, v1 falls to
    0 and the self-locking gear sticks (rho(0) = 11.4 deg > gamma). Naive sign(v) friction
    chatters about v1 = 0 here; tswm logs one event and stays at rest."""
    rtol = max(1e-10, METHOD_RTOL_MIN[method][0])   # rosenbrock23 from 1e-9
    r = simulate("paper", {"F2": -15000.0}, v1=2.0, method=method, rtol=rtol, atol=1e-12)
    assert r.status == "finished", r.message
    assert [(e.guard, e.to_mode) for e in r.events] == [("v1", "stick")]
    stop = lambda t, y: y[0]  # noqa: E731
    stop.terminal = True
    sol = solve_ivp(lambda t, y: [gear.accel(y[0], 1, -15000.0, 200.0)], (0, 1), [2.0], events=stop, **ref.TIGHT)
    accuracy = 1e-9 if method == "dopri5" else 1e-6
    assert r.events[0].t == pytest.approx(sol.t_events[0][0], rel=accuracy)
    assert np.all(r.v1[r.t > r.events[0].t] == 0.0)


def test_start_exactly_on_phi_zero_picks_the_flank_phi_moves_to():
    """F2 chosen so that phi(v1 = 7 m/s) = 0 at the start: v1 grows, F1 falls, phi turns
    negative, so the gear must start on flank b (inverse-tractive) with no event."""
    v0 = 7.0
    F2 = 200.0 * gear.kloss(v0) * math.tan(gear.GAMMA) / gear.M1
    r = simulate("paper", {"F2": F2}, v1=v0, rtol=1e-10, atol=1e-12)
    assert r.status == "finished", r.message
    assert r.events == [] and r.phases[0].regime == "inverse-tractive"
    sol = solve_ivp(lambda t, y: [gear.accel(y[0], -1, F2, 200.0)], (0, 1), [v0], **ref.TIGHT)
    assert r.v1[-1] == pytest.approx(sol.y[0, -1], rel=1e-9)


def test_over_heavy_driven_body_is_inconsistent_and_says_why():
    """Assisting load on flank b at low speed, m2 = 5000 kg: rho(0.05 m/s) = 8.3 deg >
    gamma, so D = m1 + m2 tan(gamma) tan(gamma - rho) < 0: no contact force fits the
    constraint (Painleve). Status 'inconsistent', naming the mode and the masses."""
    v0, m2, F2 = 0.05, 5000.0, 30000.0
    assert gear.phi(v0, F2, m2) < 0
    D = gear.M1 + m2 * math.tan(gear.GAMMA) * math.tan(gear.GAMMA - gear.rho(v0))
    assert D < 0
    r = simulate("paper", {"m2": m2, "F2": F2}, v1=v0)
    assert r.status == "inconsistent"
    assert "fwd_b" in r.message and "m2 = 5000" in r.message and f"{D:.6g}" in r.message


def test_speed_at_and_above_synchronous_speed():
    """v1 = V0 with F2 = 0 is an equilibrium (F1 = 0 in the safe Kloss form; the textbook
    form divides by zero): no event, v1 stays V0. From 8 m/s the motor brakes as a
    generator (F1 < 0, phi < 0: flank b) and v1 settles to V0 from above, no switch."""
    r = simulate("paper", {"F2": 0.0}, v1=gear.V0)
    assert r.status == "finished" and r.events == []
    np.testing.assert_allclose(r.v1, gear.V0, rtol=1e-12)
    r = simulate("paper", {"F2": 0.0}, v1=8.0)
    assert r.status == "finished" and r.events == [], r.events
    assert r.phases[0].regime == "inverse-tractive"
    assert r.v1[-1] == pytest.approx(gear.V0, rel=1e-6)


@pytest.mark.parametrize("method", ["dopri5", "rosenbrock23"])
def test_breakaway_with_the_non_lipschitz_friction_law(method):
    """From rest against F2 = -1000 N the drive exceeds the static cone at once; rho(v) ~
    |v|^0.535 is not Lipschitz at 0 (d rho/dv unbounded). Both methods must start, and
    agree with the reference started at v1 = 1e-12."""
    assert gear.kloss(0.0) > gear.breakaway_F1(-1000.0)
    r = simulate("paper", {"F2": -1000.0}, method=method, rtol=1e-9, atol=1e-12, points=11)
    assert r.status == "finished", r.message
    assert r.phases[0].regime == "tractive" and r.events == []
    _, v_ref, _ = ref.run_flanks(1e-12, 0.0, 1.0, -1000.0, 200.0, t_eval=r.t[1:])
    np.testing.assert_allclose(r.v1[1:], v_ref, rtol=1e-6 if method == "dopri5" else 1e-4)


@pytest.mark.heavy
def test_stiff_light_worm_both_methods_agree(scene_module):
    """m1 = 0.05 kg makes the run-up stiff (lambda ~ 1700 /s near V0): DOPRI5 would step at
    its stability limit on the equilibrium tail (~500 steps a second at any rtol); the tail
    is held instead (integration.steady), so its cost is flat in the simulated time; both
    methods agree with the reference at t_end to the accuracy asked."""
    text = PAPER.read_text().replace('m1 = "11.8 kg"', 'm1 = "0.05 kg"').replace('name = "paper"', 'name = "paper-light-worm"')
    scene = scene_module(text)
    _, v_ref, _ = ref.run_flanks(1e-12, 0.0, 1.0, -1000.0, 200.0, m1=0.05)
    for rtol, accuracy in ((1e-4, 1e-4), (1e-8, 1e-7)):
        runs = {m: simulate(scene, {"F2": -1000.0}, method=m, rtol=rtol, atol=rtol * 1e-3)
                for m in ("dopri5", "rosenbrock23")}
        for r in runs.values():
            assert r.status == "finished", r.message
            assert r.v1[-1] == pytest.approx(v_ref[-1], rel=accuracy)
    for m in ("dopri5", "rosenbrock23"):
        steps = [simulate(scene, {"F2": -1000.0}, method=m, rtol=1e-4, atol=1e-7, t_end=T).n_steps
                 for T in (1.0, 100.0)]
        assert steps[1] <= steps[0] + 2 and steps[0] < 150, (m, steps)   # flat in T, no stability-limit crawl


def test_torque_switch_seating_overshoots_and_self_locks():
    """Closing onto the seat spring: the switch trips when S1 reaches its set value, the
    drive is cut, the worm's inertia drives S1 past the trip value, v1 reaches 0 and
    the self-locking gear holds the thrust (stick, S1 = F1 = 0, S2 = spring force)."""
    r = simulate("seating")
    assert r.status == "finished", r.message
    kinds = [e.guard for e in r.events]
    assert kinds[:2] == ["load_contact", "torque_switch"] and kinds[-1] == "v1"
    assert r.phases[-1].regime == "stick"
    trip = next(e for e in r.events if e.guard == "torque_switch")
    assert r.extras["t_trip"] == trip.t
    assert abs(r.S1_max) > 1500.0                       # overshoot past the trip value
    held = r.t > r.events[-1].t
    assert np.all(r.F1[held] == 0.0) and np.all(r.v1[held] == 0.0)
    assert np.all(r.S2[held] == r.F2[held])             # statics: the spring is held
    F2 = r.F2[held][0]
    mu0 = math.tan(gear.rho(0.0))
    assert abs(F2 * math.sin(gear.GAMMA)) <= mu0 * abs(F2 * math.cos(gear.GAMMA))   # inside the cone


def _literal_phi(v, F2, m2):
    return ref.printed_phi(gear.kloss(v), F2, gear.M1, m2, gear.GAMMA)


def _literal_accel(v, flank, F2, m2):
    return ref.printed(flank, gear.kloss(v), F2, gear.rho(v), gear.M1, m2, gear.GAMMA)[0]


LITERAL_SLIDE = {"m2": 10.0, "F2": 9000.0}


def _literal_reference():
    """Run-up on flank b of the printed equations until their phi reaches 0 (DOP853)."""
    F2, m2 = LITERAL_SLIDE["F2"], LITERAL_SLIDE["m2"]
    reach = lambda t, y: _literal_phi(y[0], F2, m2)  # noqa: E731
    reach.terminal = True
    sol = solve_ivp(lambda t, y: [_literal_accel(y[0], -1, F2, m2)], (0, 1), [0.0], events=reach, **ref.TIGHT)
    t_hit, v_hit = sol.t_events[0][0], sol.y_events[0][0][0]
    # Filippov: on phi = 0 the printed equations push back from both sides.
    assert _literal_accel(v_hit, 1, F2, m2) < 0 < _literal_accel(v_hit, -1, F2, m2)
    return t_hit, v_hit


def test_paper_literal_slides_along_its_phi_zero_and_stops_when_excluded():
    """The printed equations jump across their phi = 0. With m2 = 10 kg and an assisting
    F2 = +9 kN (not a Table 3 case: for those the printed phi is crossed transversally),
    the gear runs up on flank b until phi = 0, where both sides push the state back:
    Filippov sliding. The shipped paper-literal scene excludes it, so the run stops with
    status 'sliding' at that instant instead of chattering across phi = 0."""
    t_hit, _ = _literal_reference()
    r = simulate("paper-literal", LITERAL_SLIDE, rtol=1e-10, atol=1e-12)
    assert r.status == "sliding" and "add 'sliding'" in r.message
    assert r.t_stop == pytest.approx(t_hit, rel=1e-8)
    assert len(r.events) == 1


@pytest.mark.heavy
def test_paper_literal_follows_the_sliding_motion_when_declared(scene_module):
    """Declared, the slide mode follows phi = 0: since the printed phi depends on v1
    only (constant load), the sliding motion holds v1 at the speed where phi = 0."""
    text = PAPER.with_name("paper-literal.toml").read_text().replace(
        'include = ["forward"]', 'include = ["forward", "sliding"]').replace(
        'name = "paper-literal"', 'name = "paper-literal-sliding"')
    t_hit, v_hit = _literal_reference()
    r = simulate(scene_module(text), LITERAL_SLIDE, rtol=1e-10, atol=1e-12)
    assert r.status == "finished", r.message
    assert [ph.regime for ph in r.phases] == ["inverse-tractive", "sliding along phi = 0"]
    assert r.events[0].t == pytest.approx(t_hit, rel=1e-8) and len(r.events) == 1
    sliding = r.t > t_hit
    np.testing.assert_allclose(r.v1[sliding], v_hit, rtol=1e-9)
    assert np.max(np.abs([_literal_phi(v, **{"F2": 9000.0, "m2": 10.0}) for v in r.v1[sliding]])) < 1e-6
