"""A chain with a clearance in one stage, run (tswm_runtime/chains/kernel.py, backlash.py) against closed forms, the
restitution law and scipy's solve_ivp on equations written by hand.

The chain: three bodies on two plain wedges (levers 1: x1 = q_{k-1}, x2 = q_k; body 1 moves tan(g1) times body 0,
stage 2's gap g = gap0 + q2 cos(g2) - q1 sin(g2)), the clearance in stage 2. Open: bodies 0 and 1 move together
through stage 1 (a0 = F0 / (M0 + M1 tan(g1) tan(g1 + rho1)), body 1's force 0), body 2 alone (a2 = F2 / M2); the
impact: group 0 reduced to x1 by its response to an impulse there (m1 = 1 / (tan(g1) dv0) with dv0 the speed change of
body 0 for a unit impulse on body 1 through the stage's FTF), body 2 is m2 = M2, the flank frame's inverse mass W.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from derivation.chain.scene import parse_chain
from tswm_runtime.hybrid.impact import collide
from tswm_runtime.simulation.chain import simulate_chain, summary

DEG = math.pi / 180
G1, G2 = 30 * DEG, 40 * DEG
M = (1.0, 2.0, 3.0)


def _scene(name, *, mu=0.0, e=0.5, clearance="1 mm", gap="0.5 mm", f0=10.0, f2=-2.0, stiffness=0.0, v0=0.0,
           t_end=0.3, valve="", clear=2, stiffness0=None):
    """The chain, its clearance in stage ``clear``; body 0 with a spring where ``stiffness0`` is given."""
    stages = "".join(f'[[stage]]\nkind = "wedge"\ngamma = "{g} deg"\nmu = {mu!r}\n' +
                     (f'clearance = "{clearance}"\nrestitution = {e!r}\n' if i == clear else "")
                     for i, g in ((1, 30), (2, 40)))
    spring0 = "" if stiffness0 is None else f'stiffness = "{stiffness0!r} N/m"\n'
    return (f'name = "{name}"\n{stages}'
            f'[[body]]\nmass = "1 kg"\nforce = "{f0!r} N"\n{spring0}[[body]]\nmass = "2 kg"\nforce = "0 N"\n'
            f'[[body]]\nmass = "3 kg"\nforce = "{f2!r} N"\nstiffness = "{stiffness!r} N/m"\n{valve}'
            f'[run]\nt_end = {t_end!r}\nv0 = {v0!r}\ngap_{clear} = "{gap}"\nrtol = 1e-10\natol = 1e-12\n')


def _open_accels(mu, f0, f2):
    """(a0, a2, g''): the groups' accelerations while stage 2 is open (stage 1 sliding tractive forward), the gap's."""
    rho1 = math.atan(mu)
    a0 = f0 / (M[0] + M[1] * math.tan(G1) * math.tan(G1 + rho1))
    a2 = f2 / M[2]
    return a0, a2, a2 * math.cos(G2) - math.tan(G1) * a0 * math.sin(G2)


def _masses(mu, regime=1):
    """(m1, m2): the effective masses at stage 2's x1 (bodies 0 and 1 through stage 1 sliding tractive, regime 1, or
    inverse-tractive, -1: its friction angle's sign) and x2."""
    rho1 = regime * math.atan(mu)
    dv0 = math.tan(G1 + rho1) / (M[0] + M[1] * math.tan(G1) * math.tan(G1 + rho1))
    return 1.0 / (math.tan(G1) * dv0), M[2]


