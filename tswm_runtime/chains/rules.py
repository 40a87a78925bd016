"""A chain's next mode at an event, decided in compiled code, and the torque switch's and seat's latches.

The logic is tswm_common/chain_decision.py's (which the derivation's document uses), over numbers
from the generated module's functions: every sliding mode in the direction of v0 (both at rest) is a
candidate, consistent when each stage's normal force is >= 0 and, from rest, it leaves rest in its
own direction; rest is consistent when the statics admit internal forces inside every stage's stick
cone (``rest_holds``: the admissible sets propagated stage by stage, as ``chain_decision.rest``).
One consistent mode is the answer (UNIQUE); several that agree in a_0 and exclude rest are a kink
(CRITICAL: the one that is not the current mode is taken); none (NONE) or several (SEVERAL, a
Painleve-type case) are outcomes too, never exceptions. tests/test_chain_kernel.py checks that both
implementations decide alike. While a stage with a clearance is open (``open_phase``; one at a time), each group
at rest is decided the same way on its own: stuck where ``group_holds`` (the same propagation over its bodies and
closed stages) admits its statics, or leaving rest. A stage with a clearance that is closed pushes on its flank in
contact only, in the rigid chain's modes (``mode_contact``), at rest and in another stage's open phase.

The functions a decision calls: ``rhs`` (a_0 is dy[1]) and ``guards`` (D, jam, N_k, v0, seat,
switch, delay; mode RESTING: the last four) from the mode machine's Functions, and the chain
module's ``stage_forces`` and ``body_forces_into``, all with the contract's GUARDS/RHS signatures.
"""
from collections import namedtuple

import numpy as np

from tswm_common.chain_decision import SAME
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit

RESTING = -1          # the resting chain (no mode of the module)
NO_MODE = -2          # no mode: the run stops
START, CHECK = -1, -3  # the "guards" of the start and of the switch's check on entering a mode
UNIQUE, CRITICAL, NONE, SEVERAL, RESTING_GROUP = 0, 1, 2, 3, 4
OUTCOMES = ("unique", "critical", "none", "several", "group at rest")
SET_ROWS = 64         # rows of an interval set's work array (a merged set holds a few)
FRAME = 11            # an impact's frame: the module's IMPACT_FRAME

#: A chain module's numbers for the decision: per mode its direction, per mode and guard the guard's
#: direction; the number of stages; the slots of p (filled by the module's prepare) of the stages' Psi_t, Psi_i
#: (two per stage), their levers (one per stage each) and the last body's friction magnitude at rest; the
#: switch (the stage it measures, -1 none; the slots of its delay, its state and pick-up time, of the seat's
#: latch; its states).
ChainTables = namedtuple("ChainTables", "direction guard_direction stages p_psi p_lever_in p_lever_out p_slack "
                                        "switch_on p_delay p_switch p_pick p_seated armed picked tripped "
                                        "mode_contact open_mode clear_stage p_contact p_direction p_rho_sign p_gap "
                                        "p_current p_speed_k p_speed motor")
#: With clearances (``backlash.py``): per mode and clearance stage the flank it loads (+1 a, -1 b, 0 for the open
#: modes), the first open mode OPEN (open_mode + i: clearance i's stage open; -1: no clearance), the stages with a
#: clearance (clear_stage), the first slots of the contact latches (+1, -1, 0 open; one per clearance stage), of the
#: groups' directions (two, then held_out, held_in), of the stages' regime signs and of the gaps' offsets G_i, the
#: slots of the current clearance stage's index (open, or last opened) and of its c_k = v_k / v_0; the first slot of
#: the speed factors c_j = v_j / v_0 of the rigid chain (c_0 to c_N). Whether body 0 has a motor (1; its torque depends
#: on v0, so that a stage force's maximum may lie inside a phase while it is powered).

#: What a decision writes: guard values, a rate, the bodies' forces, interval sets (two and a cone),
#: the candidates' modes and a_0, p before the latches moved, the stage forces at a cut, an impact's frame, a state;
#: p and y before a stage opens and the chosen p and y (``opening``).
ChainWork = namedtuple("ChainWork", "g f force set_a set_b cone modes accel before forces frame y saved y_saved chosen")

