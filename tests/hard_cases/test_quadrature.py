"""The quadrature reference (``quadrature``) against closed forms and scipy's DOP853.

Closed forms: constant forces (v linear in t) and a linear drive with constant friction
(exponential approach, flank switch at a closed-form time). The paper's gear: DOP853 at
rtol 1e-13 with restart at the load step and a terminal event at v = 0, and the
Painleve end D -> 0+ against its closed-form v* and the square-root law near t*.
"""
import math

import mpmath as mp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tswm_runtime.reference import quadrature as q
from tswm_runtime.reference import paper_gear as gear

DOP = dict(method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)


def const_wedge(F1, rho, m1=2.0, m2=3.0, gamma=0.3):
    return q.Wedge(m1, m2, gamma, lambda v: mp.mpf(F1), lambda v: mp.mpf(rho))


def a_const(F1, F2, f, s, rho, m1=2.0, m2=3.0, gamma=0.3):
    """a1 of the force balance, in plain floats."""
    psi = math.tan(gamma + f * s * rho)
    return (F1 + psi * F2) / (m1 + psi * m2 * math.tan(gamma))


def test_constant_forces_brake_to_zero_and_reverse():
    """F1, rho, F2 constant: A is constant per mode. Braking to v = 0 at v0 / |a_fwd|,
    the backward cone fails there (rho = 0.1 < gamma), so it slides back with a_bwd."""
    F1, F2, rho, v0 = 10.0, -200.0, 0.1, 1.5
    a_f, a_b = a_const(F1, F2, 1, 1, rho), a_const(F1, F2, 1, -1, rho)
    assert a_f < 0 and a_b < 0
    t1 = v0 / -a_f
    tr = q.solve(const_wedge(F1, rho), [(0.0, F2)], v0, 1.0)
    assert tr.status == "finished"
    assert [(e.kind, e.mode_before, e.mode_after) for e in tr.events] == [("v1", "fwd_a", "bwd_a")]
    assert float(tr.events[0].t) == pytest.approx(t1, rel=1e-13)
    assert [p.mode for p in tr.phases] == ["fwd_a", "bwd_a"]
    for t in (0.0, 0.3 * t1, t1, 0.5, 1.0):
        v = v0 + a_f * t if t <= t1 else a_b * (t - t1)
        x = v0 * t + a_f * t * t / 2 if t <= t1 else v0 * t1 / 2 + a_b * (t - t1) ** 2 / 2
        assert float(tr.v_at(t)) == pytest.approx(v, rel=1e-13, abs=1e-13 * v0)
        assert float(tr.x_at(t)) == pytest.approx(x, rel=1e-13, abs=1e-14)
    S = tr.S_extrema()  # S1 = F1 - m1 a1 is constant per mode: the larger |.| of the two
    S1 = max((F1 - 2.0 * a_f, F1 - 2.0 * a_b), key=abs)
    assert float(S["S1"][0]) == pytest.approx(S1, rel=1e-13)


def test_constant_forces_stick_load_steps_and_breakaway():
    """rho = 0.5 > gamma: both cones hold at v = 0 under F2 = -200 and -20 (stick, the
    load step at t = 1 is a 'load' event), F2 = 0 at t = 2 breaks away forward."""
    F1, rho, v0 = 10.0, 0.5, 1.5
    sched = [(0.0, -200.0), (1.0, -20.0), (2.0, 0.0)]
    a_f, a_2 = a_const(F1, -200.0, 1, 1, rho), a_const(F1, 0.0, 1, 1, rho)
    t1 = v0 / -a_f
    W = const_wedge(F1, rho)
    assert min(W.cones(-200.0)) >= 0 and min(W.cones(-20.0)) >= 0 and W.cones(0.0)[0] < 0
    tr = q.solve(W, sched, v0, 3.0)
    assert [(e.kind, e.mode_before, e.mode_after) for e in tr.events] == [
        ("v1", "fwd_a", "stick"), ("load", "stick", "stick"), ("breakaway", "stick", "fwd_a")]
    assert float(tr.events[0].t) == pytest.approx(t1, rel=1e-13)
    assert [float(e.t) for e in tr.events[1:]] == [1.0, 2.0]
    for t, v in ((0.5, 0.0), (1.5, 0.0), (2.0, 0.0), (2.5, a_2 * 0.5), (3.0, a_2)):
        assert float(tr.v_at(t)) == pytest.approx(v, rel=1e-13, abs=1e-15)
    assert float(tr.x_at(3.0)) == pytest.approx(v0 * t1 / 2 + a_2 / 2, rel=1e-13)


