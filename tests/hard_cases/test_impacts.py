"""Clearance between the flanks: free flight, separation, impacts, accumulation, grazing.

Every expected value is written by hand here from Newton's laws for two bodies on
perpendicular guides (constant forces, constant friction angle), never taken from tswm:
free flight is a parabola, a frictionless impact is a 1-D impulse along the flank normal,
a frictional one is checked against a brute-force integration of the impulse (the
relative velocity marched in tiny normal-impulse steps with Coulomb's law), and a
bouncing sequence under constant forces accumulates at a time known in closed form.
"""
import math

import numpy as np
import pytest

from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.hybrid.impact import OK, collide

from hard_cases.reference import energy_residual, impact_drops

GAMMA = math.radians(10.0)
SIN, COS = math.sin(GAMMA), math.cos(GAMMA)
# One module serves every case: the forces, masses, friction angle, clearance, restitution and
# the times of the load's two steps are free.
LAB = """
name = "impact-lab"
[wedge]
flanks = ["a", "b"]
gamma = "10 deg"
m1 = { value = "10 kg", free = true }
m2 = { value = "100 kg", free = true }
clearance = { value = "0.1 mm", free = true }
[impact]
restitution = { value = 0.5, free = true }
[friction]
law = "constant"
rho = { value = "0 deg", free = true }
[drive]
law = "constant"
F1 = { value = "0 N", free = true }
[load]
law = "schedule"
variable = "t"
shape = "steps"
at = [{ value = "0.01 s", free = true }, { value = "0.02 s", free = true }]
values = [{ value = "-100 N", free = true }, { value = "2000 N", free = true }, { value = "2000 N", free = true }]
[modes]
include = ["forward", "backward", "stick"]
[run]
t_end = "0.05 s"
v1 = "1 m/s"
rtol = 1e-10
atol = 1e-13
"""
TIGHT = {"rtol": 1e-10, "atol": 1e-13}


@pytest.fixture(scope="module")
def lab(scene_module):
    return scene_module(LAB)


def params(**kw):
    base = {"m1": 10.0, "m2": 100.0, "clearance": 1e-4, "restitution": 0.5, "friction_rho": 0.0, "F1": 0.0,
            "load_at1": 0.01, "load_at2": 0.02, "F2_0": -100.0, "F2_1": 2000.0, "F2_2": 2000.0}
    return {**base, **kw}


def normal_accel(F1, F2, m1, m2):
    """d(gap rate)/dt in free flight: body 2's own acceleration along the flank normal
    (cos gamma) less body 1's (sin gamma)."""
    return F2 / m2 * COS - F1 / m1 * SIN


def sliding_a_accel(F1, F2, m1, m2, mu):
    """a1 sliding forward on flank a: Newton for both bodies with the contact force N along
    n = (sin, cos) on body 2 and friction mu N against its slip along t = (-cos, sin)."""
    # m1 a1 = F1 - N (sin + mu cos); m2 tan(gamma) a1 = F2 + N (cos - mu sin)
    A = np.array([[m1, SIN + mu * COS], [m2 * SIN / COS, -(COS - mu * SIN)]])
    a1, _ = np.linalg.solve(A, [F1, F2])
    return a1


def frictionless_impulse(nu, m1, m2, e):
    """Normal impulse of a frictionless impact with approach speed nu < 0: the relative
    normal speed changes by P (sin^2/m1 + cos^2/m2) and ends at -e nu."""
    return -(1.0 + e) * nu / (SIN**2 / m1 + COS**2 / m2)


# --- free flight, separation and the first impact ---------------------------------------------


