"""Open stages of a chain (derivation/chain/clearance.py) against hand-written mechanics and scipy.

The hand forms: a two-stage chain, body 0 (lever r1 of stage 1) -> body 1 (lever r2 of stage 1, lever
r3 of stage 2) -> body 2 (lever r4 of stage 2). Stage 2 open: bodies 0 and 1 move together through
stage 1 sliding on flank a forward (its resultant Q leans by rho from the normal: -Q sin(g + rho) on
x1, Q cos(g + rho) on x2), body 2 alone under F2. Stage 2's gap g = x2 cos(g2) - x1 sin(g2).
"""
import itertools
import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from derivation.chain import clearance as cl
from derivation.chain import dynamics as dyn

g1, g2 = sp.symbols("gamma_1 gamma_2", positive=True)
rho1, rho2 = sp.symbols("rho_1 rho_2", nonnegative=True)
r1, r2, r3, r4 = sp.symbols("r_in_1 r_out_1 r_in_2 r_out_2", positive=True)
M0, M1, M2 = sp.symbols("M_0 M_1 M_2", positive=True)
F0, F1, F2 = sp.symbols("F_0 F_1 F_2", real=True)
v0, v2 = sp.symbols("v_0 v_2", real=True)
NUMBERS = {g1: 0.3, g2: 0.5, rho1: 0.1, rho2: 0.0, r1: 0.025, r2: 0.08, r3: 0.009, r4: 0.7, M0: 0.0069, M1: 0.02,
           M2: 20.0, F0: 5.0, F1: 0.3, F2: -40.0}


def _hand_group_a():
    """Bodies 0 and 1 through stage 1 sliding tractive forward, solved by hand: (a0, Q)."""
    k = r1 * sp.tan(g1) / r2                                   # v1 / v0
    a0 = (F0 + F1 * r1 * sp.tan(g1 + rho1) / r2) / (M0 + M1 * r1**2 * sp.tan(g1) * sp.tan(g1 + rho1) / r2**2)
    Q = (M1 * k * a0 - F1) / (r2 * sp.cos(g1 + rho1))
    return a0, Q, k


def _equal(a, b, at=NUMBERS, digits=1e-12):
    x, y = float(sp.N(a.subs(at), 30)), float(sp.N(b.subs(at), 30))
    assert x == pytest.approx(y, rel=digits, abs=1e-300), (a, b)


def test_groups_split_at_the_open_stages():
    g = cl.groups(3, (1, 3))
    assert g.first == (0, 1, 3) and g.of_body == (0, 1, 1, 2)
    assert g.factors[0] == 1 and g.factors[1] == 1 and g.factors[3] == 1
    assert sp.simplify(g.factors[2] - r3 * sp.tan(g2) / r4) == 0      # body 2 behind body 1 through stage 2
    assert cl.groups(2, ()).first == (0,)


def test_open_stage_motion_equals_the_hand_form():
    chain = cl.open_chain(2, (2,))
    psi = {chain.psi[0]: cl.sliding_psi(1, dyn.TRACTIVE, 1)}
    a0, Q, k = _hand_group_a()
    _equal(chain.accel[0].subs(psi), a0)
    assert sp.simplify(chain.accel[1] - F2 / M2) == 0
    # stage 1's normal force N = Q cos(rho): the switching function of its opening
    _equal(cl.normal_force(chain, 1, dyn.TRACTIVE, 1).subs(psi), Q * sp.cos(rho1))
    # gap kinematics: g' = r4 v2 cos(g2) - r3 (k v0) sin(g2)
    assert sp.simplify(chain.gap_rate[2] - (r4 * v2 * sp.cos(g2) - r3 * k * v0 * sp.sin(g2))) == 0
    _equal(chain.gap_accel[2].subs(psi), r4 * F2 / M2 * sp.cos(g2) - r3 * k * a0 * sp.sin(g2))


def test_a_chain_without_open_stages_is_the_rigid_chain():
    chain = cl.open_chain(2, ())
    for regimes in ((dyn.TRACTIVE, dyn.INVERSE), (dyn.INVERSE, dyn.TRACTIVE)):
        mode = dyn.sliding(-1, regimes)
        psi = {chain.psi[i]: cl.sliding_psi(i + 1, r, -1) for i, r in enumerate(regimes)}
        _equal(chain.accel[0].subs(psi), mode.accel, {**NUMBERS, rho2: 0.12})


def _closing_time(g0, rate0, accel):
    """The first root t > 0 of g0 + rate0 t + accel t^2 / 2 = 0 (the gap closing on flank a)."""
    roots = [t.real for t in np.roots([accel / 2, rate0, g0]) if abs(t.imag) < 1e-12 and t.real > 0]
    return min(roots)


