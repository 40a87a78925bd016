"""The generated code of a chain with a clearance (derivation/chain/codegen.py, ``_open_functions``) against Newton
per body and the restitution law written by hand.

The chain: the bench's worm gear (body 0 -> body 1) and Tr 18x4 stem nut (body 1 -> stem, body 2), a spring on the
stem, the clearance in stage 2 (k = 2) or stage 1 (k = 1). Hand forms (levers r1, r2 of stage 1, r3, r4 of stage
2; slopes g1, g2; friction angles rho1, rho2): with stage 2 open, bodies 0 and 1 move together through the worm
sliding (its FTF tan(g1 + s rho1), s = +1 tractive, -1 inverse-tractive), the stem alone under F2 - k q2; stage 2's
gap g = gap0 + r4 q2 cos(g2) - r3 q1 sin(g2). The impact: each group reduced to stage 2's x1 and x2 by its response
to an impulse there, the flank frame's inverse mass W of two masses on perpendicular guides.
"""
import math
from dataclasses import replace

import numpy as np
import pytest

from derivation.chain.codegen import generate_chain_module
from derivation.chain.scene import Clearance, parse_chain
from derivation.scene import Param
from tswm_runtime.chains.run import latches
from tswm_runtime.hybrid.impact import collide
from tswm_runtime.model.contract import load_module
from tswm_runtime.bench.chain import worm_and_nut

# heavy: its modules take a SymPy derivation of six chains (two minutes of CPU); CI runs it after the default set
pytestmark = pytest.mark.heavy

E = 0.4


def _chain(k: int, worm_mu: float, screw_mu: float):
    text = worm_and_nut(f"gap-{k}-{int(worm_mu * 100)}-{int(screw_mu * 100)}", worm_mu=worm_mu, screw_mu=screw_mu,
                        drive='torque = "5 N m"', load='force = "-300 N"\nstiffness = "2e5 N/m"')
    chain = parse_chain(text, "gap.toml")
    clearance = Clearance(k, Param(f"clearance_{k}", 1e-4, "m", False, f"stage[{k}].clearance"),
                          Param(f"restitution_{k}", E, "1", False, f"stage[{k}].restitution"),
                          Param(f"gap_{k}", 4e-5, "m", False, f"run.gap_{k}"))
    return replace(chain, clearances=(clearance,)), chain


@pytest.fixture(scope="module")
def modules(tmp_path_factory):
    """(module with the clearance, its chain's values, the same chain's module without it) per case."""
    folder = tmp_path_factory.mktemp("clearance_code")
    out = {}
    for key, (k, worm_mu, screw_mu) in {"k2": (2, 0.05, 0.15), "k2 frictionless": (2, 0.0, 0.0),
                                          "k1": (1, 0.05, 0.15)}.items():
        chain, rigid = _chain(k, worm_mu, screw_mu)
        paths = []
        for c, name in ((chain, "gap"), (rigid, "rigid")):
            path = folder / f"{name}_{key.replace(' ', '_')}.py"
            path.write_text(generate_chain_module(c))
            paths.append(path)
        out[key] = (load_module(paths[0]), chain.values(), load_module(paths[1]))
    return out


def _p(module, y, rho_signs=(1.0, 1.0), directions=(1.0, 1.0)):
    p = latches(module, y)
    p[module.P_DIRECTION_IN], p[module.P_DIRECTION_OUT] = directions
    p[module.P_RHO_SIGN:module.P_RHO_SIGN + 2] = rho_signs
    return p


Y = np.array([0.3, 40.0, 2e-4, 0.05])    # q0 [rad], v0 [rad/s], q_k, v_k