@pytest.mark.parametrize("e", [0.0, 1.0])
def test_separation_free_flight_and_first_impact_closed_form(lab, e):
    """Sliding on flank a until the load reverses at t_s, then a parabola in the gap, then an
    impact on flank b: e = 0 ends the normal motion, e = 1 keeps the kinetic energy."""
    m1, m2, F1, c = 10.0, 100.0, 50.0, 1e-4
    pr = params(F1=F1, restitution=e, F2_1=2000.0, F2_2=2000.0, load_at2=0.04)
    r = simulate(lab, pr, t_end=0.03, **TIGHT)
    t_s = 0.01
    a1 = sliding_a_accel(F1, -100.0, m1, m2, 0.0)
    v1_s = 1.0 + a1 * t_s
    a_n = normal_accel(F1, 2000.0, m1, m2)
    tau = math.sqrt(2.0 * c / a_n)
    v1_b, v2_b = v1_s + F1 / m1 * tau, v1_s * SIN / COS + 2000.0 / m2 * tau
    nu = -(v2_b * COS - v1_b * SIN)           # flank b: approaching while the gap grows
    P = frictionless_impulse(nu, m1, m2, e)
    v1_a, v2_a = v1_b + P * SIN / m1, v2_b - P * COS / m2
    lost = 0.5 * (m1 * (v1_b**2 - v1_a**2) + m2 * (v2_b**2 - v2_a**2))

    assert [(ev.guard, ev.from_mode, ev.to_mode) for ev in r.events[:2]] == [
        ("load_at1", "fwd_a", "free"), ("gap_b", "free", "fwd_b" if e == 0.0 else "free")]
    hit = r.events[1]
    assert hit.t == pytest.approx(t_s + tau, rel=1e-9)
    assert hit.jump.v1_before == pytest.approx(v1_b, rel=1e-9)
    assert hit.v1 == pytest.approx(v1_a, rel=1e-9)
    assert hit.jump.P_n == pytest.approx(P, rel=1e-7)
    assert hit.jump.P_t == 0.0
    assert hit.jump.energy_lost == pytest.approx(lost, rel=1e-6, abs=1e-9 * 0.5 * m2 * v2_b**2)
    if e == 1.0:
        assert abs(hit.jump.energy_lost) < 1e-9 * 0.5 * m2 * v2_b**2
        # the next impact on b after a parabola of the same height: 2 |nu| / a_n later
        assert r.events[2].guard == "gap_b"
        assert r.events[2].t == pytest.approx(hit.t + 2.0 * abs(nu) / a_n, rel=1e-8)


def test_bounces_accumulate_at_the_closed_form_time(lab):
    """e = 0.5 under constant forces: flights of 2 e^k nu1 / a_n; persistent contact from
    t_inf = t1 + 2 e |nu1| / (a_n (1 - e)), within the time the velocity tolerance allows."""
    m1, m2, F1, c, e = 10.0, 100.0, 50.0, 1e-4, 0.5
    pr = params(F1=F1, restitution=e, load_at2=0.04)
    r = simulate(lab, pr, t_end=0.035, max_events=1000, **TIGHT)
    assert r.status == "finished", r.message
    a_n = normal_accel(F1, 2000.0, m1, m2)
    tau = math.sqrt(2.0 * c / a_n)
    nu1 = a_n * tau
    t1 = 0.01 + tau
    t_inf = t1 + 2.0 * e * nu1 / (a_n * (1.0 - e))
    hits = [ev for ev in r.events if ev.guard == "gap_b"]
    expected = [t1 + 2.0 * e * nu1 / a_n * (1 - e**k) / (1 - e) for k in range(len(hits))]
    assert np.allclose([h.t for h in hits], expected, rtol=0, atol=1e-10)
    assert hits[-1].to_mode == "fwd_b" and all(h.to_mode == "free" for h in hits[:-1])
    # The bounces stop where the next one would rise less than the gap's tolerance above the
    # flank: nu^2 / (2 a_n) <= atol + rtol clearance. What is left of the sequence lasts
    # 2 nu / (a_n (1 - e)) at most.
    nu_tol = math.sqrt(2.0 * a_n * (TIGHT["atol"] + TIGHT["rtol"] * c))
    assert 0.0 <= t_inf - hits[-1].t <= 2.0 * nu_tol / (a_n * (1.0 - e)) * (1 + 1e-6)
    assert len(hits) <= 1 + math.log(nu_tol / nu1) / math.log(e) + 2
    # every impact loses energy: (1 - e^2) of the normal kinetic energy in a frictionless one
    assert all(h.jump.energy_lost > 0.0 for h in hits)


# --- friction in the impulse --------------------------------------------------------------------