#: The chain module's functions a decision calls besides rhs and guards.
ChainFunctions = namedtuple("ChainFunctions", "stage_forces body_forces impact")


@njit(refcounted=True, error_model="numpy")
def chain_work(n_guards, n_stages, n_modes, n_params, n_states):
    return ChainWork(np.empty(n_guards), np.empty(n_states), np.empty(n_stages + 1), np.empty((SET_ROWS, 2)),
                     np.empty((SET_ROWS, 2)), np.empty((2, 2)), np.empty(n_modes, np.int64), np.empty(n_modes),
                     np.empty(n_params), np.empty(3 * n_stages), np.empty(FRAME), np.empty(n_states), np.empty(n_params),
                     np.empty(n_states), np.empty(n_params + n_states))


@njit(error_model="numpy")
def current_index(c, p):
    """The index (in clear_stage) of the current clearance stage: the open one, or the last opened."""
    return int(p[c.p_current])


@njit(error_model="numpy")
def clearance_index(c, stage):
    """The index (in clear_stage) of stage ``stage`` (1-based), -1 for a stage without a clearance."""
    for j in range(c.clear_stage.size):
        if c.clear_stage[j] == stage:
            return j
    return -1


@njit(error_model="numpy")
def open_stage(c, p):
    """The current clearance stage (1-based): the one open in an open mode."""
    return c.clear_stage[int(p[c.p_current])]


@njit(error_model="numpy")
def is_open(c, mode):
    """Whether ``mode`` is an open mode (a stage with a clearance open)."""
    return c.open_mode >= 0 and mode >= c.open_mode


@njit(error_model="numpy")
def _mul(x, t):
    return 0.0 if x == 0 or t == 0 else x * t


@njit(error_model="numpy")
def _merge(s, n):
    """Sort rows [0, n) of s by (lo, hi) and merge those that overlap; returns the new count."""
    for i in range(1, n):
        lo, hi = s[i, 0], s[i, 1]
        j = i - 1
        while j >= 0 and (s[j, 0] > lo or (s[j, 0] == lo and s[j, 1] > hi)):
            s[j + 1, 0], s[j + 1, 1] = s[j, 0], s[j, 1]
            j -= 1
        s[j + 1, 0], s[j + 1, 1] = lo, hi
    m = 0
    for i in range(n):
        lo, hi = s[i, 0], s[i, 1]
        if m > 0 and lo <= s[m - 1, 1]:
            s[m - 1, 1] = max(s[m - 1, 1], hi)
        else:
            s[m, 0], s[m, 1] = lo, hi
            m += 1
    return m


@njit(error_model="numpy")
def _forward_cone(psi_t, psi_i, cone):
    """T = {t : (1 + Psi_t t)(1 + Psi_i t) <= 0} into cone; returns its count of intervals."""
    cone[0, 1] = -1 / psi_t
    if psi_i > 0:
        cone[0, 0] = -1 / psi_i
        return 1
    cone[0, 0] = -np.inf
    if psi_i == 0:
        return 1
    cone[1, 0], cone[1, 1] = -1 / psi_i, np.inf
    return 2


@njit(error_model="numpy")
def _scaled(xs, n, cone, n_cone, out):
    """The union of x T over x in the n intervals of xs into out; returns its count."""
    unbounded = False
    for j in range(n_cone):
        unbounded = unbounded or np.isinf(cone[j, 0]) or np.isinf(cone[j, 1])
    m = 0
    for i in range(n):
        lo, hi = xs[i, 0], xs[i, 1]
        if lo <= 0 <= hi and unbounded:
            out[0, 0], out[0, 1] = -np.inf, np.inf
            return 1
        for half in range(2):
            a, b = (lo, min(hi, 0.0)) if half == 0 else (max(lo, 0.0), hi)
            if a > b:
                continue
            for j in range(n_cone):
                c1, c2, c3, c4 = _mul(a, cone[j, 0]), _mul(a, cone[j, 1]), _mul(b, cone[j, 0]), _mul(b, cone[j, 1])
                out[m, 0], out[m, 1] = min(c1, c2, c3, c4), max(c1, c2, c3, c4)
                m += 1
    return _merge(out, m)


