"""Chains of wedge stages against hand solutions: the one-stage wedge, the efficiency product of a
worm gear and a power screw, self-locking, power balance, Painleve cases, the resting chain."""
import math

import numpy as np
import pytest
import sympy as sp

from derivation import mechanics as M
from derivation.chain import dynamics as dyn
from derivation.chain import stages as st
from derivation.chain.selector import ChainValues, decide
from tests.chains import DEG

BOTH = ("a", "b")
rng = np.random.default_rng(27)


def zero(expr) -> bool:
    return sp.simplify(sp.expand_trig(expr)) == 0


# ---- the stage kinds ----------------------------------------------------------------------------

def test_worm_gear_friction_angle_is_mu_over_cos_alpha_n():
    w = st.equivalent_wedge("worm_gear")
    assert zero(w.tan_rho - st.mu / sp.cos(st.alpha_n))
    assert zero(w.ratio - st.r_wheel / (st.r_worm * sp.tan(M.gamma)))


@pytest.mark.parametrize("lead_mm, diameter_mm, flank_deg", [(4, 18, 15), (7, 36, 15), (12, 50, 30)])
def test_power_screw_lead_angle_and_friction_angle(lead_mm, diameter_mm, flank_deg):
    """Hand: tan(lambda) = L / (pi d_m), tan(alpha_n) = tan(alpha) cos(lambda), tan(rho') = mu / cos(alpha_n)."""
    w = st.equivalent_wedge("power_screw")
    L, d, a, mu = lead_mm * 1e-3, diameter_mm * 1e-3, flank_deg * DEG, 0.12
    at = {st.lead: L, st.d_m: d, st.alpha_ax: a, st.mu: mu}
    lam = math.atan(L / (math.pi * d))
    alpha_n = math.atan(math.tan(a) * math.cos(lam))
    assert float(w.tan_gamma.subs(at)) == pytest.approx(math.tan(lam), rel=1e-14)
    assert float(w.tan_rho.subs(at)) == pytest.approx(mu / math.cos(alpha_n), rel=1e-13)
    assert float(w.ratio.subs(at)) == pytest.approx(2 * math.pi / L, rel=1e-14)   # rad of the nut per m of stem


def test_plain_wedge_is_the_wedge():
    w = st.equivalent_wedge("wedge")
    assert w.tan_rho == st.mu and zero(w.tan_gamma - sp.tan(M.gamma)) and w.lever_in == w.lever_out == 1


# ---- one stage is today's model ------------------------------------------------------------------

@pytest.mark.parametrize("regime", dyn.REGIMES)
@pytest.mark.parametrize("direction", (1, -1))
def test_one_stage_chain_reproduces_mechanics(regime, direction):
    sym = dyn.symbols(1)
    mode = dyn.sliding(direction, (regime,))
    ref = M.sliding(mode.flanks[0], direction)
    names = {M.gamma: sym.gamma[0], M.rho: sym.rho[0], M.m1: sym.inertia[0], M.m2: sym.inertia[1],
             M.F1: sym.force[0], M.F2: sym.force[1]}
    unit = {sym.lever_in[0]: 1, sym.lever_out[0]: 1}
    hand = sp.tan(sym.gamma[0] + (1 if regime == dyn.TRACTIVE else -1) * sym.rho[0])   # tan(gamma +- rho)
    assert zero(mode.psi[0] - hand)
    assert zero(mode.psi[0] - ref.psi.subs(names))
    assert zero(mode.accel.subs(unit) - ref.accel.subs(names))
    normal = ref.normal.subs(M.phi, ref.switching).subs(names)
    assert zero(mode.normal[0].subs(unit) - normal)
    flank_sign = M.FLANK_SIGN[mode.flanks[0]]
    assert zero(mode.switching[0].subs(unit) - flank_sign * (M.m1 * M.m2 * ref.switching).subs(names))


def test_one_stage_with_levers_is_the_wedge_in_reduced_units():
    """A rotating input of inertia J, lever r: the wedge sees m1 = J / r^2 and F1 = Q / r."""
    sym = dyn.symbols(1)
    mode = dyn.sliding(1, (dyn.TRACTIVE,))
    r1, r2 = sym.lever_in[0], sym.lever_out[0]
    ref = M.sliding("a", 1)
    names = {M.gamma: sym.gamma[0], M.rho: sym.rho[0], M.m1: sym.inertia[0] / r1**2,
             M.m2: sym.inertia[1] / r2**2, M.F1: sym.force[0] / r1, M.F2: sym.force[1] / r2}
    assert zero(mode.accel * r1 - ref.accel.subs(names))     # a1 = r1 * (angular acceleration)