def impulse_by_brute_force(nu, s, W, mu, e, steps=200_000):
    """Routh's process marched in small normal-impulse steps: Coulomb friction opposes the
    slip (or holds it at 0 when the stick ratio is inside the cone), compression ends at
    nu = 0, restitution ends when e^2 of the compression work is returned."""
    nu0 = nu
    dP = 2.5 * abs(nu0) / W[0, 0] / steps
    work = 0.0
    compressing, target = True, None
    Pn = Pt = 0.0
    for _ in range(50 * steps):
        if abs(s) < 1e-12 * max(1.0, abs(nu0)) and abs(W[0, 1] / W[1, 1]) <= mu:
            dPt = -W[0, 1] / W[1, 1] * dP
        else:
            dPt = -mu * math.copysign(1.0, s if s != 0 else W[0, 1]) * dP
        nu_new = nu + W[0, 0] * dP + W[0, 1] * dPt
        s_new = s + W[0, 1] * dP + W[1, 1] * dPt
        if s != 0 and s * s_new < 0 and abs(W[0, 1] / W[1, 1]) <= mu:
            s_new = 0.0
        work += 0.5 * (nu + nu_new) * dP
        Pn, Pt, nu, s = Pn + dP, Pt + dPt, nu_new, s_new
        if compressing and nu >= 0:
            compressing, target = False, (1 - e * e) * work
            if e == 0:
                break
        if not compressing and work >= target:
            break
    return Pn, Pt, nu, s


@pytest.mark.parametrize("case", [(-1.0, 0.05, 0.4, 0.0), (-1.0, 0.05, 0.4, 0.7), (-1.0, 0.6, 0.3, 0.5),
                                  (-0.5, -0.2, 0.1, 0.9), (-1.0, 0.0, 0.5, 0.3), (-1.0, 0.3, 0.0, 1.0)])
def test_frictional_impulse_matches_brute_force(case):
    """The piecewise-exact Routh process against small-step integration of the impulse."""
    nu, s, mu, e = case
    m1, m2 = 10.0, 100.0
    W = np.array([[SIN**2 / m1 + COS**2 / m2, SIN * COS * (1 / m2 - 1 / m1)],
                  [SIN * COS * (1 / m2 - 1 / m1), COS**2 / m1 + SIN**2 / m2]])
    Pn, Pt, nu1, s1, lost, outcome = collide(nu, s, W[0, 0], W[0, 1], W[1, 1], mu, e)
    assert outcome == OK
    ref = impulse_by_brute_force(nu, s, W, mu, e)
    scale = abs(nu) / W[0, 0]
    assert Pn == pytest.approx(ref[0], abs=1e-4 * scale)
    assert Pt == pytest.approx(ref[1], abs=1e-4 * scale)
    assert nu1 == pytest.approx(ref[2], abs=1e-4)
    assert s1 == pytest.approx(ref[3], abs=1e-4)
    A = np.linalg.inv(W)
    K = lambda u: 0.5 * u @ A @ u  # noqa: E731  kinetic energy in the flank frame
    assert lost == pytest.approx(K(np.array([nu, s])) - K(np.array([nu1, s1])), rel=1e-9, abs=1e-12)
    assert lost >= 0.0 and abs(Pt) <= mu * Pn * (1 + 1e-12)


def test_newtons_law_with_a_stick_impulse_would_create_energy():
    """Why the energetic coefficient: at the paper gear's masses, Newton's nu+ = -e nu- with
    the slip stopped by an impulse inside the cone gains kinetic energy; tswm's does not."""
    m1, m2, g = 11.8, 200.0, math.radians(4.76)
    sn, cs = math.sin(g), math.cos(g)
    W = np.array([[sn**2 / m1 + cs**2 / m2, sn * cs * (1 / m2 - 1 / m1)],
                  [sn * cs * (1 / m2 - 1 / m1), cs**2 / m1 + sn**2 / m2]])
    A = np.linalg.inv(W)
    u0 = np.array([-1.0, 0.5])
    newton = np.array([1.0, 0.0])                       # e = 1, slip stopped
    P = A @ (newton - u0)
    mu = math.tan(math.radians(11.36))
    assert abs(P[1]) <= mu * P[0]                       # the stick impulse is inside the cone
    assert 0.5 * newton @ A @ newton > 0.5 * u0 @ A @ u0   # ... and Newton's law gains energy
    *_, lost, outcome = collide(u0[0], u0[1], W[0, 0], W[0, 1], W[1, 1], mu, 1.0)
    assert outcome == OK and lost >= 0.0


