"""Lost motion with a stem: free travel, the pickup impulse through the wedge, bounces, carrying.

Every expected value is written by hand here from Newton's laws for three bodies (worm,
wheel, stem; constant forces, constant friction angle), never taken from tswm: the travel is
a parabola, a pickup is a linear impulse balance (Newton's restitution where the wedge keeps
sliding one way), one that stops the wedge inside the impulse is checked against a
brute-force march of the impulse, and a bouncing sequence is followed bounce by bounce.
"""
import math

import numpy as np
import pytest

from tswm_runtime.simulation.simulate import simulate

from hard_cases.reference import energy_residual, impact_drops
from hard_cases.test_impacts import COS, GAMMA, SIN, TIGHT, sliding_a_accel

TAN = SIN / COS
LAB = """
name = "pickup-lab"
[wedge]
flanks = ["a", "b"]
gamma = "10 deg"
m1 = { value = "10 kg", free = true }
m2 = { value = "100 kg", free = true }
[friction]
law = "constant"
rho = { value = "0 deg", free = true }
[drive]
law = "schedule"
variable = "t"
shape = "steps"
at = [{ value = "1 s", free = true }]
values = [{ value = "500 N", free = true }, { value = "500 N", free = true }]
[load]
law = "constant"
F2 = { value = "-2000 N", free = true }
[lost_motion]
travel = { value = "1 mm", free = true }
stem_mass = { value = "20 kg", free = true }
restitution = { value = 0.5, free = true }
[modes]
include = ["forward", "backward", "stick"]
[run]
t_end = "0.05 s"
v1 = "1 m/s"
rtol = 1e-10
atol = 1e-13
"""


@pytest.fixture(scope="module")
def lab(scene_module):
    return scene_module(LAB)


def params(**kw):
    base = {"m1": 10.0, "m2": 100.0, "friction_rho": 0.0, "drive_at1": 1.0, "F1_0": 500.0, "F1_1": 500.0,
            "F2": -2000.0, "lost_motion_travel": 1e-3, "lost_motion_stem_mass": 20.0, "lost_motion_restitution": 0.5}
    return {**base, **kw}


def kinetic(v1, v3, m1, m2, m3):
    return 0.5 * (m1 * v1**2 + m2 * (TAN * v1) ** 2 + m3 * v3**2)


def pickup_by_hand(v1, v3, m1, m2, m3, mu, e):
    """Newton's restitution (v3 - v2)+ = -e (v3 - v2)- with the wedge sliding forward on flank a
    throughout: impulse balance of worm (along x1), wheel (along x2, normal impulse N with
    friction mu N against its slip) and stem. Returns (v1+, v3+, P, kinetic energy lost)."""
    # unknowns dv1, N, P, dv3
    A = np.array([[m1, SIN + mu * COS, 0.0, 0.0],
                  [m2 * TAN, -(COS - mu * SIN), 1.0, 0.0],
                  [0.0, 0.0, -1.0, m3],
                  [-TAN, 0.0, 0.0, 1.0]])
    b = np.array([0.0, 0.0, 0.0, -(1.0 + e) * (v3 - TAN * v1)])
    dv1, N, P, dv3 = np.linalg.solve(A, b)
    assert N > 0.0 and P > 0.0
    return v1 + dv1, v3 + dv3, P, kinetic(v1, v3, m1, m2, m3) - kinetic(v1 + dv1, v3 + dv3, m1, m2, m3)


def first_pickup(v0, F1, m1, m2, mu, L):
    """Time and v1 when x2 = tan(gamma) x1 reaches L, sliding forward unloaded from x1 = 0."""
    a = sliding_a_accel(F1, 0.0, m1, m2, mu)
    x1 = L / TAN
    t = (-v0 + math.sqrt(v0 * v0 + 2 * a * x1)) / a if a else x1 / v0
    return t, v0 + a * t