def _hand_impact(mu, e, v0, v2, flank=1.0, regime=1):
    """Stage 2's impact by hand: the frame (nu, s) of x1 = tan(g1) v0, x2 = v2, W of the two effective masses (stage 1
    in ``regime``), Routh's process (collide) with tan(rho2) and e; body 2 takes P_n f n + P_t t, body 1's side the
    opposite, along each guide. Returns (v0 after, v2 after, nu before, nu after, energy lost)."""
    m1, m2 = _masses(mu, regime)
    s2, c2 = math.sin(G2), math.cos(G2)
    x1 = math.tan(G1) * v0
    nu, slip = flank * (v2 * c2 - x1 * s2), v2 * s2 + x1 * c2
    w_nt = flank * s2 * c2 * (1 / m2 - 1 / m1)
    p_n, p_t, nu_after, _, lost, _ = collide(nu, slip, c2**2 / m2 + s2**2 / m1, w_nt, s2**2 / m2 + c2**2 / m1, mu, e)
    x1_after = x1 - (flank * p_n * s2 - p_t * c2) / m1
    return x1_after / math.tan(G1), v2 + (flank * p_n * c2 + p_t * s2) / m2, nu, nu_after, lost


def _kinetic(v0, v2):
    return 0.5 * (M[0] * v0**2 + M[1] * (math.tan(G1) * v0)**2 + M[2] * v2**2)


def test_frictionless_gap_closes_at_the_quadratic_time_and_bounces_by_newtons_law(chain_module):
    """Started open (gap 0.5 mm) at rest, driven: g(t) = g0 + g'' t^2 / 2 closes at sqrt(-2 g0 / g''); each impact is
    Newton's restitution of the two effective masses; the bounces end at their accumulation point t1 + 2 e |nu1| /
    (|g''| (1 - e)) within the tolerance of the settling rule, the stage then closed (tractive on flank a); the
    kinetic energy at the end equals the forces' work less the impacts' losses, each (1 - e^2)/2 m_n nu^2."""
    e = 0.5
    module = chain_module(_scene("gap-newton", e=e))
    result = simulate_chain(module, points=5)
    assert result.status == "finished"
    impacts = result.run.impacts
    a0, a2, gap_accel = _open_accels(0.0, 10.0, -2.0)
    t1 = math.sqrt(-2 * 0.5e-3 / gap_accel)
    first = impacts[0]
    assert first["t"] == pytest.approx(t1, rel=1e-9) and first["flank"] == "a"
    v0, v2 = a0 * t1, a2 * t1
    assert first["v0 before"] == pytest.approx(v0, rel=1e-9) and first["vk before"] == pytest.approx(v2, rel=1e-9)
    m1, m2 = _masses(0.0)
    nu = gap_accel * t1
    w_nn = math.sin(G2)**2 / m1 + math.cos(G2)**2 / m2
    P = -(1 + e) * nu / w_nn
    assert first["nu before"] == pytest.approx(nu, rel=1e-9) and first["nu after"] == pytest.approx(-e * nu, rel=1e-9)
    assert first["v0 after"] == pytest.approx((math.tan(G1) * v0 - P * math.sin(G2) / m1) / math.tan(G1), rel=1e-9)
    assert first["vk after"] == pytest.approx(v2 + P * math.cos(G2) / m2, rel=1e-9)
    for row in impacts:   # the last, within the tolerances, taken as plastic
        kept = 0.0 if row["closed"] else e
        assert row["energy lost"] == pytest.approx((1 - kept**2) / 2 * row["nu before"]**2 / w_nn, rel=1e-9)
    # the bounces: each approach at e times the last rebound's speed (free flight under constant accelerations)
    assert impacts[-1]["nu after"] == pytest.approx(0.0, abs=1e-15)
    for before, after in zip(impacts, impacts[1:]):
        assert after["nu before"] == pytest.approx(-before["nu after"], rel=1e-7)
        assert after["t"] - before["t"] == pytest.approx(2 * before["nu after"] / -gap_accel, rel=1e-7)
    assert [row["closed"] for row in impacts] == [False] * (len(impacts) - 1) + [True]
    t_acc = t1 + 2 * e * abs(nu) / (-gap_accel * (1 - e))
    last = impacts[-1]["t"]
    rest_of_bounces = 2 * e * abs(impacts[-1]["nu before"]) / (-gap_accel * (1 - e))
    assert last < t_acc and t_acc - last == pytest.approx(rest_of_bounces, rel=1e-6)
    stage = result.stages[1]
    assert [p.regime for p in stage.phases] == ["open", "tractive"] and stage.phases[1].t_start == last
    # energy: work of the constant forces less the impacts' losses
    y = result.run.y[-1]
    work = 10.0 * y[0] - 2.0 * y[2]
    lost = sum(row["energy lost"] for row in impacts)
    assert _kinetic(y[1], y[3]) == pytest.approx(work - lost, rel=1e-8)
    assert y[3] == pytest.approx(math.tan(G1) * math.tan(G2) * y[1], rel=1e-12)    # closed: the rigid chain's ratio
    text = "\n".join(summary(result, module))
    assert f"stage 2 impacts ({len(impacts)}):" in text and "on flank a" in text and "closed" in text