def test_impact_inside_the_stick_cone_with_e_0_stops_both_bodies(lab):
    """Body 2 falls onto flank a with body 1 at rest: the slip (tan gamma of the approach
    speed) stops inside the impact, and with e = 0 both relative velocities end at 0, so
    both bodies stand still and stick; the kinetic energy lost is all of body 2's."""
    m1, m2, c = 10.0, 100.0, 1e-4
    F2 = -2000.0
    pr = params(friction_rho=math.radians(20.0), restitution=0.0, F2_0=F2, F2_1=F2, F2_2=F2)
    r = simulate(lab, pr, t_end=0.02, v1=0.0, gap=c / 2, **TIGHT)
    assert r.status == "finished", r.message
    a_n = normal_accel(0.0, F2, m1, m2)
    tau = math.sqrt(2.0 * (c / 2) / abs(a_n))
    hit = r.events[0]
    assert (hit.guard, hit.from_mode, hit.to_mode) == ("gap_a", "free", "stick")
    assert hit.t == pytest.approx(tau, rel=1e-9)
    assert hit.v1 == 0.0 and hit.jump.v1_before == 0.0
    v2 = F2 / m2 * tau
    assert hit.jump.energy_lost == pytest.approx(0.5 * m2 * v2**2, rel=1e-9)
    assert abs(hit.jump.P_t) < math.tan(math.radians(20.0)) * hit.jump.P_n
    assert np.all(r.v1[r.t > hit.t] == 0.0) and np.all(r.v2[r.t > hit.t] == 0.0)


def test_jammed_impact_is_reported_not_integrated(lab):
    """With friction so high that the sliding impulse cannot stop the approach (W_nn - mu
    W_nt <= 0 for the slip's direction), the impact has no solution: status inconsistent,
    with a message naming the impact."""
    pr = params(friction_rho=math.radians(75.0), restitution=0.0, F1=0.0, F2_0=-2000.0, F2_1=-2000.0, F2_2=-2000.0)
    r = simulate(lab, pr, t_end=0.02, v1=-3.0, gap=5e-5, **TIGHT)
    assert r.status == "inconsistent"
    assert r.events[-1].guard == "gap_a" and r.events[-1].to_mode is None
    assert "impact" in r.message


# --- grazing and zero clearance -----------------------------------------------------------------


@pytest.mark.parametrize("shift", [0.0, 1e-9, -1e-9])
def test_grazing_contact_leaves_the_motion_unchanged(lab, shift):
    """The gap opens (load pushes body 2 away from flank a), then the load turns and the
    gap's apex lands on flank b with zero normal speed (shift 0), just short of it (+) or
    just into it (-). The return to flank a happens at the closed-form time either way."""
    m1, m2 = 10.0, 100.0
    Fa, Fb, t1 = 2000.0, -4000.0, 0.005
    a1n, a2n = normal_accel(0.0, Fa, m1, m2), normal_accel(0.0, Fb, m1, m2)
    w1 = a1n * t1
    apex = 0.5 * a1n * t1**2 + w1**2 / (2 * abs(a2n))
    pr = params(clearance=apex * (1 + shift), restitution=0.5, F2_0=Fa, F2_1=Fb, F2_2=Fb, load_at1=t1,
                load_at2=0.1)
    r = simulate(lab, pr, t_end=0.04, v1=0.0, **TIGHT)
    assert r.status == "finished", r.message
    t_apex = t1 + w1 / abs(a2n)
    t_back = t_apex + math.sqrt(2 * apex / abs(a2n))
    back = [ev for ev in r.events if ev.guard == "gap_a"]
    assert back and back[0].t == pytest.approx(t_back, rel=1e-6)
    grazes = [ev for ev in r.events if ev.guard == "gap_b"]
    assert all(ev.jump.energy_lost < 1e-9 for ev in grazes)
    assert r.events[0].to_mode == "free"


ZERO = LAB.replace('name = "impact-lab"', 'name = "impact-lab-rigid"').replace(
    'clearance = { value = "0.1 mm", free = true }\n', "").replace(
    "[impact]\nrestitution = { value = 0.5, free = true }\n", "")