def _worm_group(v, s, F0, F1):
    """Bodies 0 and 1 through the worm sliding (s = +1 tractive, -1 inverse-tractive): (a0, N1) by hand."""
    g1, rho1, r1, r2 = v.gamma[0], s * v.rho[0], v.lever_in[0], v.lever_out[0]
    M0, M1 = v.inertia[0], v.inertia[1]
    k = r1 * math.tan(g1) / r2
    a0 = (F0 + F1 * r1 * math.tan(g1 + rho1) / r2) / (M0 + M1 * r1**2 * math.tan(g1) * math.tan(g1 + rho1) / r2**2)
    Q = (M1 * k * a0 - F1) / (r2 * math.cos(g1 + rho1))     # the resultant on body 1, leaning by rho1
    return a0, s * Q * math.cos(rho1)     # inverse-tractive (flank b) holds body 1 back: Q < 0 for N > 0


@pytest.mark.parametrize("s", [1.0, -1.0])
def test_open_stage_2_moves_each_group_by_newton(modules, s):
    module, v, _ = modules["k2"]
    p = _p(module, Y, rho_signs=(s, 1.0), directions=(1.0, 1.0))
    dy, g = np.empty(4), np.empty(len(module.GUARDS))
    module.rhs(module.OPEN, 0.0, Y, p, dy)
    a0, n1 = _worm_group(v, s, 5.0, 0.0)
    q2 = Y[2]
    assert dy[0] == Y[1] and dy[2] == Y[3]
    assert dy[1] == pytest.approx(a0, rel=1e-13)
    assert dy[3] == pytest.approx((-300.0 - 2e5 * q2) / v.inertia[2], rel=1e-13)
    module.guards(module.OPEN, 0.0, Y, p, g)
    k = v.lever_in[0] * math.tan(v.gamma[0]) / v.lever_out[0]
    gap = 4e-5 + v.lever_out[1] * q2 * math.cos(v.gamma[1]) - v.lever_in[1] * k * Y[0] * math.sin(v.gamma[1])
    names = module.GUARDS
    assert g[names.index("N_1")] == pytest.approx(n1, rel=1e-12) and g[names.index("N_2")] == 1.0
    assert g[names.index("jam")] == pytest.approx(math.cos(v.gamma[0] + s * v.rho[0]), rel=1e-14)
    assert g[names.index("gap_a")] == pytest.approx(gap, rel=1e-12, abs=1e-18)
    assert g[names.index("gap_b")] == pytest.approx(1e-4 - gap, rel=1e-12, abs=1e-18)
    assert g[names.index("v0")] == Y[1] and g[names.index("v_out")] == Y[3]


def test_open_stage_1_leaves_body_0_alone(modules):
    """Stage 1 open: body 0 under its torque alone, bodies 1 and 2 through the screw sliding tractive forward (its
    FTF tan(g2 + rho2)), the stem's spring at its travel (v2 / v1) q1."""
    module, v, _ = modules["k1"]
    p = _p(module, Y, directions=(1.0, 1.0))
    dy = np.empty(4)
    module.rhs(module.OPEN, 0.0, Y, p, dy)
    assert dy[1] == pytest.approx(5.0 / v.inertia[0], rel=1e-14)
    g2, rho2, r3, r4 = v.gamma[1], v.rho[1], v.lever_in[1], v.lever_out[1]
    M1, M2 = v.inertia[1], v.inertia[2]
    q2 = Y[2] * r3 * math.tan(g2) / r4     # the stem's travel: (v2 / v1) q1
    F2 = -300.0 - 2e5 * q2
    a1 = (F2 * r3 * math.tan(g2 + rho2) / r4) / (M1 + M2 * r3**2 * math.tan(g2) * math.tan(g2 + rho2) / r4**2)
    assert dy[3] == pytest.approx(a1, rel=1e-13)


