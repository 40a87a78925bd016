"""Where the run comes to rest mid-run, the mode comes from the same contact conditions as at the start.

Two ways to rest mid-run, each case solved by hand (``at_rest``: Newton per body, every candidate
with its contact force written out): v1 sliding down to 0 under constant forces (a slide that
decelerates, started at v1(0) = -a1 T_REST so that it stops at T_REST), and a load step while
sticking. tswm must take the one candidate that holds, with its a1 and S2 on every row after
the event, or stop there (indeterminate: several hold, a Painleve solution among them). Before,
tswm tested the static contact force first and parted the flanks where a light worm on a heavy
wheel slides on (bwd_a coming to rest under an 8 kN drive goes on forward on flank a).
"""
import collections
import itertools
import math

import numpy as np
import pytest

from hard_cases.at_rest import DEG, WEDGE, expected, hand_slide, hand_start
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.sweeps.sweep import sweep

CLEARANCE = 5e-4
T_REST = 5e-4  # a decelerating slide stops here
T_STEPS = (1e-3, 2e-3)  # the load schedule's breakpoints

SCENE = WEDGE + """\
[load]
law = "schedule"
variable = "t"
shape = "steps"
at = ["1 ms", "2 ms"]
values = [{{ value = "0 N", free = true }}, {{ value = "0 N", free = true }}, {{ value = "0 N", free = true }}]
[modes]
include = ["forward", "backward", "stick"]
[run]
t_end = "10 ms"
"""
BACKLASH = 'clearance = "0.5 mm"\n[impact]\nrestitution = 0.4'

FRICTION = [(8.0, 6.0), (5.0, 12.0)]
MASSES = [(1.3, 1500.0), (50.0, 2.0)]
DRIVES = [200.0, 8000.0, -3000.0]
LOADS = [2000.0, -5000.0]
# where the contact is: flank a, flank b (both with a clearance: the flanks in contact), none
STARTS = {"flank a": [1], "flank b": [-1], "no clearance": [1, -1]}


@pytest.fixture(scope="module")
def models(scene_module):
    return {"backlash": scene_module(SCENE.format(name="rest-backlash", clearance=BACKLASH)),
            "rigid": scene_module(SCENE.format(name="rest-rigid", clearance=""))}


def params(friction, masses, F1, loads):
    (gamma, rho), (m1, m2) = friction, masses
    return {"gamma": gamma * DEG, "friction_rho": rho * DEG, "m1": m1, "m2": m2, "F1": F1,
            **{f"F2_{k}": F2 for k, F2 in enumerate(loads)}}


def decelerating_slides():
    """(start, friction, masses, F1, F2, direction, flank) of every grid case where sliding in
    ``direction`` on one flank (the one whose contact force is >= 0, with D > 0) decelerates."""
    cases = []
    for start, (gamma, rho), (m1, m2), F1, F2, s in itertools.product(STARTS, FRICTION, MASSES, DRIVES, LOADS,
                                                                          (1, -1)):
        slides = [(f, hand_slide(gamma * DEG, rho * DEG, m1, m2, F1, F2, f, s)) for f in STARTS[start]]
        holding = [f for f, (a1, N, _, regular) in slides if N >= 0.0 and regular and s * a1 < 0.0]
        if len(holding) == 1 and sum(N >= 0.0 for _, (_, N, _, _) in slides) == 1:
            cases.append((start, (gamma, rho), (m1, m2), F1, F2, s, holding[0]))
    return cases


SLIDES = decelerating_slides()