@pytest.mark.parametrize("mu", [0.05, 0.15])
def test_impact_with_friction_is_the_single_stage_law_on_the_effective_masses(chain_module, mu):
    """Friction in both stages: the closing time is the quadratic gap's with stage 1's FTF in group 0's motion, and
    the impact is Routh's process with Coulomb's friction of stage 2 on the hand-written W of the effective masses."""
    e = 0.3
    module = chain_module(_scene(f"gap-friction-{int(mu * 100)}", mu=mu, e=e))
    result = simulate_chain(module, points=5)
    first = result.run.impacts[0]
    a0, a2, gap_accel = _open_accels(mu, 10.0, -2.0)
    t1 = math.sqrt(-2 * 0.5e-3 / gap_accel)
    assert first["t"] == pytest.approx(t1, rel=1e-9)
    v0_after, v2_after, nu, nu_after, lost = _hand_impact(mu, e, first["v0 before"], first["vk before"])
    assert first["nu before"] == pytest.approx(nu, rel=1e-10) and first["nu after"] == pytest.approx(nu_after, rel=1e-9)
    assert first["v0 after"] == pytest.approx(v0_after, rel=1e-10) and first["vk after"] == pytest.approx(v2_after,
                                                                                                     rel=1e-10)
    assert first["energy lost"] == pytest.approx(lost, rel=1e-9)


def _hand_cycle(t_end):
    """Scipy's DOP853 (rtol 1e-12) on Newton per body, frictionless: closed on flank b (body 2 pushed by 6 N less its
    spring's 400 N/m q2, the chain moving forward at 1 m/s) until stage 2's force on body 2 reaches 0, open (bodies 0
    and 1 coast, body 2 on its spring) until the gap closes on flank a, a plastic impact of the two effective masses,
    closed again. Returns (opening time, impact time, the normal speed at the flank before the impact, sol)."""
    c1 = math.tan(G1)
    c2 = c1 * math.tan(G2)
    inertia = M[0] + M[1] * c1**2 + M[2] * c2**2

    def force2(q2):
        return 6.0 - 400.0 * q2

    def closed(_, y):
        a0 = c2 * force2(y[2]) / inertia
        return [y[1], a0, y[3], c2 * a0]

    def pushes(_, y):   # stage 2's force on body 2, M2 a2 - F2: < 0 on flank b
        return M[2] * c2 * c2 * force2(y[2]) / inertia - force2(y[2])
    pushes.terminal, pushes.direction = True, 1

    def flying(_, y):
        return [y[1], 0.0, y[3], force2(y[2]) / M[2]]

    def gap(_, y):
        return 1e-3 + y[2] * math.cos(G2) - c1 * y[0] * math.sin(G2)
    gap.terminal, gap.direction = True, -1
    tight = {"method": "DOP853", "rtol": 1e-12, "atol": 1e-14, "dense_output": True}
    one = solve_ivp(closed, (0, t_end), [0.0, 1.0, 0.0, c2], events=pushes, **tight)
    t_open = one.t_events[0][0]
    two = solve_ivp(flying, (t_open, t_end), one.y_events[0][0], events=gap, **tight)
    t_hit = two.t_events[0][0]
    q0, v0, q2, v2 = two.y_events[0][0]
    m1, m2 = M[0] / c1**2 + M[1], M[2]
    x1 = c1 * v0
    nu = v2 * math.cos(G2) - x1 * math.sin(G2)
    P = -nu / (math.sin(G2)**2 / m1 + math.cos(G2)**2 / m2)
    v0 = (x1 - P * math.sin(G2) / m1) / c1
    three = solve_ivp(closed, (t_hit, t_end), [q0, v0, q2, c2 * v0], **tight)
    return t_open, t_hit, nu, three