# ---- an independent Newton + Coulomb for any chain -------------------------------------------------

def newton_by_hand(values: ChainValues, direction: int, flanks: tuple[str, ...]):
    """Each stage's contact force written out: normal n = (sin g, cos g), line t = (-cos g, sin g),
    body 2's slip along t with sign(v1); force on the output body f N n - s mu N t, its opposite on the input."""
    n_st = len(values.gamma)
    speed = [1.0]
    for i in range(n_st):
        speed.append(speed[-1] * values.lever_in[i] * math.tan(values.gamma[i]) / values.lever_out[i])
    A = np.zeros((n_st + 1, n_st + 1))
    b = np.array(values.force, dtype=float)
    for j in range(n_st + 1):
        A[j, 0] = values.inertia[j] * speed[j]               # M_j c_j a_0 - (contact terms) N = F_j
    for i, fl in enumerate(flanks):
        g, mu = values.gamma[i], math.tan(values.rho[i])
        f = 1 if fl == "a" else -1
        on_output = f * np.array([math.sin(g), math.cos(g)]) - direction * mu * np.array([-math.cos(g), math.sin(g)])
        A[i, 1 + i] -= values.lever_in[i] * (-on_output[0])
        A[i + 1, 1 + i] -= values.lever_out[i] * on_output[1]
    solution = np.linalg.solve(A, b)
    return solution[0], solution[1:]


def random_chain(n_st: int) -> ChainValues:
    gamma = rng.uniform(0.03, 0.6, n_st)
    rho = rng.uniform(0.0, 0.9, n_st) * (math.pi / 2 - gamma)
    return ChainValues(tuple(gamma), tuple(rho), tuple(rng.uniform(0.01, 1.0, n_st)), tuple(rng.uniform(0.01, 1.0, n_st)),
                       tuple(rng.uniform(0.01, 50.0, n_st + 1)), tuple(rng.uniform(-500, 500, n_st + 1)), (BOTH,) * n_st)


@pytest.mark.heavy
@pytest.mark.parametrize("n_st", (1, 2, 3))
def test_every_mode_agrees_with_newton_written_by_hand(n_st):
    chains = [random_chain(n_st) for _ in range(4)]
    for direction, regimes in dyn.reachable((BOTH,) * n_st):
        mode = dyn.sliding(direction, regimes)
        numbers = sp.lambdify(_symbols(n_st), (mode.accel, mode.normal, mode.switching, mode.denominator))
        for values in chains:
            accel, normal = newton_by_hand(values, direction, mode.flanks)
            derived_accel, derived_normal, phi, D = numbers(*values.args())
            assert derived_accel == pytest.approx(accel, rel=1e-9, abs=1e-9)
            assert list(derived_normal) == pytest.approx(list(normal), rel=1e-9, abs=1e-7)
            assert [p / D >= 0 for p in phi] == [n >= 0 for n in normal]


def _symbols(n_st):
    s = dyn.symbols(n_st)
    return (*s.gamma, *s.rho, *s.lever_in, *s.lever_out, *s.inertia, *s.force)


# ---- power balance ----------------------------------------------------------------------------------

@pytest.mark.parametrize("n_st", (1, 2))
def test_power_balance_in_every_mode(n_st):
    """Input power = rate of kinetic energy + friction losses, and the losses are Coulomb's, >= 0 when N >= 0."""
    sym = dyn.symbols(n_st)
    speed = dyn.speed_factors(sym)
    for direction, regimes in dyn.reachable((BOTH,) * n_st):
        mode = dyn.sliding(direction, regimes)
        supplied = sum(sym.force[j] * speed[j] * dyn.v0 for j in range(n_st + 1))
        kinetic_rate = sum(sym.inertia[j] * speed[j]**2 * mode.accel * dyn.v0 for j in range(n_st + 1))
        numbers = sp.lambdify((*_symbols(n_st), dyn.v0), (supplied - kinetic_rate, mode.friction_power,
                                                          mode.coulomb_power, mode.normal))
        for _ in range(5):
            values = random_chain(n_st)
            balance, losses, coulomb, normals = numbers(*values.args(), direction * rng.uniform(0.1, 5))
            assert balance == pytest.approx(sum(losses), rel=1e-9, abs=1e-9)
            assert losses == pytest.approx(coulomb, rel=1e-9, abs=1e-9)
            for loss, n in zip(losses, normals):
                assert (loss >= 0) == (n >= 0) or abs(n) < 1e-9