def test_closed_modes_with_a_clearance_are_the_rigid_chains(modules):
    """Closed, the chain with the clearance moves as the rigid chain does at the same state (q2 = c2 q0)."""
    module, v, rigid = modules["k2"]
    p_rigid = latches(rigid, Y[:2])
    c2 = p_rigid[rigid.P_SPEED + 2]
    y = np.array([Y[0], Y[1], c2 * Y[0], c2 * Y[1]])
    p = _p(module, y)
    dy, dy_rigid = np.empty(4), np.empty(2)
    for mode in range(len(rigid.MODES)):
        module.rhs(mode, 0.0, y, p, dy)
        rigid.rhs(mode, 0.0, y[:2], p_rigid, dy_rigid)
        assert dy[1] == pytest.approx(dy_rigid[1], rel=1e-13) and dy[3] == pytest.approx(c2 * dy_rigid[1], rel=1e-13)


def _hand_frame(v, y, flank, s1):
    """Stage 2's impact frame by hand: (nu, s, W, m1, m2, k) with group 0 reduced to x1 = r3 q1 through the worm
    sliding in regime s1 and the stem to x2 = r4 q2."""
    g1, rho1, r1, r2 = v.gamma[0], s1 * v.rho[0], v.lever_in[0], v.lever_out[0]
    g2, r3, r4 = v.gamma[1], v.lever_in[1], v.lever_out[1]
    M0, M1, M2 = v.inertia
    k = r1 * math.tan(g1) / r2
    # a unit impulse J at x1: generalized impulse r3 J on body 1; body 0 follows through the worm's FTF
    dv0 = (r3 * r1 * math.tan(g1 + rho1) / r2) / (M0 + M1 * r1**2 * math.tan(g1) * math.tan(g1 + rho1) / r2**2)
    m1, m2 = 1.0 / (r3 * k * dv0), M2 / r4**2
    f = 1.0 if flank == "a" else -1.0
    x1, x2 = r3 * k * y[1], r4 * y[3]
    nu = f * (x2 * math.cos(g2) - x1 * math.sin(g2))
    slip = x2 * math.sin(g2) + x1 * math.cos(g2)
    sc = math.sin(g2) * math.cos(g2)
    W = np.array([[math.cos(g2)**2 / m2 + math.sin(g2)**2 / m1, f * sc * (1 / m2 - 1 / m1)],
                  [f * sc * (1 / m2 - 1 / m1), math.sin(g2)**2 / m2 + math.cos(g2)**2 / m1]])
    return nu, slip, W, m1, m2, k


def _apply(frame, y):
    """collide on the generated frame, the groups' speeds after it."""
    p_n, p_t, nu, s, lost, outcome = collide(*frame[:7])
    return y[1] + frame[7] * p_n + frame[8] * p_t, y[3] + frame[9] * p_n + frame[10] * p_t, nu, lost, outcome


@pytest.mark.parametrize("flank, v2", [("a", -0.2), ("b", 0.4)])
def test_frictionless_impact_is_newtons_restitution_with_two_effective_masses(modules, flank, v2):
    module, v, _ = modules["k2 frictionless"]
    y = np.array([0.3, 40.0, 2e-4, v2])
    p = _p(module, y)
    frame = np.empty(len(module.IMPACT_FRAME))
    module.impact(1 if flank == "a" else -1, 0.0, y, p, frame)
    nu, slip, W, m1, m2, k = _hand_frame(v, y, flank, 1.0)
    assert nu < 0                                             # the flanks approach
    assert frame[0] == pytest.approx(nu, rel=1e-12) and frame[1] == pytest.approx(slip, rel=1e-12)
    assert frame[2:5] == pytest.approx([W[0, 0], W[0, 1], W[1, 1]], rel=1e-12)
    assert frame[5] == 0.0 and frame[6] == E
    v0_after, v2_after, nu_after, lost, outcome = _apply(frame, y)
    # Newton's law along the normal: P = -(1 + e) nu / W_nn, each mass's speed change along its guide
    f = 1.0 if flank == "a" else -1.0
    P = -(1 + E) * nu / W[0, 0]
    g2, r3, r4 = v.gamma[1], v.lever_in[1], v.lever_out[1]
    assert outcome == 0 and nu_after == pytest.approx(-E * nu, rel=1e-12)
    assert v0_after == pytest.approx(y[1] - f * P * math.sin(g2) / m1 / (r3 * k), rel=1e-12)
    assert v2_after == pytest.approx(y[3] + f * P * math.cos(g2) / m2 / r4, rel=1e-12)
    # energy: the bodies' kinetic energy drops by (1 - e^2)/2 m_n nu^2, 1/m_n = W_nn
    M0, M1, M2 = v.inertia

    def kinetic(v0, v2):
        return 0.5 * (M0 * v0**2 + M1 * (k * v0)**2 + M2 * v2**2)
    drop = kinetic(y[1], y[3]) - kinetic(v0_after, v2_after)
    assert drop == pytest.approx((1 - E**2) / 2 * nu**2 / W[0, 0], rel=1e-10)
    assert lost == pytest.approx(drop, rel=1e-10)