def test_an_open_close_cycle_agrees_with_scipy_on_the_hand_equations(chain_module):
    module = chain_module(_scene("gap-cycle", e=0.0, gap="1 mm", f0=0.0, f2=6.0, stiffness=400.0, v0=1.0,
                                 t_end=0.25))
    result = simulate_chain(module, points=6)
    t_open, t_hit, _, ref = _hand_cycle(0.25)
    assert result.status == "finished"
    opened = [e for e in result.events if e["to"] == "open: stage 2"]
    assert len(opened) == 1 and opened[0]["t"] == pytest.approx(t_open, rel=1e-8)
    (impact,) = result.run.impacts
    assert impact["t"] == pytest.approx(t_hit, rel=1e-8) and impact["closed"] and impact["nu after"] == 0.0
    stage = result.stages[1]
    assert [(p.regime, p.flank) for p in stage.phases] == [("inverse-tractive", "b"), ("open", ""), ("tractive", "a")]
    assert result.run.y[-1] == pytest.approx(ref.y[:, -1], rel=1e-7, abs=1e-10)


def test_each_event_of_a_cycle_gives_its_reason(chain_module):
    """The cycle's events in words, as the hand analysis has them: at the start stage 2 is closed on flank b (body 2
    pushed ahead by its spring drives body 1 and, through stage 1, body 0: both stages inverse-tractive; the modes
    loading flank a are no candidates); as body 2's push fades both stages' normal forces reach 0 together (body 0
    unforced: stage 1 carries only what body 2 pushes through), stage 1's guard fires first, no mode loading flank b
    holds any more (stage 2 would pull) and the chain cannot rest moving, so its flanks part, bodies 0 and 1 coasting
    forward, body 2 on its spring alone (no friction: its direction changes none of its forces),
    stage 1 carrying nothing (frictionless: the first regime, tractive); the flanks meet on flank a at the hand
    equations' normal speed and close (e = 0), and the closed chain is driven forward on flank a."""
    module = chain_module(_scene("gap-cycle", e=0.0, gap="1 mm", f0=0.0, f2=6.0, stiffness=400.0, v0=1.0,
                                 t_end=0.25))
    result = simulate_chain(module, points=6)
    _, _, nu, _ = _hand_cycle(0.25)
    start, opened, hit = result.events
    assert start["to"] == "forward: inverse-tractive (b), inverse-tractive (b)"
    assert start["reason"].startswith("stage 2 closed on flank b: the only consistent mode; rejected: forward: "
                                      "tractive (a), inverse-tractive (b): stage 1 would need N_1 = ")
    assert "tractive (a), tractive (a)" not in start["reason"] and "(b), tractive (a)" not in start["reason"]
    assert opened["guard"] == "N_1" and opened["reason"].startswith(
        "no mode loading flank b holds and the chain cannot rest with stage 2 pushing on it (no mode is consistent")
    assert "forward: tractive (a), inverse-tractive (b): stage 2 would need N_2 = " in opened["reason"]
    assert opened["reason"].endswith("; its flanks part from flank b; open phase: bodies 0..1 forward, body 2 free "
                                     "(its forces do not depend on its direction); closed stages: stage 1 tractive")
    words = f"stage 2's flanks meet on flank a: normal speed {nu:.6g} -> 0 m/s, closed (plastic, or its rebound "
    assert hit["reason"].startswith(words + "within the tolerances); stage 2 closed on flank a: the only consistent "
                                    "mode; rejected: ") and hit["to"] == "forward: tractive (a), tractive (a)"
    text = "\n".join(summary(result, module))
    assert all(f"      {e['reason']}" in text for e in result.events)


