"""A chain with a clearance in both of its stages (one open at a time), run (tswm_runtime/chains/kernel.py, rules.py,
backlash.py) against the same chain without clearances, a closed form and scipy's solve_ivp on equations written by
hand.

The chain: three bodies (1, 2, 3 kg) on two plain wedges (30 and 40 deg, levers 1: x1 = q_{k-1}, x2 = q_k), each stage
with a clearance of 1 mm along its flanks' normal, both closed on flank a at the start. The hand reference
(``_hand``), frictionless, plastic impacts: per phase the bodies split at the open stage into rigid groups, each moving
as one body, a_first = sum r_j F_j / sum r_j^2 M_j with r_j the product of tan(gamma_i) of the closed stages between
the group's first body and body j; a closed stage k's generalized force on body k is R_k = sum over its group's bodies
j >= k of (r_j / r_k)(M_j a_j - F_j), >= 0 on flank a, <= 0 on flank b: the stage opens where it reaches 0; an open
stage's gap is g_k = gap0_k + q_k cos(gamma_k) - q_{k-1} sin(gamma_k), closing at 0 (flank a) or the clearance (flank
b), where the plastic impact of the two groups' effective masses at x1, x2 (sum (r_j / r_b)^2 M_j over each group)
takes the normal speed to 0 (P = -nu / (sin^2 / m1 + cos^2 / m2)). Every event found by solve_ivp's event location
(DOP853, rtol 1e-12).
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from derivation.chain.scene import parse_chain
from tswm_runtime.simulation.chain import simulate_chain, summary

DEG = math.pi / 180
GAMMA = (30 * DEG, 40 * DEG)
M = (1.0, 2.0, 3.0)
CLEARANCE = 1e-3


def _scene(name, forces, stiffness=(0.0, 0.0, 0.0), *, v0=0.0, t_end=0.3, mu=0.0, clearances=True):
    """The two-stage chain: body j pushed by forces[j] less stiffness[j] q_j, both stages with a 1 mm clearance
    (plastic) closed on flank a at the start, or none (``clearances`` False)."""
    gap = f'clearance = "{CLEARANCE * 1e3!r} mm"\nrestitution = 0.0\n' if clearances else ""
    text = f'name = "{name}"\n'
    for g in (30, 40):
        text += f'[[stage]]\nkind = "wedge"\ngamma = "{g} deg"\nmu = {mu!r}\n{gap}'
    for m, f, k in zip(M, forces, stiffness):
        text += f'[[body]]\nmass = "{m!r} kg"\nforce = "{f!r} N"\n' + (f'stiffness = "{k!r} N/m"\n' if k else "")
    text += f"[run]\nt_end = {t_end!r}\nv0 = {v0!r}\nrtol = 1e-10\natol = 1e-12\n"
    return text + ('gap_1 = "0 mm"\ngap_2 = "0 mm"\n' if clearances else "")


def _hand(forces, stiffness, v0, t_end):
    """The hand reference (module docstring): the events [(t, "open" or "close", stage, state (q0, q1, q2, v0, v1, v2)
    after it, normal speed before a closing impact, its flank)] and the solution pieces (dense) from 0 to t_end or to
    the first event that a second stage opens while one is open (then the last event)."""
    tg = [math.tan(g) for g in GAMMA]
    contact = [1, 1]                 # per stage: +1 flank a, -1 flank b, 0 open
    t, y = 0.0, np.array([0.0, 0.0, 0.0, v0, tg[0] * v0, tg[0] * tg[1] * v0])
    events, pieces = [], []

    def groups():
        out, group = [], [0]
        for s in (1, 2):
            if contact[s - 1] == 0:
                out.append(group)
                group = []
            group.append(s)
        return [*out, group]

    def ratios(group):
        r = {group[0]: 1.0}
        for j in group[1:]:
            r[j] = r[j - 1] * tg[j - 1]
        return r

    def force(q):
        return [f - k * x for f, k, x in zip(forces, stiffness, q)]

    def accel(q):
        F, a = force(q), np.zeros(3)
        for group in groups():
            r = ratios(group)
            first = sum(r[j] * F[j] for j in group) / sum(r[j]**2 * M[j] for j in group)
            for j in group:
                a[j] = r[j] * first
        return a

    def load(s, q):   # closed stage s's generalized force on body s
        F, a = force(q), accel(q)
        group = next(g for g in groups() if s in g)
        r = ratios(group)
        return sum(r[j] / r[s] * (M[j] * a[j] - F[j]) for j in group if j >= s)

    def gap(s, q):
        return q[s] * math.cos(GAMMA[s - 1]) - q[s - 1] * math.sin(GAMMA[s - 1])

    def event(fn, what):
        fn.terminal, fn.direction, fn.what = True, -1, what
        return fn
    while True:
        found = []
        for s in (1, 2):
            if contact[s - 1]:
                found.append(event(lambda _, y, s=s: contact[s - 1] * load(s, y[:3]), ("open", s, 0)))
            else:
                found.append(event(lambda _, y, s=s: gap(s, y[:3]), ("close", s, 1)))
                found.append(event(lambda _, y, s=s: CLEARANCE - gap(s, y[:3]), ("close", s, -1)))
        sol = solve_ivp(lambda _, y: np.concatenate([y[3:], accel(y[:3])]), (t, t_end), y, method="DOP853",
                        rtol=1e-12, atol=1e-14, events=found, dense_output=True)
        pieces.append(sol)
        hits = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te)]
        if not hits:
            return events, pieces
        t, i = min(hits)
        y = sol.y_events[i][0].copy()
        kind, s, flank = found[i].what
        if kind == "open":
            events.append((t, "open", s, y.copy()))
            if 0 in contact:     # a second open stage: the run stops here
                return events, pieces
            contact[s - 1] = 0
            continue
        group_in, group_out = (next(g for g in groups() if body in g) for body in (s - 1, s))
        r_in, r_out = ratios(group_in), ratios(group_out)
        m1 = sum((r_in[j] / r_in[s - 1])**2 * M[j] for j in group_in)
        m2 = sum((r_out[j] / r_out[s])**2 * M[j] for j in group_out)
        sin, cos = math.sin(GAMMA[s - 1]), math.cos(GAMMA[s - 1])
        nu = y[3 + s] * cos - y[3 + s - 1] * sin
        impulse = -nu / (sin**2 / m1 + cos**2 / m2)
        for j in group_in:
            y[3 + j] -= r_in[j] / r_in[s - 1] * impulse * sin / m1
        for j in group_out:
            y[3 + j] += r_out[j] / r_out[s] * impulse * cos / m2
        events.append((t, "close", s, y.copy(), flank * nu, flank))
        contact[s - 1] = flank


def _at(pieces, t):
    """The hand state (q0, q1, q2, v0, v1, v2) at t (the later piece at an event)."""
    return next(sol for sol in reversed(pieces) if sol.t[0] <= t <= sol.t[-1]).sol(t)


@pytest.mark.parametrize("mu", [0.0, 0.1])
def test_two_clearances_that_never_open_run_as_the_chain_without_them(chain_module, mu):
    """Both stages on flank a, driven forward from rest (10 N on body 0 against 2 N on body 2): nothing opens, and
    q0(t), v0(t), the stage forces and the last body's travel are the rigid chain's (the module without clearances,
    another code path); frictionless also the closed form a0 = (F0 + c2 F2) / (M0 + c1^2 M1 + c2^2 M2), c1 = tan(g1),
    c2 = tan(g1) tan(g2), q0 = a0 t^2 / 2."""
    forces = (10.0, 0.0, -2.0)
    gapped = simulate_chain(chain_module(_scene(f"two-closed-{int(mu * 10)}", forces, mu=mu)), points=7)
    rigid = simulate_chain(chain_module(_scene(f"rigid-{int(mu * 10)}", forces, mu=mu, clearances=False)), points=7)
    assert gapped.status == rigid.status == "finished" and gapped.run.impacts == []
    assert [p.regime for s in gapped.stages for p in s.phases] == ["tractive", "tractive"]
    np.testing.assert_allclose(gapped.run.y[:, :2], rigid.run.y, rtol=1e-9, atol=1e-14)
    for mine, theirs in zip(gapped.samples, rigid.samples):
        np.testing.assert_allclose(mine, theirs, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(gapped.run.y[:, 3], math.tan(GAMMA[0]) * gapped.run.y[:, 1], rtol=1e-12)
    if mu == 0.0:
        c1, c2 = math.tan(GAMMA[0]), math.tan(GAMMA[0]) * math.tan(GAMMA[1])
        a0 = (forces[0] + c2 * forces[2]) / (M[0] + c1**2 * M[1] + c2**2 * M[2])
        np.testing.assert_allclose(gapped.run.y[:, 0], a0 * gapped.run.t**2 / 2, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(gapped.samples[4], c2 * gapped.samples[1], rtol=1e-12)


def test_a_second_clearance_that_stays_closed_changes_nothing(chain_module):
    """tests/test_chain_backlash.py's driven chain with friction started open in stage 2 (0.5 mm, e = 0.5), bouncing
    to rest on flank a, and the same chain with a 1 mm clearance in stage 1 too, closed on flank a (body 0 drives
    body 1 through it all along): stage 2 is then the second clearance stage (its open mode OPEN + 1, its index 1 the
    current one from the start), and the run is the same: every output row, every impact (time, speeds) and every
    event, exactly."""
    from tests.test_chain_backlash import _scene as one_gap

    one = one_gap("gap-bounces", e=0.5, mu=0.1)
    two = one.replace('gamma = "30 deg"\nmu = 0.1\n', 'gamma = "30 deg"\nmu = 0.1\nclearance = "1 mm"\nrestitution = 0.5\n')
    module = chain_module(two)
    single, double = simulate_chain(chain_module(one), points=21), simulate_chain(module, points=21)
    assert module.CLEARANCE_STAGES == (1, 2) and double.events[0]["to"] == module.MODES[module.OPEN + 1]
    assert double.status == single.status == "finished" and len(double.run.impacts) == len(single.run.impacts) > 5
    np.testing.assert_array_equal(double.run.y, single.run.y)
    for mine, theirs in zip(double.run.impacts, single.run.impacts):
        assert mine["stage"] == 2.0 and [mine[k] for k in ("t", "nu before", "nu after", "v0 after", "vk after")] == [
            theirs[k] for k in ("t", "nu before", "nu after", "v0 after", "vk after")]
    assert [(e["t"], e["guard"]) for e in double.events] == [(e["t"], e["guard"]) for e in single.events]
    assert [p.regime for p in double.stages[0].phases] == ["tractive"]


CYCLE = {"forces": (4.0, 7.0, -4.0), "stiffness": (50.0, 0.0, 0.0), "v0": 1.0, "t_end": 0.35}
BACK = {"forces": (5.0, 3.0, -1.0), "stiffness": (400.0, 0.0, 400.0), "v0": 0.5, "t_end": 0.32}
CYCLES = {"stage-1-then-2": (CYCLE, [("open", 1), ("close", 1, -1), ("open", 2), ("close", 2, -1)]),
          "1-2-then-1-again": (BACK, [("open", 1), ("close", 1, -1), ("open", 2), ("close", 2, 1), ("open", 1),
                                      ("close", 1, 1)])}


@pytest.mark.parametrize("case", CYCLES)
def test_stages_opening_and_closing_one_after_the_other_agree_with_scipy_on_the_hand_equations(chain_module, case):
    """Stage-1-then-2: moving forward at 1 m/s, body 1 pushed by 7 N, body 0 by 4 N less a 50 N/m spring, body 2
    held back by 4 N: body 1 outruns body 0 and stage 1 opens from flank a (its force on body 1 reaches 0), crosses
    its clearance and closes on flank b (plastic); as the spring grows stage 2's force on body 2 fades, it opens from
    flank a and closes on flank b. 1-2-then-1-again: springs of 400 N/m on bodies 0 and 2 turn the chain back, and
    stage 1 opens a second time after stage 2 has opened and closed (its gap then counted from its contact, the slips
    of stage 2 taken up). The hand equations' event sequence is the case's; the kernel's openings (guard N_k) and
    impacts (stage, flank) come in that order at the hand times (rel 1e-8), each open phase of each stage spans the
    hand's; the impacts' normal speeds and the speeds after them, the output rows q0, v0 and the last body's travel
    agree within rel 1e-7; y[2], y[3] are the current clearance stage's body k (the last one opened: body 1, then
    body 2, ...)."""
    scene, expected = CYCLES[case]
    module = chain_module(_scene(f"two-{case}", scene["forces"], scene["stiffness"], v0=scene["v0"],
                                 t_end=scene["t_end"]))
    result = simulate_chain(module, points=15)
    events, pieces = _hand(scene["forces"], scene["stiffness"], scene["v0"], scene["t_end"])
    assert result.status == "finished", result.message
    assert [(kind, s, *e[2:]) for _, kind, s, *e in events] == expected
    opens = [e for e in events if e[1] == "open"]
    opened = [e for e in result.events if (e["to"] or "").startswith("open") and e["guard"].startswith("N_")]
    assert [(e["guard"], e["to"]) for e in opened] == [(f"N_{s}", f"open: stage {s}") for _, _, s, _ in opens]
    assert [e["t"] for e in opened] == pytest.approx([e[0] for e in opens], rel=1e-8)
    impacts = result.run.impacts
    closes = [e for e in events if e[1] == "close"]
    assert [(i["stage"], i["flank"], i["closed"]) for i in impacts] == [
        (float(s), "a" if flank > 0 else "b", True) for _, _, s, _, _, flank in closes]
    for impact, (t, _, _, y, nu, _) in zip(impacts, closes):
        assert impact["t"] == pytest.approx(t, rel=1e-8)
        assert impact["nu before"] == pytest.approx(nu, rel=1e-7) and impact["nu after"] == 0.0
        assert impact["v0 after"] == pytest.approx(y[3], rel=1e-7)
    for k, stage in enumerate(result.stages, 1):
        spans = [(p.t_start, p.t_end) for p in stage.phases if p.regime == "open"]
        hand = [(a[0], b[0]) for a, b in zip(events[::2], events[1::2]) if a[2] == k]
        assert len(spans) == len(hand) > 0
        np.testing.assert_allclose(np.ravel(spans), np.ravel(hand), rtol=1e-8)
    hand = np.array([_at(pieces, t) for t in result.run.t])
    np.testing.assert_allclose(result.run.y[:, :2], hand[:, [0, 3]], rtol=1e-7, atol=1e-10)
    body = np.array([([1] + [s for t0, _, s, _ in opens if t0 <= t])[-1] for t in result.run.t])
    rows = np.arange(result.run.t.size)
    np.testing.assert_allclose(result.run.y[:, 2], hand[rows, body], rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(result.run.y[:, 3], hand[rows, 3 + body], rtol=1e-7, atol=1e-10)
    t, _, _, _, travel = result.samples
    seen = np.isfinite(travel)
    np.testing.assert_allclose(travel[seen], [_at(pieces, x)[2] for x in t[seen]], rtol=1e-7, atol=1e-10)
    text = "\n".join(summary(result, module))
    assert f"stage 1, 2 impacts ({len(closes)}):" in text and "stage 2 on flank" in text


TWO_OPEN = {"forces": (-3.0, 0.0, -10.0), "stiffness": (50.0, 0.0, 400.0), "v0": 0.0, "t_end": 0.4}


def test_a_second_stage_opening_while_one_is_open_stops_the_run(chain_module):
    """From rest, pulled backward (3 N on body 0 with a 50 N/m spring, 10 N on body 2 with a 400 N/m one): both
    stages on flank a, back-driven; stage 1 opens where its force on body 1 reaches 0, and while it is open stage 2's
    force on body 2 reaches 0 too: the run stops there with status two-open (its time the hand equations' zero of
    that force, rel 1e-8), the record kept up to it (rows before it the hand equations', after it NaN), the event's
    reason in words, no exception."""
    module = chain_module(_scene("two-open", TWO_OPEN["forces"], TWO_OPEN["stiffness"], v0=TWO_OPEN["v0"],
                                 t_end=TWO_OPEN["t_end"]))
    result = simulate_chain(module, points=9)
    events, pieces = _hand(TWO_OPEN["forces"], TWO_OPEN["stiffness"], TWO_OPEN["v0"], TWO_OPEN["t_end"])
    assert [(kind, s) for _, kind, s, *_ in events] == [("open", 1), ("open", 2)]
    t_stop = events[1][0]
    assert result.status == "two-open"
    assert result.t_stop == pytest.approx(t_stop, rel=1e-8)
    assert result.message.startswith("stage 2 opens while stage 1 is open: two open stages are not modelled")
    last = result.events[-1]
    assert (last["guard"], last["from"], last["to"]) == ("N_2", "open: stage 1", None)
    assert last["reason"] == "stage 2 opens while stage 1 is open: two open stages are not modelled"
    before = result.run.t < t_stop
    assert before.sum() >= 4 and np.isnan(result.run.y[~before]).all()
    hand = np.array([_at(pieces, t) for t in result.run.t[before]])
    np.testing.assert_allclose(result.run.y[before, :2], hand[:, [0, 3]], rtol=1e-7, atol=1e-10)


def test_a_sweep_records_a_two_open_case_and_goes_on(chain_module):
    """The chain sweep over body 2's spring: at 400 N/m the case stops two-open (its status in the table), at 0 N/m
    (body 2 pulled back by 10 N only) nothing opens and it finishes; each case as simulate_chain gives it."""
    from tswm_runtime.sweeps.chain import sizing

    module = chain_module(_scene("two-open", TWO_OPEN["forces"], TWO_OPEN["stiffness"], v0=TWO_OPEN["v0"],
                                 t_end=TWO_OPEN["t_end"]))
    table = sizing(module, {"stiffness_2": [400.0, 0.0]}, {"points": 5}).table
    single = [simulate_chain(module, {"stiffness_2": k}, points=5) for k in (400.0, 0.0)]
    assert table["status"].tolist() == [s.status for s in single] == ["two-open", "finished"]
    assert table["t_stop [s]"].tolist() == [s.t_stop for s in single]


def test_the_document_shows_each_clearance_stages_open_phase(tmp_path, capsys):
    """The derivation's document has one open-stage section per stage with a clearance; ``tswm derive`` names each
    stage's open mode and section."""
    from derivation.chain.document import OPEN_STAGE, build_chain_document
    from tswm_runtime.cli import main

    text = _scene("two-doc", CYCLE["forces"], CYCLE["stiffness"])
    titles = [s.title for s in build_chain_document(parse_chain(text, "doc.toml"))["sections"]]
    assert [t for t in titles if t.startswith(OPEN_STAGE)] == [f"{OPEN_STAGE}: stage 1", f"{OPEN_STAGE}: stage 2"]
    path = tmp_path / "two.toml"
    path.write_text(text)
    assert main(["derive", str(path)]) == 0
    out = capsys.readouterr().out
    assert "  open mode OPEN (stage 1's flanks apart): groups body 0 and bodies 1..2," in out
    assert "  open mode OPEN + 1 (stage 2's flanks apart): groups bodies 0..1 and body 2," in out
    assert f'document section: "{OPEN_STAGE}: stage 2" (stage 2 open:' in out