# ---- worm gear + power screw: efficiency product and self-locking ------------------------------------

def worm_and_screw(mu_worm, mu_screw, gamma=5 * DEG, alpha_n=20 * DEG, lead=4e-3, d_m=18e-3, flank=15 * DEG):
    """Equivalent wedges of a worm (r1 = 20 mm, r2 = 80 mm) and a Tr 18x4 stem nut, from stages.py."""
    worm, screw = st.equivalent_wedge("worm_gear"), st.equivalent_wedge("power_screw")
    w_at = {st.mu: mu_worm, st.alpha_n: alpha_n, M.gamma: gamma, st.r_worm: 0.02, st.r_wheel: 0.08}
    s_at = {st.mu: mu_screw, st.alpha_ax: flank, st.lead: lead, st.d_m: d_m}
    gammas = (gamma, math.atan(float(screw.tan_gamma.subs(s_at))))
    rhos = (math.atan(float(worm.tan_rho.subs(w_at))), math.atan(float(screw.tan_rho.subs(s_at))))
    levers_in = (float(worm.lever_in.subs(w_at)), float(screw.lever_in.subs(s_at)))
    levers_out = (float(worm.lever_out.subs(w_at)), float(screw.lever_out.subs(s_at)))
    return gammas, rhos, levers_in, levers_out


def shigley(mu, lead_angle, alpha_n):
    """Textbook efficiency of a thread or worm driving: (cos a_n - mu tan l) / (cos a_n + mu cot l)."""
    return (math.cos(alpha_n) - mu * math.tan(lead_angle)) / (math.cos(alpha_n) + mu / math.tan(lead_angle))


@pytest.mark.parametrize("mu_worm, mu_screw", [(0.05, 0.1), (0.1, 0.15), (0.02, 0.05)])
def test_tractive_efficiency_is_the_product_of_the_stages(mu_worm, mu_screw):
    gammas, rhos, li, lo = worm_and_screw(mu_worm, mu_screw)
    sym = dyn.symbols(2)
    mode = dyn.sliding(1, (dyn.TRACTIVE, dyn.TRACTIVE))
    at = dict(zip((*sym.gamma, *sym.rho, *sym.lever_in, *sym.lever_out), (*gammas, *rhos, *li, *lo)))
    at.update({sym.force[1]: 0, sym.force[2]: -1000.0, **{m: 1.0 for m in sym.inertia}})
    # steady running: a_0 = 0 fixes the drive torque for the load
    drive = sp.solve(sp.numer(sp.together(mode.accel.subs(at))), sym.force[0])[0]
    speed = dyn.speed_factors(sym)[2].subs(at)
    eta = float(1000.0 * speed / drive)
    lam = math.atan(4e-3 / (math.pi * 18e-3))
    hand = shigley(mu_worm, 5 * DEG, 20 * DEG) * shigley(mu_screw, lam, math.atan(math.tan(15 * DEG) * math.cos(lam)))
    assert eta == pytest.approx(hand, rel=1e-12)