def test_gap_closes_at_the_closed_form_time_of_a_scipy_run_of_the_hand_equations():
    """Constant forces: each group moves with constant acceleration, so g(t) is quadratic; the derived
    g'' gives the closing time, checked against solve_ivp (rtol 1e-12) on Newton per body by hand."""
    chain = cl.open_chain(2, (2,))
    psi = {chain.psi[0]: cl.sliding_psi(1, dyn.TRACTIVE, 1)}
    n = {s: float(v) for s, v in NUMBERS.items()}
    a0, _, k = (float(sp.N(e.subs(NUMBERS))) for e in _hand_group_a())
    gap0, speed0 = 0.1e-3, 20.0
    start_v2 = float(sp.N((r3 * k * v0 * sp.tan(g2) / r4).subs({**NUMBERS, v0: speed0})))   # g' = 0 at t = 0

    def rhs(_, y):
        return [y[1], a0, y[3], n[F2] / n[M2]]

    def gap(_, y):
        x1 = n[r3] * float(k) * y[0]
        return n[r4] * y[2] * math.cos(n[g2]) - x1 * math.sin(n[g2]) + gap0
    gap.terminal, gap.direction = True, -1
    ref = solve_ivp(rhs, (0, 1.0), [0.0, speed0, 0.0, start_v2], rtol=1e-12, atol=1e-15, events=gap)
    rate0 = float(sp.N(chain.gap_rate[2].subs({**NUMBERS, v0: speed0, v2: start_v2})))
    accel = float(sp.N(chain.gap_accel[2].subs(psi).subs(NUMBERS)))
    assert rate0 == pytest.approx(0.0, abs=1e-12)
    assert _closing_time(gap0, rate0, accel) == pytest.approx(ref.t_events[0][0], rel=1e-9)


def _hand_impact(e, nu_sign=1):
    """Frictionless stages: group A's mass reduced to stage 2's x1 by its kinetic energy, body 2's to x2;
    Newton's law along the flank normal n = (sin(g2), cos(g2)) seen from x1, x2: (dv0, dv2, m_n)."""
    m1 = M0 / (r1 * sp.tan(g1) / r2)**2 / r3**2 + M1 / r3**2
    m2 = M2 / r4**2
    w_nn = sp.sin(g2)**2 / m1 + sp.cos(g2)**2 / m2
    nu = nu_sign * (r4 * v2 * sp.cos(g2) - r3 * (r1 * sp.tan(g1) / r2) * v0 * sp.sin(g2))
    P = -(1 + e) * nu / w_nn
    dx1, dx2 = -nu_sign * P * sp.sin(g2) / m1, nu_sign * P * sp.cos(g2) / m2
    return dx1 / (r3 * r1 * sp.tan(g1) / r2), dx2 / r4, 1 / w_nn, nu, P


@pytest.mark.parametrize("flank, sign", [("a", 1), ("b", -1)])
def test_impact_speeds_and_loss_equal_the_restitution_law_of_two_effective_masses(flank, sign):
    e = sp.Rational(3, 10)
    frictionless = {rho1: 0, rho2: 0}
    im = cl.impact(2, (2,), 2, flank)
    psi = {sp.Symbol("Psi_1", real=True): cl.sliding_psi(1, dyn.TRACTIVE, 1).subs(frictionless)}
    dv0, dv2, m_n, nu, P = _hand_impact(e, sign)
    at = {**NUMBERS, **frictionless, v0: 20.0, v2: 0.0 if sign == 1 else 1.0}
    assert float(sp.N(nu.subs(at))) < 0                       # the flanks approach
    Pn = sp.Symbol("P_n", real=True)
    w = im.W.subs(psi)
    derived_P = -(1 + e) * nu / w[0, 0]
    jumps = [j.subs(psi).subs({Pn: derived_P, sp.Symbol("P_t", real=True): 0}) for j in im.jumps]
    _equal(1 / w[0, 0], m_n, at)
    _equal(jumps[0], dv0, at)
    _equal(jumps[1], dv2, at)
    # kinetic energy of the three bodies before and after: the loss is (1 - e^2)/2 m_n nu^2
    c1 = r1 * sp.tan(g1) / r2
    kinetic = lambda a, b: (M0 * a**2 + M1 * (c1 * a)**2 + M2 * b**2) / 2   # noqa: E731
    loss = kinetic(v0, v2) - kinetic(v0 + jumps[0], v2 + jumps[1])
    _equal(loss, (1 - e**2) / 2 * m_n * nu**2, at)
    after = nu.subs({v0: v0 + dv0, v2: v2 + dv2}, simultaneous=True)
    _equal(after, -e * nu, at)