@pytest.mark.parametrize("s1", [1.0, -1.0])
def test_impact_with_friction_is_the_single_stage_law_on_the_effective_masses(modules, s1):
    """With friction in both stages: the worm's FTF in the group's response, Coulomb in the impact (Routh's
    process, ``collide``) on the W of the two effective masses written by hand."""
    module, v, _ = modules["k2"]
    y = np.array([0.3, 40.0, 2e-4, -0.2])
    p = _p(module, y, rho_signs=(s1, 1.0))
    frame = np.empty(len(module.IMPACT_FRAME))
    module.impact(1, 0.0, y, p, frame)
    nu, slip, W, m1, m2, k = _hand_frame(v, y, "a", s1)
    assert frame[:5] == pytest.approx([nu, slip, W[0, 0], W[0, 1], W[1, 1]], rel=1e-12)
    assert frame[5] == pytest.approx(math.tan(v.rho[1]), rel=1e-14)
    hand = collide(nu, slip, W[0, 0], W[0, 1], W[1, 1], math.tan(v.rho[1]), E)
    v0_after, v2_after, nu_after, lost, outcome = _apply(frame, y)
    assert outcome == 0 and nu_after == pytest.approx(hand[2], rel=1e-12)
    g2, r3, r4 = v.gamma[1], v.lever_in[1], v.lever_out[1]
    p_n, p_t = hand[0], hand[1]
    # body 2 takes P_n n + P_t t, body 1's side the opposite, each along its guide
    assert v2_after == pytest.approx(y[3] + (p_n * math.cos(g2) + p_t * math.sin(g2)) / m2 / r4, rel=1e-12)
    assert v0_after == pytest.approx(y[1] - (p_n * math.sin(g2) - p_t * math.cos(g2)) / m1 / (r3 * k), rel=1e-12)


@pytest.mark.parametrize("stages, k", [(2, 1), (2, 2), (3, 2)])
def test_an_open_phase_stage_force_depends_on_its_own_groups_bodies_only(stages, k):
    """What the chain kernel's peaks rest on (chains/kernel.py): while stage k is open, a closed stage's force and
    normal force depend on the forces and inertias of its own group's bodies only (bodies 0..k-1 or k..N), so each
    on one coordinate (q0 or qk), monotone between the group's speed's events, and on v0 (a motor) in the input
    group only."""
    from derivation.chain import clearance as cl

    phase = cl.open_phase(stages, k)
    bodies = {f"{x}_{j}" for x in ("F", "M") for j in range(stages + 1)}
    assert sorted(phase.stage_force) == [i for i in range(1, stages + 1) if i != k]
    for i in phase.stage_force:
        group = range(0, k) if i < k else range(k, stages + 1)
        for expr in (phase.stage_force[i], phase.normal[i]):
            used = {str(s) for s in expr.free_symbols} & bodies
            assert used == {f"{x}_{j}" for x in ("F", "M") for j in group}, (i, used)