@pytest.mark.parametrize("stage", (0, 1))
@pytest.mark.parametrize("factor", (0.9, 1.1))
def test_a_load_back_drives_the_chain_unless_a_stage_self_locks(stage, factor):
    """Hand: a worm self-locks when mu >= tan(gamma) cos(alpha_n), a thread when mu >= tan(lambda) cos(alpha_n).
    No drive torque, a load pushing the stem back: the chain runs backward, or rests if either stage locks."""
    lam = math.atan(4e-3 / (math.pi * 18e-3))
    limits = (math.tan(5 * DEG) * math.cos(20 * DEG), math.tan(lam) * math.cos(math.atan(math.tan(15 * DEG) * math.cos(lam))))
    mus = [0.5 * limits[0], 0.5 * limits[1]]
    mus[stage] = factor * limits[stage]
    gammas, rhos, li, lo = worm_and_screw(*mus)
    values = ChainValues(gammas, rhos, li, lo, (1e-3, 0.05, 20.0), (0.0, 0.0, -5000.0), (BOTH, BOTH))
    decision = decide(values, 0.0)
    assert decision.outcome == "unique"
    if factor > 1:
        assert decision.modes == ("stuck",)
        # a free worm with no torque on it holds no force: X_1 = 0 exactly; a locked worm holds a band of X_1
        assert ("the statics determine the internal forces: X_1 = 0;" if stage == 1 else
                "statically undetermined; admissible X_1 in [") in decision.reason, decision.reason
    else:
        assert decision.modes == ("backward: inverse-tractive (a), inverse-tractive (a)",)
        assert decision.accel < 0


# ---- the mode logic -------------------------------------------------------------------------------

def test_painleve_light_input_heavy_output_through_a_self_locking_stage():
    """One self-locking wedge (rho > gamma), light input, heavy output coasting forward: D < 0 on flank b.
    Pushed by the drive both flanks are consistent; pushed by the load neither is."""
    values = ChainValues((5 * DEG,), (8 * DEG,), (1.0,), (1.0,), (1.0, 1000.0), (100.0, 0.0), (BOTH,))
    several = decide(values, 1.0)
    assert several.outcome == "several" and len(several.modes) == 2 and "D < 0" in several.reason
    assisted = ChainValues((5 * DEG,), (8 * DEG,), (1.0,), (1.0,), (1.0, 1000.0), (0.0, 100.0), (BOTH,))
    none = decide(assisted, 1.0)
    assert none.outcome == "none" and none.modes == () and "N_1" in none.reason


def test_painleve_in_a_worm_and_screw_chain():
    """The worm self-locks; the stem is heavy and runs on forward: the same ambiguity, in a two-stage chain."""
    gammas, rhos, li, lo = worm_and_screw(0.15, 0.1)
    values = ChainValues(gammas, rhos, li, lo, (1e-5, 1e-4, 5e4), (0.5, 0.0, 0.0), (BOTH, BOTH))
    decision = decide(values, 1.0)
    assert decision.outcome == "several" and "D < 0" in decision.reason


@pytest.mark.heavy
@pytest.mark.parametrize("n_st", (1, 2, 3))
def test_unique_mode_whenever_every_reduced_inertia_is_positive(n_st):
    """Without a negative D the sliding modes never overlap nor leave a gap: exactly one is consistent while
    moving, and for one stage at rest. From rest, two or more stages can also rest under an internal force
    their statics leave free (a prestress), beside one breakaway: reported as such, never a silent pick."""
    checked = prestressed = 0
    for _ in range(30):
        values = random_chain(n_st)
        args = dict(zip(_symbols(n_st), values.args()))
        if any(float(dyn.sliding(*r).denominator.subs(args)) <= 0 for r in dyn.reachable(values.flanks)):
            continue
        checked += 1
        for velocity in (1.0, -1.0):
            assert decide(values, velocity).outcome in ("unique", "critical"), (values, velocity)
        at_rest = decide(values, 0.0)
        if at_rest.outcome == "several":
            prestressed += 1
            assert n_st > 1 and "stuck" in at_rest.modes and len(at_rest.modes) == 2
            assert "statically undetermined" in at_rest.reason and at_rest.internal
        else:
            assert at_rest.outcome in ("unique", "critical")
    assert checked >= 5


def test_a_prestressed_rest_beside_a_breakaway_is_reported():
    """Two self-locking stages, a force on the middle body: breaking away and resting under an internal torque
    X (which stage 1 holds for any large X) are both consistent; the rigid chain cannot choose."""
    values = ChainValues((0.0416, 0.0505), (0.5603, 0.3), (0.1, 0.1), (0.1, 0.1), (1.0, 1.0, 1.0),
                         (10.0, 144.7, -356.7), (BOTH, BOTH))
    decision = decide(values, 0.0)
    assert decision.outcome == "several" and "stuck" in decision.modes
    assert "statically undetermined" in decision.reason
    (admissible,) = decision.internal
    for X in (admissible[0][0], admissible[0][1]):
        assert holds_by_hand(0.0416, 0.5603, 10.0 / 0.1, -X / 0.1)
        assert holds_by_hand(0.0505, 0.3, (144.7 + X) / 0.1, -356.7 / 0.1)