@njit(error_model="numpy")
def _affine(xs, n, offset, scale, out):
    """{offset + scale x : x in the n intervals of xs} into out; returns its count."""
    for i in range(n):
        a, b = offset + _mul(scale, xs[i, 0]), offset + _mul(scale, xs[i, 1])
        out[i, 0], out[i, 1] = min(a, b), max(a, b)
    return _merge(out, n)


@njit(error_model="numpy")
def _one_side(s, n, side):
    """The n intervals of s cut to x >= 0 (side > 0) or x <= 0 (side < 0); returns the count left."""
    m = 0
    for i in range(n):
        lo, hi = (max(s[i, 0], 0.0), s[i, 1]) if side > 0 else (s[i, 0], min(s[i, 1], 0.0))
        if lo <= hi:
            s[m, 0], s[m, 1] = lo, hi
            m += 1
    return m


@njit(error_model="numpy")
def rest_holds(c, p, force, w):
    """Whether the resting chain holds under the bodies' forces ``force`` (its numbers from p): the
    stage-by-stage propagation of ``chain_decision.rest`` from body 0 meets what the last body's load and
    friction ask of the last stage."""
    return group_holds(c, p, force, w, 0, c.stages)


@njit(error_model="numpy")
def group_holds(c, p, force, w, first, last):
    """Whether bodies ``first`` .. ``last``, joined by stages first + 1 .. last and taking no force from the stages
    beyond them, rest under ``force``: ``chain_decision.rest``'s propagation from body ``first`` (what it asks of
    stage first + 1) to body ``last``, whose balance it must meet (the valve's friction widening it on the last
    body of the chain). One body alone holds when its force is within that friction."""
    a, b = w.set_a, w.set_b
    slack = p[c.p_slack] if last == c.stages else 0.0
    lo, hi = -force[last] - slack, -force[last] + slack
    if first == last:
        return lo <= 0.0 <= hi
    a[0, 0] = a[0, 1] = -force[first] / p[c.p_lever_in + first]
    n = 1
    for i in range(first, last):
        n_cone = _forward_cone(p[c.p_psi + 2 * i], p[c.p_psi + 2 * i + 1], w.cone)
        n = _scaled(a, n, w.cone, n_cone, b)
        n = _affine(b, n, 0.0, p[c.p_lever_out + i], a)
        j = clearance_index(c, i + 1)   # a stage with a clearance pushes on its one flank in contact only
        if j >= 0 and p[c.p_contact + j] != 0.0:
            n = _one_side(a, n, p[c.p_contact + j])
        if i == last - 1:
            for j in range(n):
                if max(a[j, 0], lo) <= min(a[j, 1], hi):
                    return True
            return False
        n = _affine(a, n, -force[i + 1] / p[c.p_lever_in + i + 1], -1.0 / p[c.p_lever_in + i + 1], b)
        for j in range(n):
            a[j, 0], a[j, 1] = b[j, 0], b[j, 1]
    return False


@njit(error_model="numpy")
def decide(fns, chain_fns, c, t, y, p, current, w):
    """(outcome, mode) at (t, y) under latches p: the candidates in the direction of v0 (both at rest) and
    rest; ``current`` is the mode the event ended (a CRITICAL outcome takes another). Mode NO_MODE for
    NONE and SEVERAL. With clearances: the open stage's phase (``open_phase``) while its contact latch is 0 (it is
    the current one), else the modes loading the flanks in contact, rest with those stages pushing on them, and when
    neither holds a stage opening (``opening``)."""
    if c.open_mode >= 0 and p[c.p_contact + current_index(c, p)] == 0.0:
        return open_phase(fns, chain_fns, c, t, y, p, w)
    v = y[1]
    stages = c.stages
    n = 0
    for m in range(c.direction.size):
        d = c.direction[m]
        if not (v == 0.0 or (v > 0.0) == (d > 0)):
            continue
        if c.open_mode >= 0 and (m >= c.open_mode or not _loads(c, m, p)):
            continue
        fns.guards(m, t, y, p, w.g)
        fns.rhs(m, t, y, p, w.f)
        ok = v != 0.0 or d * w.f[1] > 0
        for k in range(stages):
            ok = ok and not w.g[2 + k] < 0
        if ok:
            w.modes[n], w.accel[n] = m, w.f[1]
            n += 1
    stuck = False
    if v == 0.0:
        chain_fns.body_forces(0, t, y, p, w.force)
        stuck = rest_holds(c, p, w.force, w)
    if n + stuck == 0:
        return opening(fns, chain_fns, c, t, y, p, w) if c.open_mode >= 0 else (NONE, NO_MODE)
    if n + stuck == 1:
        return UNIQUE, RESTING if stuck else w.modes[0]
    if not stuck:
        lo, hi, big = w.accel[0], w.accel[0], 1.0
        for j in range(n):
            lo, hi, big = min(lo, w.accel[j]), max(hi, w.accel[j]), max(big, abs(w.accel[j]))
        if hi - lo <= SAME * big:
            for j in range(n):
                if w.modes[j] != current:
                    return CRITICAL, w.modes[j]
    return SEVERAL, NO_MODE