def assert_decided_by_hand(r, e, found):
    """Event ``e`` of run ``r`` leads where the hand candidates ``found`` say: the one that holds,
    with its a1 and S2 on every row of the phase after it, or a stop there naming them."""
    status, mode = expected(found)
    if status == "indeterminate":
        assert r.status == status and e.to_mode is None and r.t_stop == e.t, (found, r.message)
        for name, *_ in found:
            assert name in r.message
        assert f"at t = {e.t:.9g} s" in r.message
        return
    if status == "inconsistent":
        assert r.status == status and f"in mode {mode}" in r.message, (found, r.message)
        return
    assert e.to_mode == mode, (found, r.message, r.events)
    [phase] = [ph for ph in r.phases if ph.t_start <= e.t < ph.t_end]   # (stick after stick: one phase)
    rows = (r.t > e.t) & (r.t < phase.t_end)
    assert rows.sum() >= 2
    a1, S2 = found[0][1:3]
    np.testing.assert_allclose(r.a1[rows], a1, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(r.S2[rows], S2, rtol=1e-9, atol=1e-6)


def case_id(*values):
    """A readable test id: 'flank a-8,6-1.3,1500-8000-2000--1-1' (start, gamma,rho, m1,m2, F1, F2, s, flank)."""
    words = []
    for value in values:
        if isinstance(value, tuple):
            words.append(",".join(f"{v:g}" for v in value))
        elif isinstance(value, bool):
            words.append("rigid" if value else "backlash")
        else:
            words.append(f"{value:g}" if isinstance(value, float) else str(value))
    return "-".join(words)


@pytest.mark.heavy
@pytest.mark.parametrize("start, friction, masses, F1, F2, s, flank", SLIDES, ids=[case_id(*c) for c in SLIDES])
def test_a_slide_that_stops_mid_run_goes_on_by_the_contact_conditions(models, start, friction, masses, F1, F2, s,
                                                                     flank):
    """v1 reaches 0 at T_REST: the mode after it is the hand solution's at rest, as at a start."""
    (gamma, rho), (m1, m2) = friction, masses
    a1, _, S2, _ = hand_slide(gamma * DEG, rho * DEG, m1, m2, F1, F2, flank, s)
    rigid = start == "no clearance"
    r = simulate(models["rigid" if rigid else "backlash"], params(friction, masses, F1, (F2, F2, F2)),
                 v1=-a1 * T_REST, **({} if rigid else {"gap": 0.0 if flank > 0 else CLEARANCE}),
                 t_end=2 * T_REST, points=2001, rtol=1e-10, atol=1e-13)
    sliding = ("fwd_" if s > 0 else "bwd_") + ("a" if flank > 0 else "b")
    assert r.phases[0].mode == sliding
    before = r.t < T_REST * (1 - 1e-6)
    np.testing.assert_allclose(r.a1[before], a1, rtol=1e-9)
    e = r.events[0]
    assert (e.guard, e.from_mode) == ("v1", sliding) and e.t == pytest.approx(T_REST, rel=1e-8)
    assert_decided_by_hand(r, e, hand_start(gamma * DEG, rho * DEG, m1, m2, F1, F2, STARTS[start]))


LOAD_STEPS = list(itertools.product((False, True), FRICTION, MASSES, DRIVES, LOADS))


@pytest.mark.parametrize("rigid, friction, masses, F1, F2", LOAD_STEPS, ids=[case_id(*c) for c in LOAD_STEPS])
def test_a_load_step_while_sticking_goes_on_by_the_contact_conditions(models, rigid, friction, masses, F1, F2):
    """Stuck with the contact force along the flank normal (F2 = -F1 / tan gamma: no friction
    needed; on flank a for F1 > 0, on b for F1 < 0), the load steps to F2 at 1 ms."""
    (gamma, rho), (m1, m2) = friction, masses
    flanks = [1, -1] if rigid else [1 if F1 > 0 else -1]
    held = -F1 / math.tan(gamma * DEG)
    assert expected(hand_start(gamma * DEG, rho * DEG, m1, m2, F1, held, flanks)) == ("finished", "stick")
    r = simulate(models["rigid" if rigid else "backlash"], params(friction, masses, F1, (held, F2, F2)),
                 **({} if rigid or F1 > 0 else {"gap": CLEARANCE}), t_end=1.5e-3, points=3001,
                 rtol=1e-10, atol=1e-13)
    assert r.phases[0].mode == "stick"
    e = r.events[0]
    assert (e.guard, e.from_mode) == ("load_at1", "stick") and e.t == pytest.approx(T_STEPS[0], rel=1e-12)
    assert_decided_by_hand(r, e, hand_start(gamma * DEG, rho * DEG, m1, m2, F1, F2, flanks))


def test_the_grids_cover_every_kind_of_rest():
    """Stops mid-run in stick, breakaway each way on each flank, parting, and several candidates
    with a Painleve solution among them (indeterminate), so each branch is checked mid-run."""
    kinds = set()
    for start, (gamma, rho), (m1, m2), F1, F2, s, flank in SLIDES:
        status, mode = expected(hand_start(gamma * DEG, rho * DEG, m1, m2, F1, F2, STARTS[start]))
        kinds.add(mode if status == "finished" else status)
    for rigid, (gamma, rho), (m1, m2), F1, F2 in LOAD_STEPS:
        flanks = [1, -1] if rigid else [1 if F1 > 0 else -1]
        status, mode = expected(hand_start(gamma * DEG, rho * DEG, m1, m2, F1, F2, flanks))
        kinds.add(mode if status == "finished" else status)
    assert kinds >= {"stick", "fwd_a", "fwd_b", "bwd_a", "bwd_b", "free", "indeterminate"}
    assert ("flank a", (8.0, 6.0), (1.3, 1500.0), 8000.0, 2000.0, -1, 1) in SLIDES   # the light worm


def random_stops(n, seed):
    """n random cases of the light worm's scene (gamma 8 deg, rho 6 deg, a clearance, on flank a):
    stuck at first (F2_0 = -F1 / tan gamma), the load step at 1 ms sets it sliding on flank a,
    the one at 2 ms decelerates it to rest before t_end. Returns (free values by name per case,
    the hand candidates at that rest)."""
    rng = np.random.default_rng(seed)
    gamma, rho = 8.0 * DEG, 6.0 * DEG
    cases = []
    while len(cases) < n:
        m1, m2, F1 = rng.uniform(0.5, 20.0), rng.uniform(10.0, 3000.0), rng.uniform(1000.0, 10000.0)
        F2_1, F2_2 = rng.uniform(-40000.0, 10000.0), rng.uniform(-40000.0, 40000.0)
        [*first] = hand_start(gamma, rho, m1, m2, F1, F2_1, [1])
        if len(first) != 1 or first[0][0] not in ("fwd_a", "bwd_a"):
            continue
        s, v = (1 if first[0][0] == "fwd_a" else -1), first[0][1] * (T_STEPS[1] - T_STEPS[0])
        a1, N, _, regular = hand_slide(gamma, rho, m1, m2, F1, F2_2, 1, s)
        if N < 0.0 or not regular or s * a1 >= 0.0 or T_STEPS[1] - v / a1 > 9e-3:
            continue
        values = {"gamma": gamma, "friction_rho": rho, "m1": m1, "m2": m2, "F1": F1,
                  "F2_0": -F1 / math.tan(gamma), "F2_1": F2_1, "F2_2": F2_2}
        cases.append((values, first[0][0], hand_start(gamma, rho, m1, m2, F1, F2_2, [1])))
    return cases


def test_a_random_sweep_of_stops_mid_run_goes_on_as_the_hand_solution_says(models):
    """3000 random stops mid-run through the sweep (the parallel batch): stick, slide at the first
    load step, v1 -> 0 after the second; the mode after the stop (or the status) is the hand's."""
    module = models["backlash"]
    cases = random_stops(3000, seed=1)
    P = np.array([[values[name] for name in module.PARAM_NAMES] for values, *_ in cases])
    table = sweep(module, P, {}).table
    seen = collections.Counter()
    for (values, sliding, found), status, codes in zip(cases, table["status"], table["modes"]):
        modes = [module.MODES[int(c)] for c in codes.split()]
        want, mode = expected(found)
        seen[mode if want == "finished" else want] += 1
        assert modes[:2] == ["stick", sliding], values
        if want == "finished":
            assert status == "finished" and modes[2] == mode, (values, found, modes)
        else:
            assert status == want and len(modes) == 2, (values, found, status)
    assert seen["stick"] > 0 and seen["bwd_a"] > 0 and seen["fwd_a"] > 0, seen