def _trip_scene(setting):
    """The cycle's scene with a switch on stage 2's force on body 2 at ``setting`` (N), 5 ms delay."""
    switch = f'[switch]\non = "stage 2"\nsetting = "{setting} N"\ndelay = "5 ms"\n[run]'
    return _scene("gap-trip", e=0.0, gap="1 mm", f0=0.0, f2=6.0, stiffness=400.0, v0=1.0,
                  t_end=0.25).replace("[run]", switch)


@pytest.mark.parametrize("setting", [15.0, 1.0])
def test_travel_at_the_trip_is_the_last_bodys_own_coordinate(chain_module, setting):
    """The cycle above with a switch on stage 2's force on body 2 (5 ms delay): at 15 N it picks up after the stage
    has opened and closed again, where the force reaches 15 N; at 1 N at the impact, where the closing makes the
    force jump from 0 past the setting. The travel at the trip is body 2's q2 on the hand equations (scipy), not the
    rigid kinematics' c2 q0, which counts the backlash taken up before (here the 1 mm clearance along the flanks'
    normal); the thrust there and the extra travel to the end (body 2 still moving forward) too."""
    module = chain_module(_trip_scene(setting))
    result = simulate_chain(module, points=6)
    t_open, t_hit, _, ref = _hand_cycle(0.25)
    c2 = math.tan(G1) * math.tan(G2)
    inertia = M[0] + M[1] * math.tan(G1)**2 + M[2] * c2**2

    def thrust(t):   # stage 2's force on body 2 while closed: M2 a2 - F2
        q2 = ref.sol(t)[2]
        return M[2] * c2 * c2 * (6.0 - 400.0 * q2) / inertia - (6.0 - 400.0 * q2)
    assert thrust(t_hit) > 1.0
    t_pick = t_hit if setting == 1.0 else brentq(lambda t: thrust(t) - setting, t_hit, 0.25, xtol=1e-15)
    t_trip = t_pick + 0.005
    trip = result.answers["trip"]
    assert result.status == "finished" and t_hit <= t_pick
    assert trip["t"] == pytest.approx(t_trip, rel=1e-8)
    q0, v0, q2, v2 = ref.sol(t_trip)
    assert trip["travel"] == pytest.approx(q2, rel=1e-8)
    assert abs(c2 * q0 - q2) > 1e-4   # the rigid reading is off by the backlash
    assert trip["thrust"] == pytest.approx(thrust(t_trip), rel=1e-7)
    assert (ref.y[3] > 0).all()
    assert result.answers["extra_travel"] == pytest.approx(ref.y[2, -1] - q2, rel=1e-7)


def _same_as_simulate(module, grid, points, **run):
    """The chain sweep's table of ``grid`` (run settings ``run``) against simulate_chain of each case's values
    (``--set``): every answer and count exactly, the impacts' count and energy lost to rounding (summed in another
    order)."""
    from tswm_runtime.sweeps.chain import sizing

    table = sizing(module, grid, {"points": points, **run}).table
    names = list(grid)
    for _, row in table.iterrows():
        case = {name: row[column] for name, column in zip(names, table.columns)}
        single = simulate_chain(module, case, points=points, **run)
        trip = single.answers["trip"] or {}
        assert row["status"] == single.status, case
        for column, value in (("t_trip [s]", trip.get("t")), ("travel at trip [m]", trip.get("travel")),
                              ("thrust at trip [N]", trip.get("thrust")), ("t_stop [s]", single.t_stop),
                              ("extra travel [m]", single.answers["extra_travel"])):
            np.testing.assert_array_equal(row[column], np.nan if value is None else value, err_msg=column)
        assert (row["events"], row["steps"], row["impacts"]) == (len(single.events), single.n_steps,
                                                                 len(single.run.impacts))
        assert row["holds"] == single.answers["holds"]["verdict"]
        lost = sum(impact["energy lost"] for impact in single.run.impacts)
        assert row["impact loss [J]"] == pytest.approx(lost, rel=1e-14, abs=1e-300)
    return table