@njit(error_model="numpy")
def _loads(c, m, p):
    """Whether closed mode ``m`` loads every stage with a clearance on its flank in contact."""
    for j in range(c.clear_stage.size):
        if c.mode_contact[m, j] != p[c.p_contact + j]:
            return False
    return True


def free_group(group, stage, stages, slack):
    """Whether ``group`` (0 input, 1 output) is free while clearance stage ``stage`` (1-based) of ``stages`` is open:
    its direction changes none of its forces, as it holds no closed stage and (the output group) the last body feels
    no valve friction (``slack``, its magnitude at rest). Plain Python for the decision's words (run.py), compiled
    for ``_free``."""
    return stage == 1 if group == 0 else stage == stages and slack == 0.0


_free_group = njit(error_model="numpy")(free_group)


@njit(error_model="numpy")
def _free(c, p, group):
    """``free_group`` of the current clearance stage under the latches p."""
    return _free_group(group, open_stage(c, p), c.stages, p[c.p_slack])


@njit(error_model="numpy")
def in_group(k, stage, group):
    """Whether closed stage ``stage`` (1-based) joins bodies of ``group`` (0 input, 1 output) while stage k is
    open."""
    return stage < k if group == 0 else stage > k


@njit(error_model="numpy")
def _keeps_flanks(c, p):
    """Whether each closed stage with a clearance slides on its flank in contact under the open phase's latches: its
    flank is its regime's sign times its group's direction (no check in a stuck or free group: no regime there)."""
    k = open_stage(c, p)
    for j in range(c.clear_stage.size):
        stage = c.clear_stage[j]
        if j == current_index(c, p):
            continue
        group = 0 if in_group(k, stage, 0) else 1
        direction = p[c.p_direction + group]
        if p[c.p_direction + 3 - group] == 0.0 and direction != 0.0 and \
                p[c.p_rho_sign + stage - 1] * direction != p[c.p_contact + j]:
            return False
    return True


@njit(error_model="numpy")
def _open_candidate(fns, c, t, y, p, w, combo, held):
    """Set the open phase's latches to ``combo`` (bit 0 and 1: a group at rest moves backward; bit 2 + i: stage
    i + 1 inverse-tractive) and ``held`` (bit 0 and 1: the input, the output group stuck at rest: latches held_in,
    held_out, its acceleration 0); whether it is consistent: no closed stage jams or pulls (N_i >= 0; a stuck group's
    are undetermined, its guards 1), and a group leaving rest accelerates in its direction. A stuck group's
    direction is 0 (its speed's guard stays 0, never an event); a free group's is its speed's sign, at rest its
    acceleration's (0: none): none of its forces depends on it, but its speed's guard falls through 0 where it turns,
    an event, so that the last body's farthest point is a phase end (the extra travel after the trip)."""
    p[c.p_direction + 3], p[c.p_direction + 2] = float(held & 1), float(held >> 1 & 1)
    for g in range(2):
        v = y[1] if g == 0 else y[3]
        if _free(c, p, g):
            p[c.p_direction + g] = np.sign(v)
        elif held >> g & 1:
            p[c.p_direction + g] = 0.0
        else:
            p[c.p_direction + g] = (1.0 if v > 0.0 else -1.0) if v != 0.0 else (-1.0 if combo >> g & 1 else 1.0)
    for i in range(c.stages):
        p[c.p_rho_sign + i] = -1.0 if combo >> (2 + i) & 1 else 1.0
    if not _keeps_flanks(c, p):
        return False
    mode = c.open_mode + current_index(c, p)
    fns.guards(mode, t, y, p, w.g)
    ok = w.g[1] > 0.0
    for i in range(c.stages):
        ok = ok and not w.g[2 + i] < 0.0
    fns.rhs(mode, t, y, p, w.f)
    for g in range(2):
        v, a = (y[1], w.f[1]) if g == 0 else (y[3], w.f[3])
        if v == 0.0 and _free(c, p, g):
            p[c.p_direction + g] = np.sign(a)
        elif v == 0.0 and not held >> g & 1:
            ok = ok and p[c.p_direction + g] * a > 0.0
    return ok