# ---- the resting chain -------------------------------------------------------------------------------

def holds_by_hand(gamma, rho, p, q):
    """The forces p on the stage's input and q on its output (each along its wedge line, as the other
    bodies and loads apply them: the stage's own force X on body j enters as -X) split into normal and tangential parts
    of the contact line; it holds while |tangential| <= tan(rho) |normal|."""
    normal = p * math.sin(gamma) - q * math.cos(gamma)
    tangential = p * math.cos(gamma) + q * math.sin(gamma)
    return np.abs(tangential) <= math.tan(rho) * np.abs(normal) * (1 + 1e-12) + 1e-12


def test_stick_cone_as_one_product():
    """cone_forward * cone_backward = k (F1 + Psi_t F2)(F1 + Psi_i F2), k = -cos(g + r) cos(g - r) / cos(r)^2 < 0."""
    g, r = sp.symbols("g r", positive=True)
    _, k, _ = dyn.holding(g, r)
    assert zero(k + sp.cos(g + r) * sp.cos(g - r) / sp.cos(r)**2)


def test_one_stage_rest_is_the_stick_cone():
    for _ in range(200):
        values = random_chain(1)
        decision = decide(values, 0.0)
        p, q = values.force[0] / values.lever_in[0], values.force[1] / values.lever_out[0]
        assert ("stuck" in decision.modes) == holds_by_hand(values.gamma[0], values.rho[0], p, q)


@pytest.mark.parametrize("locking", (False, True))
def test_two_stage_rest_gives_the_admissible_internal_torque(locking):
    """Grid over the wheel torque X: X is admissible exactly where both stages hold (by hand)."""
    gammas, rhos, li, lo = worm_and_screw(0.15 if locking else 0.03, 0.2)
    values = ChainValues(gammas, rhos, li, lo, (1e-3, 0.05, 20.0), (0.2, 0.0, -3000.0), (BOTH, BOTH))
    decision = decide(values, 0.0)
    assert decision.modes == ("stuck",) and "statically undetermined" in decision.reason
    (admissible,) = decision.internal
    assert all(math.isfinite(lo_) or locking for lo_, _ in admissible)
    for X in np.linspace(-200, 200, 4001):
        stage1 = holds_by_hand(gammas[0], rhos[0], values.force[0] / li[0], -X / lo[0])
        stage2 = holds_by_hand(gammas[1], rhos[1], (values.force[1] + X) / li[1], values.force[2] / lo[1])
        inside = any(a - 1e-9 <= X <= b + 1e-9 for a, b in admissible)
        assert inside == (stage1 and stage2), X


@pytest.mark.heavy
def test_three_stage_rest_ranges_against_a_grid():
    """Three stages: the propagated ranges of X_1, X_2 are the projections of the set where all three hold."""
    values = ChainValues((0.1, 0.2, 0.3), (0.15, 0.1, 0.05), (0.02, 0.05, 0.01), (0.1, 0.2, 1.0),
                         (1.0, 1.0, 1.0, 1.0), (0.3, 0.0, 0.0, -30000.0), (BOTH,) * 3)
    decision = decide(values, 0.0)
    assert decision.modes == ("stuck",)
    x1, x2 = np.meshgrid(np.linspace(0, 25, 1001), np.linspace(50, 300, 1001), indexing="ij")
    feasible = (holds_by_hand(0.1, 0.15, 0.3 / 0.02, -x1 / 0.1) & holds_by_hand(0.2, 0.1, x1 / 0.05, -x2 / 0.2)
                & holds_by_hand(0.3, 0.05, x2 / 0.01, -30000.0 / 1.0))
    assert feasible.any()
    for grid, ranges, step in ((x1, decision.internal[0], 0.025), (x2, decision.internal[1], 0.25)):
        seen = grid[feasible]
        (lo_, hi_), = ranges
        assert lo_ <= seen.min() + 1e-9 and seen.max() <= hi_ + 1e-9
        assert seen.min() - lo_ < step and hi_ - seen.max() < step