def test_a_chain_sweep_with_a_clearance_runs_each_case_as_simulate(chain_module):
    """The chain sweep of a chain with a clearance runs every case on the kernel's path of simulate (mode OPEN,
    impacts): per case the same answers as simulate_chain with the case's values; a case that stops early (its
    bounces exceed max_events) keeps its status and the sweep goes on to the next, an unforced one whose groups both
    stick while the stage is open (force_0 = force_2 = 0: no event after the start)."""
    table = _same_as_simulate(chain_module(_trip_scene(15.0)), {"switch_setting": [1.0, 15.0]}, 6)
    assert list(table["status"]) == ["finished"] * 2 and list(table["impacts"]) == [1, 1]
    assert table["t_trip [s]"].tolist()[0] < table["t_trip [s]"].tolist()[1]
    table = _same_as_simulate(chain_module(_scene("gap-rest", mu=0.1, f0=0.0, f2=0.0)), {"force_0": [10.0, 0.0]}, 5,
                              max_events=2)
    assert list(table["status"]) == ["too-many-events", "finished"], table["status"]
    assert table["impacts"].tolist() == [1, 0] and table["events"].tolist()[1] == 1


def test_the_scene_keeps_the_clearance(tmp_path):
    chain = parse_chain(_scene("gap-keys"), "gap.toml")
    (c,) = chain.clearances
    assert (c.stage, c.clearance.value, c.restitution.value, c.gap.value) == (2, 1e-3, 0.5, 0.5e-3)
    assert c.gap.key == "run.gap_2" and c.clearance.key == "stage[2].clearance"


def test_a_group_left_unforced_at_rest_while_open_sticks(chain_module):
    """Bodies 0 and 1 unforced and at rest while stage 2 is open: their rest holds (no force asks anything of stage
    1's stick cone) and leaving it would need an acceleration they do not have, so they stay (speeds exactly 0) while
    body 2 alone (-2 N) closes the gap g = g0 + cos(g2) q2 at sqrt(2 g0 / (cos(g2) 2 N / M2)); the impact pushes them
    backward through stage 1 driven from body 1, inverse-tractive: ``collide`` on W with that stage's m1."""
    module = chain_module(_scene("gap-rest", mu=0.1, f0=0.0))
    result = simulate_chain(module, points=31)
    assert result.status == "finished", result.message
    first = result.run.impacts[0]
    assert first["v0 before"] == 0.0 and first["flank"] == "a"
    assert first["t"] == pytest.approx(math.sqrt(2 * 0.5e-3 / (math.cos(G2) * 2.0 / M[2])), rel=1e-9)
    rows = result.run.t < first["t"]
    assert rows.sum() > 1 and np.all(result.run.y[rows, :2] == 0.0)
    assert result.stages[0].phases[0].regime == "resting"
    v0_after, v2_after, nu, nu_after, lost = _hand_impact(0.1, 0.5, 0.0, first["vk before"], regime=-1)
    assert first["nu before"] == pytest.approx(nu, rel=1e-10) and first["nu after"] == pytest.approx(nu_after, rel=1e-9)
    assert first["v0 after"] == pytest.approx(v0_after, rel=1e-10) and first["vk after"] == pytest.approx(v2_after,
                                                                                                     rel=1e-10)