def linear_wedge(F0, V0, rho, m1, m2, gamma):
    return q.Wedge(m1, m2, gamma, lambda v: F0 * (1 - v / V0), lambda v: mp.mpf(rho))


def test_linear_drive_exponential_approach():
    """F1 = F0 (1 - v/V0), F2 = 0, flank a: v = V0 (1 - exp(-beta t)), beta = F0 / (V0 D);
    the equilibrium V0 coincides with phi = 0 and must not be reported as a flank switch."""
    F0, V0, rho, m1, m2, g = 50.0, 4.0, 0.08, 1.5, 7.0, 0.25
    psi = math.tan(g + rho)
    beta = F0 / (V0 * (m1 + psi * m2 * math.tan(g)))
    tr = q.solve(linear_wedge(F0, V0, rho, m1, m2, g), [(0.0, 0.0)], 0.0, 60.0 / beta)
    assert tr.status == "finished" and tr.events == [] and [p.mode for p in tr.phases] == ["fwd_a"]
    for bt in (1e-3, 0.5, 1.0, 3.0, 10.0, 30.0, 60.0):
        t = bt / beta
        v = V0 * -math.expm1(-bt)
        assert float(tr.v_at(t)) == pytest.approx(v, rel=1e-12, abs=1e-15)
        assert float(tr.x_at(t)) == pytest.approx(V0 * (t + math.expm1(-bt) / beta), rel=1e-12)


def test_linear_drive_flank_switch_at_closed_form_time():
    """F2 = +20 > 0: flank a from rest until phi = 0 at v_sw = V0 (1 - F2 m1 / (m2 F0 tan g)),
    then flank b; both linear ODEs, so the switch time and v(t) are closed forms."""
    F0, V0, rho, m1, m2, g, F2 = 100.0, 10.0, 0.05, 1.0, 2.0, 0.2, 20.0
    W = linear_wedge(F0, V0, rho, m1, m2, g)
    v_sw = V0 * (1 - F2 * m1 / (m2 * F0 * math.tan(g)))

    def lin(f):  # v' = beta (v_inf - v)
        psi = math.tan(g + f * rho)
        return F0 / (V0 * (m1 + psi * m2 * math.tan(g))), V0 * (1 + psi * F2 / F0)
    (ba, va), (bb, vb) = lin(1), lin(-1)
    t_sw = math.log(va / (va - v_sw)) / ba
    tr = q.solve(W, [(0.0, F2)], 0.0, 3.0)
    assert [(e.kind, e.mode_before, e.mode_after) for e in tr.events] == [("phi", "fwd_a", "fwd_b")]
    assert float(tr.events[0].t) == pytest.approx(t_sw, rel=1e-13)
    assert float(tr.events[0].v) == pytest.approx(v_sw, rel=1e-14)
    for t in (0.5 * t_sw, t_sw, t_sw + 0.01, 0.5, 3.0):
        v = va - va * math.exp(-ba * t) if t <= t_sw else vb - (vb - v_sw) * math.exp(-bb * (t - t_sw))
        assert float(tr.v_at(t)) == pytest.approx(v, rel=1e-12)


PAPER200 = q.paper_wedge(200.0)


def test_paper_run_up_then_load_matches_dop853():
    """Free run-up from rest, F2 = -15000 N from 0.3 s (flank a throughout)."""
    tr = q.solve(PAPER200, [(0.0, 0.0), (0.3, -15000.0)], 0.0, 1.0)
    assert tr.status == "finished" and [p.mode for p in tr.phases] == ["fwd_a", "fwd_a"]
    assert [(e.kind, float(e.t)) for e in tr.events] == [("load", 0.3)]
    s1 = solve_ivp(lambda t, y: [gear.accel(y[0], 1, 0.0, 200.0)], (0.0, 0.3), [0.0], **DOP)
    s2 = solve_ivp(lambda t, y: [gear.accel(y[0], 1, -15000.0, 200.0)], (0.3, 1.0), [s1.y[0, -1]], **DOP)
    for t in (0.01, 0.05, 0.1, 0.3, 0.31, 0.35, 0.5, 1.0):
        v_ref = (s1 if t <= 0.3 else s2).sol(t)[0]
        assert float(tr.v_at(t)) == pytest.approx(v_ref, rel=1e-10)
    # S extrema against the dense DOP853 solution sampled finely (one-sided at 0.3)
    S = tr.S_extrema()
    for i, name in enumerate(("S1", "S2")):
        best = max(((gear.reactions(sol.sol(t)[0], 1, F2, 200.0)[i], t)
                    for sol, F2 in ((s1, 0.0), (s2, -15000.0)) for t in np.linspace(*sol.t[[0, -1]], 4001)),
                   key=lambda st: abs(st[0]))
        assert float(S[name][0]) == pytest.approx(best[0], rel=1e-9)
        assert float(tr.v_at(S[name][1])) == pytest.approx(float(tr.v_at(best[1])), rel=1e-6)