@njit(error_model="numpy")
def _stuck(chain_fns, c, t, y, p, w, group):
    """Whether ``group``, at rest while the stage is open and not free, can stay at rest: ``group_holds`` over its
    bodies and closed stages under its forces at rest (the valve's friction at most its magnitude), the open stage
    carrying nothing. Its forces depend on its own coordinate and speed and on the latches only, so they stay while
    it rests and the other group moves: the stick is decided again at every event (a cut motor, a seat, an impact)."""
    if (y[1] if group == 0 else y[3]) != 0.0 or _free(c, p, group):
        return False
    chain_fns.body_forces(0, t, y, p, w.force)
    return group_holds(c, p, w.force, w, 0, open_stage(c, p) - 1) if group == 0 else \
        group_holds(c, p, w.force, w, open_stage(c, p), c.stages)


@njit(error_model="numpy")
def _open_candidates(fns, c, t, y, p, w, held):
    """(how many of the open phase's candidates with the stuck groups ``held`` hold, the first, whether they agree in
    both accelerations, whether a group that is not free is at rest). A stuck group's direction and regimes are
    fixed (0, tractive): one candidate for it."""
    found, first, a_in, a_out, agree = 0, -1, 0.0, 0.0, True
    still = False
    for combo in range(1 << (2 + c.stages)):
        if combo >> (2 + open_stage(c, p) - 1) & 1:
            continue
        skip = False
        for g in range(2):
            v = y[1] if g == 0 else y[3]
            skip = skip or (combo >> g & 1 == 1 and (v != 0.0 or _free(c, p, g) or held >> g & 1 == 1))
        for i in range(c.stages):
            for g in range(2):
                skip = skip or (held >> g & 1 == 1 and combo >> (2 + i) & 1 == 1 and in_group(open_stage(c, p), i + 1, g))
        if skip:
            continue
        still = still or (y[1] == 0.0 and not _free(c, p, 0)) or (y[3] == 0.0 and not _free(c, p, 1))
        if _open_candidate(fns, c, t, y, p, w, combo, held):
            if found == 0:
                first, a_in, a_out = combo, w.f[1], w.f[3]
            else:
                big = max(1.0, abs(a_in), abs(a_out))
                agree = agree and abs(w.f[1] - a_in) <= SAME * big and abs(w.f[3] - a_out) <= SAME * big
            found += 1
    return found, first, agree, still