def test_the_figure_shows_the_gap_of_the_hand_kinematics(chain_module, tmp_path):
    """The stage's gap at the output rows is g0 + q2 cos(g2) - tan(g1) q0 sin(g2) (the coordinates of the run's
    rows), inside [0, clearance] within the tolerances; the figure is written with it."""
    from tswm_runtime.simulation.chain import gaps, plot

    module = chain_module(_scene("gap-plot"))
    result = simulate_chain(module, points=21)
    y = result.run.y
    hand = 0.5e-3 + y[:, 2] * math.cos(G2) - math.tan(G1) * y[:, 0] * math.sin(G2)
    assert gaps(module, result) == pytest.approx(hand, rel=1e-12, abs=1e-15)
    assert (hand >= -1e-9).all() and (hand <= 1e-3 + 1e-9).all()
    assert plot(result, module, tmp_path / "gap.png").stat().st_size > 0


def test_the_last_body_held_by_its_valve_friction_waits_for_the_flanks(chain_module):
    """The stem at rest, its load (2 N) within its packing's friction (5 N), while the driven group closes the gap:
    it stays (a2 = 0), so the gap closes at sqrt(2 g0 / (tan(g1) a0 sin(g2))) with group 0's a0 through stage 1's
    FTF; the impact takes it along (its friction finite, the impulse not)."""
    module = chain_module(_scene("gap-held", mu=0.1, e=0.3, valve='packing = "5 N"\n'))
    result = simulate_chain(module, points=5)
    assert result.status != "group-at-rest", result.message
    a0, _, _ = _open_accels(0.1, 10.0, 0.0)
    first = result.run.impacts[0]
    assert first["vk before"] == 0.0
    assert first["t"] == pytest.approx(math.sqrt(2 * 0.5e-3 / (math.tan(G1) * a0 * math.sin(G2))), rel=1e-9)
    v0_after, v2_after, *_ = _hand_impact(0.1, 0.3, first["v0 before"], 0.0)
    assert first["v0 after"] == pytest.approx(v0_after, rel=1e-10) and first["vk after"] == pytest.approx(v2_after,
                                                                                                     rel=1e-10)


@pytest.mark.parametrize("f2", [0.0, 0.5])
def test_extra_travel_is_the_free_stems_farthest_point_on_the_seat(chain_module, f2):
    """Stage 2 open from the start (gap 0.5 mm), the chain coasting at v0 = 0.1 m/s, body 0 pushed by 0.2 N: the stem
    (body 2, M2, force F2, no valve friction: a free group) flies on its own, v2 = c2 v0 + F2 t / M2, into a seat at
    2 mm of k = 100 N/mm and turns on it before the flanks meet (the run ends before); the switch on body 0's 0.2 N
    (setting 0.1 N) trips after its 5 ms delay. The farthest point (energy: F2 x + M2 v_s^2 / 2 = k x^2 / 2 beyond
    the seat, v_s the stem's speed at the seat) less the travel at the trip is the extra travel, and the stem's turn
    is an event at that point."""
    seat, k, delay, rtol = 2e-3, 1e5, 5e-3, 1e-10   # rtol: the scene's run.rtol
    switch = '[switch]\non = "motor"\nsetting = "0.1 N"\ndelay = "5 ms"\n[run]'
    text = _scene("gap-seat-free", f0=0.2, f2=f2, v0=0.1, t_end=0.052,
                  valve=f'seat = "{seat!r} m"\nseat_stiffness = "{k!r} N/m"\n').replace("[run]", switch)
    module = chain_module(text)
    result = simulate_chain(module, points=5)
    assert result.status == "finished", result.message
    assert not result.run.impacts   # the flanks meet after t_end (54.6 ms with F2 = 0)
    v2 = math.tan(G1) * math.tan(G2) * 0.1
    v_s = math.sqrt(v2**2 + 2 * f2 / M[2] * seat)
    x = f2 / k + math.sqrt((f2 / k)**2 + M[2] * v_s**2 / k)
    trip = result.answers["trip"]
    assert trip["t"] == pytest.approx(delay, rel=1e-12)
    assert trip["travel"] == pytest.approx(v2 * delay + f2 / (2 * M[2]) * delay**2, rel=1e-9)
    assert result.answers["extra_travel"] == pytest.approx(seat + x - trip["travel"], rel=10 * rtol)
    turns = [e["t"] for e in result.events if e["guard"] == "v_out"]
    assert len(turns) == 1
    if f2 == 0.0:   # at the seat after seat / v2, a quarter of the spring's period later
        assert turns[0] == pytest.approx(seat / v2 + math.pi / 2 * math.sqrt(M[2] / k), rel=10 * rtol)