def test_paper_decelerates_and_sticks_like_dop853():
    """m2 = 200, F2 = -15000 N from v0 = 2 m/s: brakes to v = 0, both cones hold: stick."""
    tr = q.solve(PAPER200, [(0.0, -15000.0)], 2.0, 0.1)
    ev = lambda t, y: y[0]  # noqa: E731
    ev.terminal, ev.direction = True, -1
    sol = solve_ivp(lambda t, y: [gear.accel(y[0], 1, -15000.0, 200.0)], (0.0, 1.0), [2.0], events=ev, **DOP)
    assert tr.status == "finished"
    assert [(e.kind, e.mode_before, e.mode_after) for e in tr.events] == [("v1", "fwd_a", "stick")]
    assert float(tr.events[0].t) == pytest.approx(sol.t_events[0][0], rel=1e-9)
    assert [p.mode for p in tr.phases] == ["fwd_a", "stick"] and tr.v_at(0.1) == 0
    assert float(tr.v_at(0.01)) == pytest.approx(sol.sol(0.01)[0], rel=1e-10)
    S1, t_S1 = tr.S_extrema()["S1"]  # largest at the one-sided limit v -> 0+ of the sliding phase
    assert float(S1) == pytest.approx(gear.reactions(0.0, 1, -15000.0, 200.0)[0], rel=1e-12)
    assert t_S1 == tr.events[0].t


def test_paper_painleve_end_square_root_approach():
    """m2 = 5000, run-up from rest, F2 = +60000 N at 0.04 s: phi < 0 -> flank b with
    Psi = tan(g - rho) < 0; braking raises rho until D = 0 at v* (closed form from the
    friction law) at a finite t*, approached as (v - v*)^2 = C (t* - t), C = -2 N*/D'(v*)."""
    m2, F2, ts = 5000.0, 60000.0, 0.04
    W = q.paper_wedge(m2)
    tr = q.solve(W, [(0.0, 0.0), (ts, F2)], 0.0, 1.0)
    assert tr.status == "inconsistent"
    assert [(e.kind, e.mode_before, e.mode_after) for e in tr.events] == [
        ("load", "fwd_a", "fwd_b"), ("D", "fwd_b", "fwd_b")]
    t_star, v_star = tr.events[-1].t, tr.events[-1].v
    assert tr.t_stop == t_star and ts < t_star < ts + 0.01
    # v* in closed form: tan(g - rho*) = -m1 / (m2 tan g), then invert the friction law
    g = gear.GAMMA
    rho_star = g + math.atan(gear.M1 / (m2 * math.tan(g)))
    v_closed = math.cos(g) * ((1 / math.degrees(rho_star) - 0.088) / 0.161) ** (1 / 0.535)
    assert float(v_star) == pytest.approx(v_closed, rel=1e-13)
    with mp.workdps(q.DPS):
        assert abs(W.D(v_star, -1, 1)) < mp.mpf(10) ** -25
        N = W.N(v_star, -1, 1, F2)
        C = -2 * N / mp.diff(lambda v: W.D(v, -1, 1), v_star)
        # C from the reference at t* - h: the relative deviation is O(sqrt(h)) (a regular
        # expansion in sqrt(t* - t)); its coefficient must settle (23.43 here)
        dev = []
        for h in (1e-6, 1e-8, 1e-10):
            dv = tr.v_at(t_star - h) - v_star
            dev.append(float((dv * dv / h / C - 1) / mp.sqrt(h)))
        assert all(abs(d) < 30 for d in dev), dev
        assert dev[2] == pytest.approx(dev[1], rel=1e-3) and dev[1] == pytest.approx(dev[0], rel=1e-2)
    # the approach itself against DOP853 from the load step to 10 us before t*
    sol = solve_ivp(lambda t, y: [gear.accel(y[0], -1, F2, m2)], (ts, float(t_star) - 1e-5),
                    [float(tr.v_at(ts))], **DOP)
    assert float(tr.v_at(sol.t[-1])) == pytest.approx(sol.y[0, -1], rel=1e-10)
    S = tr.S_extrema()
    assert mp.isinf(S["S1"][0]) and mp.isinf(S["S2"][0]) and S["S1"][1] == t_star