@njit(error_model="numpy")
def open_phase(fns, chain_fns, c, t, y, p, w):
    """The open phase's latches at (t, y): each group's direction (its speed's sign; at rest, the way it leaves
    rest) or, for a group at rest whose rest holds (``_stuck``), its stick (held_in, held_out), and each closed
    stage's regime, such that ``_open_candidate`` holds. The groups do not interact while the stage is open, so each
    at rest is decided on its own: stuck, or leaving rest, as the rigid chain's rest beside its break-away.
    (UNIQUE, OPEN) when one candidate holds (or several that agree in both accelerations), (NONE, NO_MODE) when none
    and both groups move or are free, (RESTING_GROUP, NO_MODE) when none and a group is at rest: it can neither stay
    (its statics exceed its stages' stick cones or its friction) nor leave rest in any direction and regimes (a
    Painleve-type case of the group), (SEVERAL, NO_MODE) when a group could both stay and leave rest, or leave it
    in ways that differ."""
    stuck = (1 if _stuck(chain_fns, c, t, y, p, w, 0) else 0) + (2 if _stuck(chain_fns, c, t, y, p, w, 1) else 0)
    total, first, first_held, agree, still = 0, -1, 0, True, False
    for held in range(4):
        if held & ~stuck:
            continue
        found, combo, agreed, resting = _open_candidates(fns, c, t, y, p, w, held)
        still = still or resting
        if found > 0 and total == 0:
            first, first_held, agree = combo, held, agreed
        elif found > 0:
            agree = False    # staying at rest and leaving it: never the same accelerations
        total += found
    if total == 0:
        p[c.p_direction + 2], p[c.p_direction + 3] = 0.0, 0.0
        return (RESTING_GROUP if still else NONE), NO_MODE
    if total > 1 and not agree:
        return SEVERAL, NO_MODE
    _open_candidate(fns, c, t, y, p, w, first, first_held)
    return UNIQUE, c.open_mode + current_index(c, p)


@njit(error_model="numpy")
def separating(chain_fns, c, flank, t, y, p, w):
    """f g'', the open stage's normal acceleration away from ``flank`` (+1 a, -1 b) in the open phase's latches: the
    impact frame's normal speed nu = f g' (linear in the groups' speeds) at their accelerations (w.f, from rhs)."""
    copy_into(w.y, y)
    w.y[1], w.y[3] = w.f[1], w.f[3]
    chain_fns.impact(flank, t, w.y, p, w.frame)
    return w.frame[0]


@njit(error_model="numpy")
def part(fns, c, i, t, y, p, w):
    """Clearance i's stage opens: its contact latch 0; where it is not the current stage j, it becomes current:
    y[2], y[3] scaled by c_k / c_j (bodies j and k move rigidly together until now, so the last body's coordinate
    c_N / c_j y[2] is kept), its c_k the latch, and its gap's offset G_i set so that the gap is its contact value (0
    on flank a, the clearance on flank b) now: it takes up the other stages' slips since it was current."""
    flank = p[c.p_contact + i]
    p[c.p_contact + i] = 0.0
    if current_index(c, p) == i:
        return
    speed = p[c.p_speed + c.clear_stage[i]]
    y[2] *= speed / p[c.p_speed_k]
    y[3] *= speed / p[c.p_speed_k]
    p[c.p_current], p[c.p_speed_k], p[c.p_gap + i] = float(i), speed, 0.0
    fns.guards(c.open_mode + i, t, y, p, w.g)   # the gap with G_i = 0: its rate's integral; and the clearance
    n = c.stages
    p[c.p_gap + i] = (0.0 if flank > 0.0 else w.g[n + 3] + w.g[n + 4]) - w.g[n + 3]


@njit(error_model="numpy")
def opening(fns, chain_fns, c, t, y, p, w):
    """No mode loading the flanks in contact holds and the chain cannot rest: a stage with a clearance opens
    (``part``) when its open phase is consistent and its gap's acceleration parts the flanks; (UNIQUE, its open mode)
    when one such stage does, (SEVERAL, NO_MODE) when more than one could (two open stages are not modelled), else
    (NONE, NO_MODE) with p and y as they were."""
    found, n_y = -1, y.size
    copy_into(w.saved, p)
    copy_into(w.y_saved, y)
    for i in range(c.clear_stage.size):
        flank = w.saved[c.p_contact + i]
        if flank == 0.0:
            continue
        part(fns, c, i, t, y, p, w)
        outcome, mode = open_phase(fns, chain_fns, c, t, y, p, w)
        if outcome == UNIQUE:
            fns.rhs(mode, t, y, p, w.f)
            if separating(chain_fns, c, int(flank), t, y, p, w) > 0.0:
                if found >= 0:
                    found = -2
                    copy_into(p, w.saved)
                    copy_into(y, w.y_saved)
                    break
                found = i
                copy_into(w.chosen[:p.size], p)
                copy_into(w.chosen[p.size:p.size + n_y], y)
        copy_into(p, w.saved)
        copy_into(y, w.y_saved)
    if found < 0:   # p and y as they were: restored after each stage tried
        return (SEVERAL if found == -2 else NONE), NO_MODE
    copy_into(p, w.chosen[:p.size])
    copy_into(y, w.chosen[p.size:p.size + n_y])
    return UNIQUE, c.open_mode + found