@pytest.mark.parametrize("f0, k0", [(-2.0, 0.0), (-1.0, 1000.0)])
def test_the_free_input_groups_turn_is_an_event_at_its_closed_form(chain_module, f0, k0):
    """Stage 1 open from the start (gap 1 mm of 10 mm), the chain coasting at v0 = 0.1 m/s: body 0 alone is the
    input group, free (no closed stage, no valve), pushed by f0 less a spring k0 q0: from speed v0 it turns at
    t = M0 v0 / -f0 at q0 = M0 v0^2 / (-2 f0) (k0 = 0), or with w = sqrt(k0 / M0) at tan(w t) = v0 k0 / (-f0 w),
    q0 = f0 / k0 + sqrt((f0 / k0)^2 + (v0 / w)^2); the turn is a v0 event there. The output group (bodies 1 and 2
    through stage 2, frictionless, body 2 held back by 0.5 N) starts at c1 v0 and decelerates at
    a1 = tan(g2) F2 / (M1 + M2 tan(g2)^2); the gap g0 + q1 cos(g1) - q0 sin(g1) of the output rows is these hand
    kinematics' (it never reaches a flank)."""
    v0, f2, g0, rtol = 0.1, -0.5, 1e-3, 1e-10   # rtol: the scene's run.rtol
    module = chain_module(_scene("gap-free-input", f0=f0, f2=f2, v0=v0, t_end=0.08, clearance="10 mm", gap="1 mm",
                                 clear=1, stiffness0=k0))
    result = simulate_chain(module, points=9)
    assert result.status == "finished", result.message
    assert not result.run.impacts
    if k0 == 0.0:
        t_turn, far = M[0] * v0 / -f0, M[0] * v0**2 / (-2 * f0)

        def q0(t):
            return v0 * t + f0 / (2 * M[0]) * t**2
    else:
        w = math.sqrt(k0 / M[0])
        t_turn, far = math.atan2(v0 * k0, -f0 * w) / w, f0 / k0 + math.sqrt((f0 / k0)**2 + (v0 / w)**2)

        def q0(t):
            return f0 / k0 * (1 - np.cos(w * t)) + v0 / w * np.sin(w * t)
    (turn,) = [e for e in result.run.events if e.guard == "v0"]
    assert turn.t == pytest.approx(t_turn, rel=10 * rtol)
    _, y, _ = turn.seen
    assert y[0] == pytest.approx(far, rel=10 * rtol) and y[1] == pytest.approx(0.0, abs=1e-12)
    assert turn.to_mode == turn.from_mode == module.OPEN
    assert [e.guard for e in result.run.events] == ["start", "v0"]
    words = ("open phase: body 0 free (its forces do not depend on its direction), bodies 1..2 forward; closed stages: "
             "stage 2 tractive")
    assert all(e["reason"].endswith(words) for e in result.events)
    t = result.run.t
    a1 = math.tan(G2) * f2 / (M[1] + M[2] * math.tan(G2)**2)
    q1 = math.tan(G1) * v0 * t + a1 / 2 * t**2
    np.testing.assert_allclose(result.run.y[:, 0], q0(t), rtol=1e-8, atol=1e-8 * far)
    np.testing.assert_allclose(result.run.y[:, 2], q1, rtol=1e-8, atol=1e-8 * far)
    from tswm_runtime.simulation.chain import gaps

    hand = g0 + q1 * math.cos(G1) - q0(t) * math.sin(G1)
    assert gaps(module, result) == pytest.approx(hand, rel=1e-8, abs=1e-8 * far)
    assert (hand > 0).all() and (hand < 10e-3).all() and t[-1] > t_turn