def test_energy_while_open_kinetic_rate_is_input_power_less_coulomb_friction():
    """d/dt of sum M_j v_j^2 / 2 = sum F_j v_j - tan(rho) N |sliding speed| of the closed stage (v0 > 0)."""
    chain = cl.open_chain(2, (2,))
    psi = {chain.psi[0]: cl.sliding_psi(1, dyn.TRACTIVE, 1)}
    c1 = r1 * sp.tan(g1) / r2
    a0, a2 = chain.accel[0].subs(psi), chain.accel[1]
    kinetic_rate = M0 * v0 * a0 + M1 * c1**2 * v0 * a0 + M2 * v2 * a2
    N = cl.normal_force(chain, 1, dyn.TRACTIVE, 1).subs(psi)
    coulomb = sp.tan(rho1) * N * r1 * v0 / sp.cos(g1)        # sliding speed |v1| / cos(gamma) at x1 = r1 q0
    power = F0 * v0 + F1 * c1 * v0 + F2 * v2
    _equal(kinetic_rate, power - coulomb, {**NUMBERS, v0: 20.0, v2: 0.7})


def test_impulse_masses_with_friction_inside_a_group_follow_its_ftf():
    """Group A's impulse response at stage 2's x1 with stage 1 sliding inverse-tractive: by hand, an
    impulse P on body 1 (x1 = r3 q1) with stage 1 passing -Psi W to body 0: M0 dv0 = -Psi r1 W,
    M1 c dv0 = r3 P + r2 W."""
    im = cl.impact(2, (2,), 2, "a")
    psi_value = cl.sliding_psi(1, dyn.INVERSE, 1)
    Psi = sp.Symbol("Psi_1", real=True)
    c1 = r1 * sp.tan(g1) / r2
    W = -M0 / (Psi * r1) * sp.Symbol("dv")
    dv = sp.solve(sp.Eq(M1 * c1 * sp.Symbol("dv"), r3 + r2 * W), sp.Symbol("dv"))[0]
    _equal(im.m1.subs(Psi, psi_value), (1 / (r3 * c1 * dv)).subs(Psi, psi_value))
    assert sp.simplify(im.m2 - M2 / r4**2) == 0


def test_with_e_zero_the_groups_leave_the_impact_moving_as_the_rigid_chain():
    """e = 0, frictionless stage 2 (stage 1 sliding tractive): after the impulse the gap's rate is 0, so body
    2's speed is the rigid chain's speed factor times v0 (dynamics.speed_factors)."""
    im = cl.impact(2, (2,), 2, "a")
    chain = cl.open_chain(2, (2,))
    psi = {chain.psi[0]: cl.sliding_psi(1, dyn.TRACTIVE, 1)}
    at = {**NUMBERS, v0: 20.0, v2: -0.3}
    nu = chain.gap_rate[2]
    w = im.W.subs(psi)
    P = {sp.Symbol("P_n", real=True): -nu / w[0, 0], sp.Symbol("P_t", real=True): 0}
    after = {v0: v0 + im.jumps[0].subs(psi).subs(P), v2: v2 + im.jumps[1].subs(psi).subs(P)}
    rigid = dyn.speed_factors(dyn.symbols(2))[2]
    assert abs(float(sp.N(nu.subs(after, simultaneous=True).subs(at)))) < 1e-15
    _equal(after[v2], rigid * after[v0], at)


@pytest.mark.parametrize("regimes, f", [((dyn.TRACTIVE, dyn.TRACTIVE), 1), ((dyn.TRACTIVE, dyn.INVERSE), -1)])
def test_a_closed_stage_opens_where_its_switching_function_crosses_zero(regimes, f):
    """Stage 2 loaded on flank f (a: tractive forward, b: inverse-tractive): were it cut, the gap would move
    onto that flank (f g'' < 0) exactly where its normal force, of phi_2's sign, is > 0. At phi_2 = 0 the open
    chain's g'' is 0: the flanks part with zero relative normal acceleration (and speed)."""
    rigid = dyn.sliding(1, regimes)
    chain = cl.open_chain(2, (2,))
    gap_accel = chain.gap_accel[2].subs({chain.psi[0]: cl.sliding_psi(1, regimes[0], 1)})
    values = {s: v for s, v in {**NUMBERS, rho2: 0.12}.items() if s != F2}
    for force in (-400.0, -40.0, 3.0, 50.0):
        phi, g = (float(sp.N(e.subs({**values, F2: force}))) for e in (rigid.switching[1], gap_accel))
        assert f * g * phi < 0, (force, phi, g)
    zero = sp.solve(rigid.switching[1].subs(values), F2)[0]
    assert abs(float(sp.N(gap_accel.subs({**values, F2: zero})))) < 1e-12