@pytest.mark.heavy
@pytest.mark.parametrize("rho_deg, e", [(0.0, 0.0), (0.0, 1.0), (8.0, 0.0), (8.0, 0.6)])
def test_first_pickup_matches_the_impulse_balance(lab, rho_deg, e):
    mu = math.tan(math.radians(rho_deg))
    p = params(friction_rho=math.radians(rho_deg), lost_motion_restitution=e)
    r = simulate(lab, p, **TIGHT)
    t_p, v1_p = first_pickup(1.0, 500.0, 10.0, 100.0, mu, 1e-3)
    ev = r.impacts[0]
    assert ev.guard == "stem_gap" and ev.t == pytest.approx(t_p, rel=1e-9)
    v1_after, v3_after, P, lost = pickup_by_hand(v1_p, 0.0, 10.0, 100.0, 20.0, mu, e)
    assert ev.jump.v1_before == pytest.approx(v1_p, rel=1e-9)
    assert ev.v1 == pytest.approx(v1_after, rel=1e-9)
    assert ev.state["v3"] == pytest.approx(v3_after, rel=1e-9)
    assert ev.jump.P_n == pytest.approx(P, rel=1e-8)
    assert ev.jump.energy_lost == pytest.approx(lost, rel=1e-7, abs=1e-12)
    if e == 1.0 and mu == 0.0:
        assert abs(ev.jump.energy_lost) < 1e-9 * kinetic(v1_p, 0.0, 10.0, 100.0, 20.0)


def bounces_by_hand(p, n_max=200):
    """The bounce sequence bounce by bounce: after each pickup the stem flies under F2/m3 and
    body 2 slides unloaded, both at constant acceleration, until the gap closes again.
    Returns the impact times, v1 after each, and (t, v1) at the accumulation point."""
    m1, m2, m3, F1, F2 = p["m1"], p["m2"], p["lost_motion_stem_mass"], p["F1_0"], p["F2"]
    mu, e = math.tan(p["friction_rho"]), p["lost_motion_restitution"]
    t, v1 = first_pickup(1.0, F1, m1, m2, mu, p["lost_motion_travel"])
    v3 = 0.0
    a1, a3 = sliding_a_accel(F1, 0.0, m1, m2, mu), F2 / m3
    closing = a3 - TAN * a1                     # d2(gap)/dt2 in flight: < 0, the stem falls back
    times, v1s = [], []
    for _ in range(n_max):
        v1, v3, _, _ = pickup_by_hand(v1, v3, m1, m2, m3, mu, e)
        times.append(t)
        v1s.append(v1)
        nu = v3 - TAN * v1
        if nu < 1e-15:
            break
        dt = -2.0 * nu / closing
        t, v1, v3 = t + dt, v1 + a1 * dt, v3 + a3 * dt
    return times, v1s, (t, v1)


def test_bounces_follow_the_hand_sequence_and_end_in_carrying(lab):
    p = params(lost_motion_restitution=0.5)
    r = simulate(lab, p, **TIGHT)
    times, v1s, (t_inf, v1_inf) = bounces_by_hand(p)
    got = r.impacts
    assert r.status == "finished" and 8 <= len(got) < len(times)
    for ev, t, v1 in zip(got, times, v1s):
        assert ev.t == pytest.approx(t, abs=1e-10)
        if ev is not got[-1]:      # the last is taken as plastic: its rebound is within the tolerance
            assert ev.v1 == pytest.approx(v1, abs=1e-9)
    assert got[-1].t < t_inf and t_inf - got[-1].t < 1e-6
    # carried from there on: body 2 and the stem as one, under the load. Ending the bounces with a
    # plastic impact keeps the momentum, so the state meets the accumulation point's limit.
    a_carried = sliding_a_accel(500.0, -2000.0, 10.0, 120.0, 0.0)
    assert r.v1[-1] == pytest.approx(v1_inf + a_carried * (r.t[-1] - t_inf), abs=1e-11)
    assert r.v3[-1] == pytest.approx(TAN * r.v1[-1], abs=1e-12)
    assert r.x3[-1] == pytest.approx(r.x2[-1] - 1e-3, abs=1e-9)


def march_pickup(v1, v3, m1, m2, m3, mu, e, steps=400_000):
    """The pickup impulse by brute force: P in small steps, the wedge's rates from the impulse
    balance of the direction it slides in, or locked when its slip reaches 0 and the wedge is
    self-locking (tan rho >= tan gamma: no impulse on the wheel alone moves it), else sliding
    back; compression until v3 = v2, then restitution until its work is e^2 of compression's."""
    def rates(s):
        if s == 0:
            return 0.0, 1.0 / m3
        A = np.array([[m1, SIN + s * mu * COS], [m2 * TAN, -(COS - s * mu * SIN)]])
        dv1 = np.linalg.solve(A, [0.0, -1.0])[0]
        return dv1, 1.0 / m3 - TAN * dv1
    nu0 = v3 - TAN * v1
    dP = -nu0 / rates(1)[1] * 4.0 / steps
    P = work_c = work_r = 0.0
    s, compressing = 1, True
    while True:
        dv1, dnu = rates(s)
        nu = v3 - TAN * v1
        if compressing and nu + dnu * dP >= 0.0:
            compressing = False
        if not compressing and work_r + nu * dP > e * e * -work_c:
            break
        if compressing:
            work_c += (nu + 0.5 * dnu * dP) * dP
        else:
            work_r += (nu + 0.5 * dnu * dP) * dP
        v1 += dv1 * dP
        v3 += dP / m3
        P += dP
        if s != 0 and v1 * s <= 0.0:
            s, v1 = (0, 0.0) if mu >= TAN else (-s, v1)
    return v1, v3, P


