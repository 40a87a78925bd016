"""A group at rest while a stage's flanks are apart: it sticks while its own statics hold (its closed stages' stick
cones, its friction) and leaves rest the way it accelerates otherwise; run against closed forms, Newton per body written
by hand, scipy's solve_ivp and the single-stage impact law (``collide``) on hand-written effective masses.

The chain: three bodies on two plain wedges (levers 1: x1 = q_{k-1}, x2 = q_k; stage i moves body i tan(g_i) times body
i - 1). A wedge's FTF sliding tractive is tan(g + rho), inverse-tractive (its output drives) tan(g - rho), rho =
atan(mu): the input body takes -Psi times the stage's force W on the output body.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from tswm_runtime.hybrid.impact import collide
from tswm_runtime.simulation.chain import simulate_chain

DEG = math.pi / 180
M = (1.0, 2.0, 3.0)


def _scene(name, *, open_stage=1, g2=10.0, mu1=0.1, mu2=0.3, f0=10.0, f1=0.0, f2=-2.0, drive="", switch="", valve="",
           t_end=0.3):
    """Stage 1 (30 deg) and stage 2 (g2), the clearance (1 mm, e = 0.3, start gap 0.5 mm) in ``open_stage``."""
    gap = 'clearance = "1 mm"\nrestitution = 0.3\n'
    return (f'name = "{name}"\n[[stage]]\nkind = "wedge"\ngamma = "30 deg"\nmu = {mu1!r}\n{gap if open_stage == 1 else ""}'
            f'[[stage]]\nkind = "wedge"\ngamma = "{g2!r} deg"\nmu = {mu2!r}\n{gap if open_stage == 2 else ""}'
            f'[[body]]\nmass = "1 kg"\nforce = "{f0!r} N"\n{drive}[[body]]\nmass = "2 kg"\nforce = "{f1!r} N"\n'
            f'[[body]]\nmass = "3 kg"\nforce = "{f2!r} N"\n{valve}{switch}'
            f'[run]\nt_end = {t_end!r}\nv0 = 0.0\ngap_{open_stage} = "0.5 mm"\nrtol = 1e-10\natol = 1e-12\n')


def _open_rows(result):
    """The output rows before the first impact."""
    return result.run.t < result.run.impacts[0]["t"]


def test_a_group_held_by_a_self_locking_stage_waits_and_is_struck_as_collide_says(chain_module):
    """Clearance in stage 1; the output group (bodies 1, 2) at rest, its load -2 N held by the self-locking stage 2
    (10 deg, mu 0.3): it stays (speed exactly 0) while body 0 alone crosses the gap under 10 N, so the gap
    g = g0 - sin(g1) q0 closes at sqrt(2 g0 / (sin(g1) F0 / M0)); the impact is Routh's process on W of m1 = M0 and
    the output group at x2 = q1 through stage 2 driven tractive, m2 = M1 + tan(g2 + rho2) tan(g2) M2."""
    module = chain_module(_scene("held-locking"))
    result = simulate_chain(module, points=31)
    assert result.status == "finished", result.message
    assert result.events[0]["to"] == "open: stage 1"
    assert [p.regime for p in result.stages[1].phases][0] == "resting"
    rows = _open_rows(result)
    assert rows.sum() > 1 and np.all(result.run.y[rows, 3] == 0.0) and np.all(result.run.y[rows, 2] == 0.0)
    g1, g2, rho2 = 30 * DEG, 10 * DEG, math.atan(0.3)
    a0 = 10.0 / M[0]
    first = result.run.impacts[0]
    t1 = math.sqrt(2 * 0.5e-3 / (math.sin(g1) * a0))
    assert first["t"] == pytest.approx(t1, rel=1e-9) and first["flank"] == "a"
    assert first["v0 before"] == pytest.approx(a0 * t1, rel=1e-9) and first["vk before"] == 0.0
    m1, m2 = M[0], M[1] + math.tan(g2 + rho2) * math.tan(g2) * M[2]
    s, c = math.sin(g1), math.cos(g1)
    v0 = first["v0 before"]
    nu, slip = -v0 * s, v0 * c
    p_n, p_t, nu_after, _, lost, _ = collide(nu, slip, c**2 / m2 + s**2 / m1, s * c * (1 / m2 - 1 / m1),
                                             s**2 / m2 + c**2 / m1, 0.1, 0.3)
    assert first["nu before"] == pytest.approx(nu, rel=1e-10) and first["nu after"] == pytest.approx(nu_after, rel=1e-9)
    assert first["v0 after"] == pytest.approx(v0 - (p_n * s - p_t * c) / m1, rel=1e-10)
    assert first["vk after"] == pytest.approx((p_n * c + p_t * s) / m2, rel=1e-10)
    assert first["energy lost"] == pytest.approx(lost, rel=1e-9)


def _backdriven(t_end):
    """Scipy's DOP853 (rtol 1e-12) on Newton per body while stage 1 is open: body 0 alone under 10 N; bodies 1 and 2
    through stage 2 (40 deg, mu 0.1) back-driven by body 2's -2 N (inverse-tractive: body 1 takes -tan(g2 - rho2) W,
    body 2 F2 + W, a2 = tan(g2) a1). Returns the solution with its gap event (g = g0 + cos(g1) q1 - sin(g1) q0 = 0)."""
    g1, g2, rho2 = 30 * DEG, 40 * DEG, math.atan(0.1)
    psi = math.tan(g2 - rho2)

    def newton(_, y):
        # body 1: M1 a1 = -psi W; body 2: M2 tan(g2) a1 = F2 + W  =>  W = M2 tan(g2) a1 - F2
        a1 = psi * -2.0 / (M[1] + psi * M[2] * math.tan(g2))
        return [y[1], 10.0 / M[0], y[3], a1]

    def gap(_, y):
        return 0.5e-3 + math.cos(g1) * y[2] - math.sin(g1) * y[0]
    gap.terminal, gap.direction = True, -1
    return solve_ivp(newton, (0, t_end), [0.0, 0.0, 0.0, 0.0], events=gap, method="DOP853", rtol=1e-12, atol=1e-14)


def test_a_group_its_load_backdrives_leaves_rest_as_newton_per_body_says(chain_module):
    """Stage 2 not self-locking (40 deg, mu 0.1): body 2's load back-drives it, so the output group leaves rest
    backward with a1 = tan(g2 - rho2) F2 / (M1 + tan(g2 - rho2) tan(g2) M2) and the gap closes at the closed form of
    two constant accelerations, sqrt(2 g0 / (sin(g1) a0 - cos(g1) a1)), as scipy finds on the hand equations."""
    module = chain_module(_scene("held-backdriven", g2=40.0, mu2=0.1))
    result = simulate_chain(module, points=31)
    assert result.status == "finished", result.message
    g1, g2, rho2 = 30 * DEG, 40 * DEG, math.atan(0.1)
    psi = math.tan(g2 - rho2)
    a0, a1 = 10.0 / M[0], psi * -2.0 / (M[1] + psi * M[2] * math.tan(g2))
    assert a1 < 0 and -2.0 - M[2] * math.tan(g2) * a1 < 0     # backward; body 2's load presses stage 2 (W < 0)
    assert [(p.regime, p.flank) for p in result.stages[1].phases][0] == ("inverse-tractive", "a")
    t1 = math.sqrt(2 * 0.5e-3 / (math.sin(g1) * a0 - math.cos(g1) * a1))
    ref = _backdriven(0.3)
    (t_ref,) = ref.t_events[0]
    first = result.run.impacts[0]
    assert t_ref == pytest.approx(t1, rel=1e-10)
    assert first["t"] == pytest.approx(t_ref, rel=1e-9)
    assert first["v0 before"] == pytest.approx(ref.y_events[0][0][1], rel=1e-9)
    assert first["vk before"] == pytest.approx(ref.y_events[0][0][3], rel=1e-9)
    rows = _open_rows(result)
    t = result.run.t[rows]
    assert result.run.y[rows, 3] == pytest.approx(a1 * t, rel=1e-9, abs=1e-15)


def test_a_held_group_breaks_away_when_the_motor_is_cut(chain_module):
    """Clearance in stage 2; the input group (bodies 0, 1) at rest, its constant 5 N motor against body 1's -10 N
    within stage 1's stick band (30 deg, mu 0.3: 10 tan(g - rho) < 5 < 10 tan(g + rho)): it sticks. The switch on
    the motor picks up at once and cuts it after its delay of 50 ms; then body 1's load back-drives stage 1, the group
    leaves rest backward at the cut, a0 = tan(g1 - rho1) F1 / (M0 + tan(g1 - rho1) tan(g1) M1), and the gap opens to
    the clearance at 0.05 + sqrt(2 (c - g0) / (tan(g1) sin(g2) |a0|))."""
    drive = "motor = { speed = [0.0, 100.0], torque = [5.0, 5.0], voltage = 1.0 }\n"
    switch = '[switch]\non = "motor"\nsetting = "4 N"\nhysteresis = "0.5 N"\ndelay = "50 ms"\n'
    module = chain_module(_scene("held-cut", open_stage=2, g2=40.0, mu1=0.3, mu2=0.1, f0=0.0, f1=-10.0, f2=0.0,
                                 drive=drive, switch=switch))
    g1, g2, rho1 = 30 * DEG, 40 * DEG, math.atan(0.3)
    assert 10 * math.tan(g1 - rho1) < 5.0 < 10 * math.tan(g1 + rho1)
    result = simulate_chain(module, points=61)
    assert result.status == "finished", result.message
    assert result.trip["t"] == pytest.approx(0.05, abs=1e-15)
    assert [(p.regime, p.t_start, p.t_end) for p in result.stages[0].phases][0] == ("resting", 0.0, result.trip["t"])
    before = result.run.t <= 0.05
    assert np.all(result.run.y[before] == 0.0)
    psi = math.tan(g1 - rho1)
    a0 = psi * -10.0 / (M[0] + psi * math.tan(g1) * M[1])
    first = result.run.impacts[0]
    assert first["flank"] == "b"
    assert first["t"] == pytest.approx(0.05 + math.sqrt(2 * 0.5e-3 / (math.tan(g1) * math.sin(g2) * -a0)), rel=1e-9)
    assert first["v0 before"] == pytest.approx(a0 * (first["t"] - 0.05), rel=1e-9)


def test_mov_with_its_clearance_in_the_worm_runs_and_the_worm_strikes_at_its_energy(chain_module):
    """The shipped mov with a clearance of 0.1 mm in its worm gear (stage 1), started 0.05 mm from flank a: the wheel,
    stem nut and stem wait (the stem's packing and the self-locking nut hold them) while the motor spins the worm
    across the gap, g = g0 - sin(lead) r_worm q0. On the motor's first table piece, T = 17.99 + 0.0632 w N m, the worm
    turns theta = g0 / (sin(lead) r_worm) with I w dw / dtheta = T: theta = I / b (w - a / b ln(1 + b w / a))."""
    from derivation.chain.scenes import __path__ as scenes

    text = open(f"{scenes[0]}/mov.toml").read()
    text = text.replace('name = "mov"', 'name = "mov-worm-gap"').replace(
        "mu = 0.05 ", 'clearance = "0.1 mm"\nrestitution = 0.3\nmu = 0.05 ').replace(
        "atol = 1e-10", 'atol = 1e-10\ngap_1 = "0.05 mm"')
    module = chain_module(text)
    result = simulate_chain(module, points=31)
    assert result.status == "finished", result.message
    assert result.trip is not None and result.answers["holds"]["verdict"].startswith("holds")
    first = result.run.impacts[0]
    assert first["vk before"] == 0.0 and first["flank"] == "a"
    inertia, a, b = 0.0069, 17.99, (21.15 - 17.99) / 50.0
    theta = 0.05e-3 / (math.sin(4.76 * DEG) * 25e-3)
    w = brentq(lambda w: inertia / b * (w - a / b * math.log1p(b * w / a)) - theta, 1e-9, 50.0, xtol=1e-14)
    assert w < 50.0
    assert first["v0 before"] == pytest.approx(w, rel=1e-8)


@pytest.mark.parametrize("packing, stays", [(5.0, True), (1.0, False)])
def test_both_groups_at_rest_are_decided_each_on_its_own(chain_module, packing, stays):
    """Clearance in stage 2, nothing moving: bodies 0 and 1 unforced (their rest holds) and body 2's load -2 N against
    its packing's friction. With 5 N both groups stay and nothing moves to the end; with 1 N body 2 leaves rest on its
    own, a2 = (-2 + 1) / M2, while the input group stays, and the gap g = g0 + cos(g2) q2 closes at
    sqrt(2 g0 / (cos(g2) |a2|))."""
    module = chain_module(_scene(f"held-both-{int(packing)}", open_stage=2, g2=40.0, mu1=0.1, mu2=0.1, f0=0.0,
                                 valve=f'packing = "{packing!r} N"\n'))
    result = simulate_chain(module, points=31)
    assert result.status == "finished", result.message
    assert result.stages[0].phases[0].regime == "resting"
    if stays:
        assert not result.run.impacts and np.all(result.run.y == 0.0) and result.t_stop == 0.3
        return
    a2 = (-2.0 + packing) / M[2]
    first = result.run.impacts[0]
    assert first["v0 before"] == 0.0
    assert first["t"] == pytest.approx(math.sqrt(2 * 0.5e-3 / (math.cos(40 * DEG) * -a2)), rel=1e-9)
    assert first["vk before"] == pytest.approx(a2 * first["t"], rel=1e-9)


def test_a_held_group_beyond_a_middle_clearance_waits_for_the_driven_group(chain_module):
    """Three stages (30, 40, 10 deg), the clearance in stage 2: bodies 0 and 1 driven by 10 N through stage 1 sliding
    tractive, a0 = F0 / (M0 + M1 tan(g1) tan(g1 + rho1)); bodies 2 and 3 held at rest by the self-locking stage 3
    (mu 0.3) under body 3's -3 N: they stay (speed exactly 0) and the gap g = g0 - sin(g2) tan(g1) q0 closes at
    sqrt(2 g0 / (sin(g2) tan(g1) a0))."""
    text = ('name = "held-middle"\n[[stage]]\nkind = "wedge"\ngamma = "30 deg"\nmu = 0.1\n'
            '[[stage]]\nkind = "wedge"\ngamma = "40 deg"\nmu = 0.1\nclearance = "1 mm"\nrestitution = 0.3\n'
            '[[stage]]\nkind = "wedge"\ngamma = "10 deg"\nmu = 0.3\n'
            '[[body]]\nmass = "1 kg"\nforce = "10 N"\n[[body]]\nmass = "2 kg"\nforce = "0 N"\n'
            '[[body]]\nmass = "3 kg"\nforce = "0 N"\n[[body]]\nmass = "4 kg"\nforce = "-3 N"\n'
            '[run]\nt_end = 0.1\nv0 = 0.0\ngap_2 = "0.5 mm"\nrtol = 1e-10\natol = 1e-12\n')
    module = chain_module(text)
    result = simulate_chain(module, points=31)
    assert result.status == "finished", result.message
    assert [p.regime for p in result.stages[2].phases][0] == "resting"
    assert [p.regime for p in result.stages[0].phases][0] == "tractive"
    g1, g2 = 30 * DEG, 40 * DEG
    a0 = 10.0 / (M[0] + M[1] * math.tan(g1) * math.tan(g1 + math.atan(0.1)))
    first = result.run.impacts[0]
    assert first["vk before"] == 0.0
    assert first["t"] == pytest.approx(math.sqrt(2 * 0.5e-3 / (math.sin(g2) * math.tan(g1) * a0)), rel=1e-9)
    rows = _open_rows(result)
    assert rows.sum() > 1 and np.all(result.run.y[rows, 2:] == 0.0)


def test_a_resting_groups_stick_is_the_rigid_chains_rest_decision_on_its_own_stages(chain_module):
    """Clearance in stage 2, body 2 free and unforced; bodies 0 and 1 at rest under forces (F0, F1) on a grid: the
    run keeps them at rest exactly where ``chain_decision.rest`` (the Python decision the derivation uses) admits the
    statics of the group alone, stage 1 (30 deg, mu 0.3; Psi_t = tan(g + rho), Psi_i = tan(g - rho), levers 1) with
    forces (F0, F1), and they leave rest otherwise; every run decides (status finished)."""
    from tswm_common.chain_decision import Statics, rest

    module = chain_module(_scene("held-grid", open_stage=2, g2=40.0, mu1=0.3, mu2=0.1, f0=0.0, f2=0.0))
    g1, rho1 = 30 * DEG, math.atan(0.3)
    stuck = {True: 0, False: 0}
    for f1 in (-10.0, 0.0, 7.0):
        for f0 in np.linspace(-13.0, 13.0, 14):
            result = simulate_chain(module, {"force_0": float(f0), "force_1": f1}, t_end=1e-3, points=3)
            assert result.status == "finished", (f0, f1, result.message)
            _, why_not = rest(Statics(((math.tan(g1 + rho1), math.tan(g1 - rho1)),), (1.0,), (1.0,), (f0, f1)))
            held = result.stages[0].phases[0].regime == "resting"
            assert held == (why_not == ""), (f0, f1)
            assert held == bool(np.all(result.run.y[:, :2] == 0.0)), (f0, f1)
            stuck[held] += 1
    assert stuck[True] >= 4 and stuck[False] >= 20
