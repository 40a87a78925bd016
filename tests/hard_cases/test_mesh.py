"""Compliant flanks (a spring-damper mesh along the normal) and their stiff limit.

Expected values are independent of tswm: with constant forces and no friction the normal
motion in contact is one-dimensional, gap'' = a_n - W_nn N with N = k overlap + c
overlap' (W_nn = sin^2/m1 + cos^2/m2 written by hand), solved here by scipy's DOP853 at
rtol 1e-12; the approach speed is the closed-form free flight of test_impacts.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tswm_runtime.simulation.simulate import simulate

from hard_cases.test_impacts import COS, LAB, SIN, normal_accel

# heavy: two scenes compiled for this file alone and stiff runs at tight tolerances; CI runs it after the default set
pytestmark = pytest.mark.heavy

MESH_LAB = LAB.replace('name = "impact-lab"', 'name = "mesh-lab"').replace(
    "[impact]\nrestitution = { value = 0.5, free = true }\n",
    '[mesh]\nstiffness = { value = "1e8 N/m", free = true }\ndamping = { value = "1e3 N s/m", free = true }\n')
TIGHT = {"rtol": 1e-10, "atol": 1e-13}
M1, M2, F1, CLEAR = 10.0, 100.0, 50.0, 1e-4
W_NN = SIN**2 / M1 + COS**2 / M2


@pytest.fixture(scope="module")
def mesh_lab(scene_module):
    return scene_module(MESH_LAB)


@pytest.fixture(scope="module")
def rigid_lab(scene_module):
    return scene_module(LAB)


def params(**kw):
    """Constant forces pushing body 2 toward flank b; runs start in free flight mid-gap."""
    base = {"m1": M1, "m2": M2, "clearance": CLEAR, "friction_rho": 0.0, "F1": F1, "load_at1": 0.04,
            "load_at2": 0.05, "F2_0": 2000.0, "F2_1": 2000.0, "F2_2": 2000.0}
    return {**base, **kw}


START = {"gap": CLEAR / 2, "v1": 1.0}


def damping_for(k, zeta):
    """Damping for the ratio zeta on the mesh mass 1 / W_nn."""
    return 2.0 * zeta * math.sqrt(k / W_NN)


def contact_reference(k, c, nu_in, a_n):
    """The first contact on flank b by hand: overlap d = gap - clearance from 0 with rate
    nu_in, d'' = a_n - W_nn (k d + c d') until the force k d + c d' falls back to 0.
    Returns (duration, outgoing gap rate, peak force)."""
    def rhs(t, z):
        return [z[1], a_n - W_NN * (k * z[0] + c * z[1])]

    def released(t, z):
        return k * z[0] + c * z[1]
    released.terminal, released.direction = True, -1
    period = math.pi * math.sqrt(1.0 / (k * W_NN))
    sol = solve_ivp(rhs, (0.0, 20 * period), [0.0, nu_in], method="DOP853", rtol=1e-12, atol=1e-16,
                    events=released, dense_output=True, first_step=period * 1e-4)
    t_end = sol.t_events[0][0]
    tt = np.linspace(0.0, t_end, 4001)
    z = sol.sol(tt)
    return t_end, sol.y_events[0][0][1], float(np.max(k * z[0] + c * z[1]))


def approach():
    """Time and normal speed of the first arrival on flank b: from mid-gap at rest along the
    normal, the gap's free flight is a parabola."""
    a_n = normal_accel(F1, 2000.0, M1, M2)
    tau = math.sqrt(2.0 * (CLEAR / 2) / a_n)
    return tau, a_n * tau, a_n


@pytest.mark.parametrize("k", [1e8, 1e10])
def test_first_mesh_contact_against_the_one_dimensional_reference(mesh_lab, k):
    """Free flight from mid-gap, then a compliant contact on flank b: its start, duration and
    release speed match the 1-D spring-damper reference."""
    c = damping_for(k, 0.2)
    r = simulate(mesh_lab, params(mesh_stiffness=k, mesh_damping=c), t_end=0.02, **START, **TIGHT)
    assert r.status == "finished", r.message
    t_in, nu_in, a_n = approach()
    duration, nu_out, _ = contact_reference(k, c, nu_in, a_n)
    enter = next(e for e in r.events if e.guard == "gap_b")
    leave = next(e for e in r.events if e.guard == "mesh_normal" and e.t > enter.t)
    assert r.phases[0].mode == "free" and enter.to_mode == "mesh_fwd_b" and leave.to_mode == "free"
    assert enter.t == pytest.approx(t_in, rel=1e-9)
    assert leave.t - enter.t == pytest.approx(duration, rel=1e-6)
    assert leave.state["gap_rate"] == pytest.approx(nu_out, rel=1e-6)
    assert r.impacts == []  # compliant flanks overlap, they do not collide


def test_stiff_mesh_converges_to_the_rigid_impact(mesh_lab, rigid_lab):
    """With the damping ratio held, a stiffer mesh shortens the contact like 1/sqrt(k); the
    rebound ratio tends to the spring-damper's e(zeta) and the motion to the rigid model's
    with that restitution, while the peak force grows like sqrt(k): the rigid limit is an
    impulse (P_n = (1 + e) |nu| / W_nn), not a force."""
    t_in, nu_in, a_n = approach()
    _, nu_e, _ = contact_reference(1e12, damping_for(1e12, 0.2), nu_in, 0.0)
    e = -nu_e / nu_in                               # the rebound ratio of the bare spring-damper
    rigid = simulate(rigid_lab, {**params(), "restitution": e}, t_end=0.02, **START, **TIGHT)
    t_probe = 0.0175
    v_rigid = float(np.interp(t_probe, rigid.t, rigid.v1))
    errors, durations, peaks, rebound = [], [], [], []
    stiffness = (1e8, 1e9, 1e10, 1e11)
    for k in stiffness:
        c = damping_for(k, 0.2)
        r = simulate(mesh_lab, params(mesh_stiffness=k, mesh_damping=c), t_end=0.02, **START, **TIGHT)
        enter = next(ev for ev in r.events if ev.guard == "gap_b")
        leave = next(ev for ev in r.events if ev.guard == "mesh_normal" and ev.t > enter.t)
        durations.append(leave.t - enter.t)
        rebound.append(abs(-leave.state["gap_rate"] / nu_in - e))
        errors.append(abs(float(np.interp(t_probe, r.t, r.v1)) - v_rigid))
        peaks.append(contact_reference(k, c, nu_in, a_n)[2])
        # S2 = -R2, the mesh force's component along x2: N cos(gamma) without friction
        assert abs(r.S2_max) == pytest.approx(peaks[-1] * COS, rel=1e-3)
    # the load's own push during the contact is what separates the two: it fades like 1/sqrt(k)
    assert all(b < a for a, b in zip(rebound, rebound[1:])) and rebound[-1] < 0.02
    # v1 later on: from 0.28 m/s apart at k = 1e8 to the level the rigid run's bounce tolerance sets
    assert errors[0] > 1e4 * errors[-1] and max(errors[1:]) < 1e-5 * abs(v_rigid)
    scaled = np.array(durations) * np.sqrt(stiffness)      # contact time x sqrt(k) settles
    assert np.all(np.diff(scaled) < 0) and scaled[-2] == pytest.approx(scaled[-1], rel=0.05)
    ratio = np.array(peaks) / np.sqrt(stiffness)           # peak force / sqrt(k) settles: it grows
    assert ratio[-2] == pytest.approx(ratio[-1], rel=0.05)
    P_rigid = (1 + e) * nu_in / W_NN
    assert rigid.impacts[0].jump.P_n == pytest.approx(P_rigid, rel=1e-6)