@pytest.mark.heavy
@pytest.mark.parametrize("rho_deg", [20.0, 4.0])
def test_a_heavy_stem_stops_or_reverses_the_wedge_inside_the_impulse(lab, rho_deg):
    """e = 1, stem 50x the wheel: the rebound drives the wheel back through v1 = 0. A self-locking
    wedge (rho = 20 deg > gamma) locks there; at rho = 4 deg it slides back."""
    mu = math.tan(math.radians(rho_deg))
    p = params(friction_rho=math.radians(rho_deg), lost_motion_restitution=1.0, lost_motion_stem_mass=5000.0,
               F1_0=0.0, F1_1=0.0)
    r = simulate(lab, p, **TIGHT)
    ev = r.impacts[0]
    v1_hand, v3_hand, P_hand = march_pickup(1.0, 0.0, 10.0, 100.0, 5000.0, mu, 1.0)
    assert ev.jump.v1_before == pytest.approx(1.0, rel=1e-12)
    if mu >= TAN:
        assert ev.v1 == 0.0 and v1_hand == 0.0
    else:
        assert ev.v1 < 0.0 and ev.v1 == pytest.approx(v1_hand, rel=1e-4)
    assert ev.state["v3"] == pytest.approx(v3_hand, rel=1e-4)
    assert ev.jump.P_n == pytest.approx(P_hand, rel=1e-4)
    assert ev.jump.energy_lost >= 0.0
    assert ev.jump.energy_lost == pytest.approx(
        kinetic(1.0, 0.0, 10.0, 100.0, 5000.0) - kinetic(ev.v1, ev.state["v3"], 10.0, 100.0, 5000.0), abs=1e-9)


def test_no_travel_carries_the_stem_from_the_start(lab):
    """Travel 0: the wheel starts at the stem and carries it; the motion is the rigid wedge's with
    m2 + m3 and the load from t = 0, a1 constant."""
    p = params(lost_motion_travel=0.0, friction_rho=math.radians(5.0))
    r = simulate(lab, p, **TIGHT)
    a = sliding_a_accel(500.0, -2000.0, 10.0, 120.0, math.tan(math.radians(5.0)))
    assert r.status == "finished" and not r.impacts
    assert r.v1 == pytest.approx(1.0 + a * r.t, abs=1e-9)
    assert r.v3 == pytest.approx(TAN * r.v1, abs=1e-9)


def test_the_stem_leaves_when_the_wheel_brakes_harder_than_its_load(lab):
    """The drive reverses at 20 ms (500 N -> -8000 N): the wheel decelerates faster than the load
    alone decelerates the stem (F2/m3 = -100 m/s^2), so the stem leaves it at once and flies on
    its own: x3 a parabola under F2/m3 from there."""
    p = params(lost_motion_restitution=0.0, drive_at1=0.02, F1_1=-8000.0)
    r = simulate(lab, p, points=2001, **TIGHT)
    release = [ev for ev in r.events if ev.guard == "drive_at1"]
    assert len(release) == 1 and release[0].t == pytest.approx(0.02, abs=1e-12)
    t_s = release[0].t
    v3_s, x3_s = release[0].state["v3"], release[0].state["x3"]
    a1 = sliding_a_accel(-8000.0, 0.0, 10.0, 100.0, 0.0)
    assert TAN * a1 < -100.0
    flight = (r.t > t_s) & (r.t < t_s + 0.002)
    dt = r.t[flight] - t_s
    assert r.x3[flight] == pytest.approx(x3_s + v3_s * dt - 50.0 * dt**2, abs=1e-10)
    assert r.v1[flight] == pytest.approx(release[0].v1 + a1 * dt, abs=1e-8)