@njit(error_model="numpy")
def switched(fns, c, mode, guard, t, y, p, w):
    """The switch's logic at (t, y) in ``mode`` (RESTING: the module's resting guards); a fired ``guard``
    (the switch's or its delay's index) forces its transition. True when the motor has just been cut."""
    if c.switch_on < 0:
        return False
    n_guards = w.g.size
    fns.guards(mode, t, y, p, w.g)
    if p[c.p_switch] != c.tripped and (guard == n_guards - 2 or w.g[n_guards - 2] < 0):
        p[c.p_switch] = c.picked if p[c.p_switch] == c.armed else c.armed
        p[c.p_pick] = t
    if p[c.p_switch] == c.picked:
        fns.guards(mode, t, y, p, w.g)
        if guard == n_guards - 1 or w.g[n_guards - 1] <= 0:
            p[c.p_switch] = c.tripped
            return True
    return False


@njit(error_model="numpy")
def last_coordinate(c, y, p):
    """The last body's coordinate q_N: c_N q0 for a rigid chain; with clearances, y[2] (body k's coordinate, k the
    current clearance stage, rescaled whenever another becomes current) mapped through the stages after k,
    (c_N / c_k) y[2], so that the backlash taken up before counts no travel."""
    if y.size == 2:
        return p[c.p_speed + c.stages] * y[0]
    return p[c.p_speed + c.stages] / p[c.p_speed_k] * y[2]


@njit(error_model="numpy")
def cut(chain_fns, c, mode, t, y, w, trip):
    """What the chain carried just before the motor's cut, with p still powered (w.before), into trip:
    t, q0, v0, body 0's drive torque, the stage forces (NaN at rest: undetermined), the last body's coordinate
    (``last_coordinate``), the mode."""
    trip[0], trip[1], trip[2] = t, y[0], y[1]
    chain_fns.body_forces(0 if mode == RESTING else c.direction[mode], t, y, w.before, w.force)
    trip[3] = w.force[0]
    if mode == RESTING:
        w.forces[:] = np.nan
    else:
        chain_fns.stage_forces(mode, t, y, w.before, w.forces)
    copy_into(trip[4:4 + w.forces.size], w.forces)
    trip[4 + w.forces.size] = last_coordinate(c, y, w.before)
    trip[5 + w.forces.size] = mode


@njit(error_model="numpy")
def settle(fns, chain_fns, c, t, y, p, mode, guard, w, trip):
    """The latches after ``guard`` fired in ``mode`` (the seat's contact flips; the switch moves; the stage with a
    clearance opens where its normal force reached 0), then the next mode; a switch that picks up with no delay, or
    sees its setting already where the chain starts, comes to rest or leaves the open phase (an impact's closing
    makes the stage's force jump), cuts the motor at once and the mode is decided again. The first cut is written
    into trip (trip[0] NaN until then). Returns (outcome, mode)."""
    n_guards = w.g.size
    copy_into(w.before, p)
    if guard == n_guards - 3:
        p[c.p_seated] = 1.0 - p[c.p_seated]
    if (guard == n_guards - 2 or guard == n_guards - 1) and switched(fns, c, mode, guard, t, y, p, w):
        if np.isnan(trip[0]):
            cut(chain_fns, c, mode, t, y, w, trip)
    if 0 <= mode and not is_open(c, mode):
        i = clearance_index(c, guard - 1)
        if i >= 0:
            part(fns, c, i, t, y, p, w)   # the normal force of a stage with a clearance reached 0: its flanks part
    outcome, new = decide(fns, chain_fns, c, t, y, p, mode, w)
    if new != NO_MODE and (guard == START or new == RESTING or is_open(c, mode)):
        copy_into(w.before, p)
        if switched(fns, c, new, CHECK, t, y, p, w):
            if np.isnan(trip[0]):
                cut(chain_fns, c, new, t, y, w, trip)
            outcome, new = decide(fns, chain_fns, c, t, y, p, new, w)
    return outcome, new