@pytest.mark.heavy
def test_zero_clearance_reproduces_the_rigid_model(lab, scene_module):
    """clearance = 0: the flanks part and meet again at once (no flight, no impulse), so the
    run is the zero-clearance model's, through the same flank change."""
    rigid = scene_module(ZERO)
    common = dict(m1=10.0, m2=100.0, friction_rho=math.radians(5.0), F1=300.0, load_at1=0.01, load_at2=0.02,
                  F2_0=-500.0, F2_1=1500.0, F2_2=-800.0)
    a = simulate(lab, {**common, "clearance": 0.0, "restitution": 0.5}, t_end=0.03, **TIGHT)
    b = simulate(rigid, common, t_end=0.03, **TIGHT)
    assert a.status == b.status == "finished", (a.message, b.message)
    assert np.allclose(a.v1, b.v1, rtol=1e-8, atol=1e-10)
    assert np.allclose(a.S2, b.S2, rtol=1e-7, atol=1e-6)
    assert [p.regime for p in a.phases] == [p.regime for p in b.phases]
    assert not a.impacts or all(ev.jump.energy_lost == 0.0 for ev in a.impacts)


# --- the energy audit ---------------------------------------------------------------------------


def test_energy_audit_over_a_run_with_impacts():
    """Work of F1 and F2 = kinetic energy change + friction dissipation (S1 v1 + S2 v2, the
    power the contact absorbs) + impact losses, along the whole backlash run."""
    r = simulate("backlash", points=40001, **TIGHT)
    assert r.status == "finished" and len(r.impacts) > 3
    m1, m2 = r.model["fixed_params"]["m1"], r.params["m2"]
    K = 0.5 * (m1 * r.v1**2 + m2 * r.v2**2)
    power_in = r.F1 * r.v1 + r.F2 * r.v2
    absorbed = r.S1 * r.v1 + r.S2 * r.v2
    residual, total = energy_residual(r, K, power_in, absorbed)
    assert abs(residual) < 1e-6 * total
    assert all(absorbed[r.mode == r.mode_names.index("free")] == 0.0)
    # across each impact, the kinetic energy falls by the reported loss
    for drop, lost, slack in impact_drops(r, K, power_in - absorbed, r.impacts):
        assert drop == pytest.approx(lost, abs=slack)


def test_a_sweep_counts_the_impacts_and_their_energy(lab):
    """The sweep's impacts and impact_energy columns, per case, against the closed forms of the
    first test: e = 0 takes one impact and ends the normal motion (the lost energy is that
    impact's); e = 1 loses nothing however often it bounces."""
    from tswm_runtime.simulation.simulate import settings
    from tswm_runtime.sweeps.rows import run_cases

    m1, m2, F1, c = 10.0, 100.0, 50.0, 1e-4
    names = lab.PARAM_NAMES
    rows = [[params(F1=F1, restitution=e, load_at2=0.04)[n] for n in names] for e in (0.0, 1.0)]
    table = run_cases(lab, np.array(rows), settings(lab, {"t_end": 0.03, **TIGHT}))
    a1 = sliding_a_accel(F1, -100.0, m1, m2, 0.0)
    v1_s = 1.0 + a1 * 0.01
    a_n = normal_accel(F1, 2000.0, m1, m2)
    tau = math.sqrt(2.0 * c / a_n)
    v1_b, v2_b = v1_s + F1 / m1 * tau, v1_s * SIN / COS + 2000.0 / m2 * tau
    nu = -(v2_b * COS - v1_b * SIN)
    P = frictionless_impulse(nu, m1, m2, 0.0)
    v1_a, v2_a = v1_b + P * SIN / m1, v2_b - P * COS / m2
    lost = 0.5 * (m1 * (v1_b**2 - v1_a**2) + m2 * (v2_b**2 - v2_a**2))
    assert list(table["status"]) == ["finished", "finished"]
    assert table["impacts"][0] == 1 and table["impact_energy"][0] == pytest.approx(lost, rel=1e-6)
    assert table["impacts"][1] >= 3 and abs(table["impact_energy"][1]) < 1e-9 * lost


def test_exports_carry_the_gap(lab):
    """With a clearance the CSV and the DataFrame have the gap and its rate (round-trip exact)."""
    import io

    import pandas as pd

    from tswm_runtime.results.export import csv_text

    r = simulate(lab, params(F1=50.0, load_at2=0.04), t_end=0.02, points=101, **TIGHT)
    table = pd.read_csv(io.StringIO(csv_text(r, lab.MODE_REGIME)))
    assert {"gap [m]", "gap_rate [m/s]"} <= set(table.columns)
    assert np.array_equal(table["gap [m]"].to_numpy(), r.gap) and r.gap.max() > 0.0
    assert np.array_equal(r.to_dataframe()["gap_rate"].to_numpy(), r.gap_rate)