def test_energy_audit_over_the_lost_motion_scene():
    """Work of F1 and of the load on the stem = kinetic energy change of all three bodies +
    friction dissipation in the wedge (S1 v1 + S2 v2) + pickup losses, over the shipped scene."""
    r = simulate("lost-motion", points=40001, **TIGHT)
    assert r.status == "finished" and len(r.impacts) > 3
    m1, m2, m3 = r.model["fixed_params"]["m1"], r.params["m2"], r.params["lost_motion_stem_mass"]
    K = 0.5 * (m1 * r.v1**2 + m2 * r.v2**2 + m3 * r.v3**2)
    power_in = r.F1 * r.v1 + r.F2 * r.v3     # the held stem does not move: the load does no work on it
    absorbed = r.S1 * r.v1 + r.S2 * r.v2
    residual, total = energy_residual(r, K, power_in, absorbed)
    assert abs(residual) < 1e-6 * total
    # across each impact the kinetic energy falls by the reported loss; impacts closer than two
    # rows to another event are skipped
    dt = r.t[1] - r.t[0]
    isolated = [ev for ev in r.impacts if min(abs(ev.t - other.t) for other in r.events if other is not ev) > 2 * dt]
    assert len(isolated) >= 2
    for drop, lost, slack in impact_drops(r, K, power_in - absorbed, isolated):
        assert drop == pytest.approx(lost, abs=slack)


def test_a_pickup_that_cannot_stop_the_stem_jams(lab):
    """Sliding backward on a self-locking wedge, an impulse on the wheel pushes v1 up towards 0
    (dv1/dP = -tan(gamma - rho) / D > 0), so the wheel gives way forward: with a heavy stem
    falling back onto it, d(v3 - v2)/dP = 1/m3 - tan(gamma) dv1/dP <= 0 and no impulse stops the
    approach (the impulse counterpart of D <= 0). Written by hand; the run's message names it."""
    from tswm_runtime.simulation.simulate import parameter_vector
    from tswm_runtime.hybrid.impact import JAMMED, OK, pickup
    from tswm_runtime.hybrid.machine import INCONSISTENT, NEED_NOTHING
    from tswm_runtime.results.result import Event, Jump, status_message
    rho = math.radians(30.0)
    for m3, jams in ((5000.0, True), (20.0, False)):
        p = parameter_vector(lab, params(friction_rho=rho, lost_motion_stem_mass=m3))
        psi = math.tan(GAMMA - rho)
        rate = 1.0 / m3 - TAN * (-psi / (10.0 + psi * 100.0 * TAN))
        assert (rate <= 0.0) == jams
        frame = np.empty(12)
        lab.impact(0, 0.0, np.array([0.0, 0.0, -1.0, -0.5]), p, frame)   # v3 = -1 behind v2 = -0.5 tan
        assert frame[4] == pytest.approx(rate, rel=1e-12)
        assert pickup(frame)[4] == (JAMMED if jams else OK)
    events = [Event(0.01, "stem_gap", "bwd_a", None, 0.0, -0.5, Jump(0.0, 0.0, 0.0, -0.5), {})]
    text = status_message(lab, INCONSISTENT, 0.01, np.zeros(4), 2, NEED_NOTHING, events, p)
    assert "strikes the stem and the wedge jams" in text



def test_a_sweep_counts_the_pickups_and_their_energy(lab):
    """The sweep's impacts and impact_energy columns against the hand pickup: e = 0 picks the stem
    up in one impact (rigid wedge, rho = 5 deg) for any travel; e = 1 without friction bounces
    and loses nothing but the last, plastic, bounce's speck of energy."""
    from tswm_runtime.simulation.simulate import settings
    from tswm_runtime.sweeps.rows import run_cases

    rho = math.radians(5.0)
    cases = [dict(lost_motion_travel=L, friction_rho=rho, lost_motion_restitution=0.0) for L in (1e-3, 3e-3)]
    cases.append(dict(lost_motion_restitution=1.0))
    rows = [[params(**c)[n] for n in lab.PARAM_NAMES] for c in cases]
    table = run_cases(lab, np.array(rows), settings(lab, TIGHT))
    assert list(table["status"]) == ["finished"] * 3
    for k, L in enumerate((1e-3, 3e-3)):
        _, v1 = first_pickup(1.0, 500.0, 10.0, 100.0, math.tan(rho), L)
        lost = pickup_by_hand(v1, 0.0, 10.0, 100.0, 20.0, math.tan(rho), 0.0)[3]
        assert table["impacts"][k] == 1 and table["impact_energy"][k] == pytest.approx(lost, rel=1e-9)
    _, v1 = first_pickup(1.0, 500.0, 10.0, 100.0, 0.0, 1e-3)
    assert table["impacts"][2] > 3 and table["impact_energy"][2] < 1e-6 * kinetic(v1, 0.0, 10.0, 100.0, 20.0)