def test_two_open_stages_leave_a_middle_group_moving_alone():
    """Three stages, 1 and 3 open: body 0 alone, bodies 1 and 2 through stage 2 (sliding tractive backward on
    flank b: Q (-cos(rho) n + sin(rho) t) on body 2 leans against its slip, R1 = Q sin(g + rho) on x1 and
    R2 = -Q cos(g + rho) on x2, by hand), body 3 alone."""
    g3, rho3 = sp.Symbol("gamma_3", positive=True), sp.Symbol("rho_3", nonnegative=True)
    r5, r6 = sp.symbols("r_in_3 r_out_3", positive=True)
    M3, F3 = sp.Symbol("M_3", positive=True), sp.Symbol("F_3", real=True)
    v1, v3 = sp.symbols("v_1 v_3", real=True)
    chain = cl.open_chain(3, (1, 3))
    assert chain.groups.first == (0, 1, 3) and set(chain.stage_force) == {2}
    psi = {chain.psi[1]: cl.sliding_psi(2, dyn.TRACTIVE, -1)}
    k = r3 * sp.tan(g2) / r4                                      # v2 / v1
    # M1 a1 = F1 + r3 Q sin(g2 + rho2), M2 k a1 = F2 - r4 Q cos(g2 + rho2): eliminate Q
    a1 = (F1 + F2 * r3 * sp.tan(g2 + rho2) / r4) / (M1 + M2 * k * r3 * sp.tan(g2 + rho2) / r4)
    at = {**NUMBERS, rho2: 0.12, g3: 0.4, rho3: 0.05, r5: 0.3, r6: 1.5, M3: 3.0, F3: -2.0}
    assert [sp.simplify(a - b) for a, b in zip((chain.accel[0], chain.accel[2]), (F0 / M0, F3 / M3))] == [0, 0]
    _equal(chain.accel[1].subs(psi), a1, at)
    assert sp.simplify(chain.gap_rate[1] - (r2 * v1 * sp.cos(g1) - r1 * v0 * sp.sin(g1))) == 0
    assert sp.simplify(chain.gap_rate[3] - (r6 * v3 * sp.cos(g3) - r5 * k * v1 * sp.sin(g3))) == 0


@pytest.mark.parametrize("stages, open_stage", [(2, 2), (2, 1), pytest.param(3, 2, marks=pytest.mark.heavy)])
def test_open_phase_in_signed_friction_angles_is_every_regime_and_direction(stages, open_stage):
    """open_phase's one set of expressions (rho_i standing for rho_sign_i rho_i) equals open_chain with each closed
    stage's FTF (sliding_psi) and normal force (normal_force) of its regime and its group's direction, for every
    regime of the closed stages and both directions of each group, at random numbers."""
    phase, chain = cl.open_phase(stages, open_stage), cl.open_chain(stages, (open_stage,))
    sym = dyn.symbols(stages)
    rng = np.random.default_rng(7)
    closed = sorted(phase.normal)
    for regimes in itertools.product(dyn.REGIMES, repeat=stages):
        for directions in itertools.product((1, -1), repeat=2):
            at = {s: rng.uniform(0.1, 0.5) for s in (*sym.gamma, *sym.rho)}
            at.update({s: rng.uniform(0.01, 1.0) for s in (*sym.lever_in, *sym.lever_out, *sym.inertia)})
            at.update({s: rng.uniform(-3.0, 3.0) for s in sym.force})
            sign = {i: 1 if regimes[i - 1] == dyn.TRACTIVE else -1 for i in range(1, stages + 1)}
            own = {**{cl.rho_sign(i): s for i, s in sign.items()},
                   cl.DIRECTION_IN: directions[0], cl.DIRECTION_OUT: directions[1]}
            signed = {sym.rho[i - 1]: s * sym.rho[i - 1] for i, s in sign.items()}

            def direction(i):
                return directions[chain.groups.of_body[i]]
            psi = {chain.psi[i - 1]: cl.sliding_psi(i, regimes[i - 1], direction(i)) for i in closed}

            def hand(e):
                return float(e.subs(psi).subs(at))

            def phased(e):
                return float(e.subs(signed, simultaneous=True).subs(own).subs(at))
            for g in range(2):
                assert phased(phase.accel[g]) == pytest.approx(hand(chain.accel[g]), rel=1e-10, abs=1e-12)
            for i in closed:
                ref = hand(cl.normal_force(chain, i, regimes[i - 1], direction(i)))
                assert phased(phase.normal[i]) == pytest.approx(ref, rel=1e-10, abs=1e-12)
