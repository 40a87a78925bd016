"""The mode machine: integrate a generated model across regime changes, in nopython mode.

``integrate_hybrid`` runs segments of fixed mode (``segment.run``) and, at each
event, decides the next mode from the guard that fired and the model's own
functions, generically over the contract (modes and guards are described by the
integer tables built in ``modes.py``):

* phi (the switching function) crosses 0: the contact moves to the other flank.
  In the consistent model a1 is continuous there (a kink). Where a1 jumps (the
  paper's printed equations), both neighbouring modes may push the state onto
  phi = 0; the slide mode's guards tell (Filippov: d phi/dt < 0 on the phi > 0
  side and > 0 on the other). The state then slides along phi = 0 in the slide
  mode if the scene declares it, else the run stops with status SLIDING.
* v1 reaches 0: at rest, the static friction cones decide: stick (v1 stays 0;
  the Filippov sliding motion on v1 = 0), or sliding on in the direction whose
  cone is violated. Stick ends when a cone guard falls through 0 (breakaway).
* D or the jam factor reaches 0: no contact force satisfies the constraint
  (Painleve-type inconsistency): status INCONSISTENT.
* A law event (a load step in time, a spring contact, the torque switch, which
  also latches the trip time into p): the mode is re-selected at once, since the
  law may have moved the state across phi = 0 or out of the friction cone.
* Lost motion: body 2 reaches the stem (its gap closes): the pickup impulse through the
  wedge; body 2 carries the stem from then on, or the stem rebounds and flies ahead on its
  own until it lands again. The stem's contact force reaches 0: the stem leaves body 2.
  Both set the stem's latches in p, which switch the load and the stem's mass onto body 2.
* A mode the state needs but the scene did not declare: status UNDECLARED, with
  the mode needed (NEED_*), for a message naming it; NEED_FLANK when a one-sided
  scene's only contact force vanishes (body 2 would lift off the flank).

Chattering guard: more than MAX_SAME_TIME events without the time advancing
stops the run with status CHATTERING instead of looping.
"""
from collections import namedtuple

import numpy as np
from numba import types

from tswm_runtime.hybrid import impact as collision
from tswm_runtime.jit import cache_guard
from tswm_runtime.integration import segment
from tswm_runtime.integration import steplog
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.borrow import borrowed
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.structures import (JUMP_WIDTH, MODE_TABLES, RECORD, SETTINGS, START, EventSettings, Segment,
                                         State)

# Guard kinds (modes.GUARD_KINDS maps the generated GUARDS names to these).
(G_PHI, G_V1, G_D, G_JAM, G_CONE_F, G_CONE_B, G_FLANK_N, G_LAW, G_SLIDE_A, G_SLIDE_B, G_TRIP, G_GAP_A, G_GAP_B,
 G_MESH_N, G_SLIP, G_STEM_GAP, G_STEM_N) = range(17)
# Mode kinds: rigid sliding, rigid stick, Filippov sliding on phi = 0, free flight, compliant contact.
M_SLIDING, M_STICK, M_FILIPPOV, M_FREE, M_MESH = 0, 1, 2, 3, 4
IMPACT_FRAME = 12  # the quantities a model's impact() fills at most (codegen.IMPACT_FRAME, PICKUP_FRAME)

# Status codes; the integrator's own failures keep segment's codes.
FINISHED = 0
STEP_TOO_SMALL = segment.STEP_TOO_SMALL
MAX_STEPS = segment.MAX_STEPS
NOT_FINITE = segment.NOT_FINITE
INVALID_INPUT = segment.INVALID_INPUT
SLIDING = -5  # Filippov sliding along phi = 0, which the scene does not declare.
INCONSISTENT = -6  # D <= 0 or jam factor <= 0 in the mode the state asks for.
UNDECLARED = -7  # The state needs a mode the scene does not declare (see NEED_*).
CHATTERING = -8  # MAX_SAME_TIME events at one instant.
TOO_MANY_EVENTS = -9  # The event log is full.
INDETERMINATE = -10  # At rest at the start the contact conditions admit no mode or several.

# How a sliding mode meets the contact conditions at rest (``_slide_at_rest``).
NO, REGULAR, SINGULAR = 0, 1, 2

# What an UNDECLARED stop needs.
NEED_NOTHING, NEED_STICK, NEED_FORWARD, NEED_BACKWARD, NEED_FLANK = 0, 1, 2, 3, 4

MAX_SAME_TIME = 8  # Events allowed at one instant before CHATTERING.
SAME_TIME_ULPS = 64.0  # "One instant": within 64 ulp(t).


@njit(error_model="numpy")
def _guard(kind, guard_kind):
    """Index of the first guard of ``kind``, -1 if the model has none."""
    for k in range(guard_kind.size):
        if guard_kind[k] == kind:
            return k
    return -1


@njit(error_model="numpy")
def _mode(kind, flank, direction, tables):
    """Index of the mode of ``kind`` (sliding: on ``flank`` in ``direction``; flank 0 = any)."""
    mode_kind, mode_flank, mode_dir = tables.kind, tables.flank, tables.direction
    for m in range(mode_kind.size):
        if mode_kind[m] != kind:
            continue
        if kind == M_STICK or kind == M_FREE or (mode_dir[m] == direction and (flank == 0 or mode_flank[m] == flank)):
            return m
    return -1


@njit(error_model="numpy")
def _phi_sign(rhs, guards, mode, t, y, p, tol, k_phi, g, y_tmp, f):
    """Sign of phi at (t, y) for entering a sliding mode. If phi is zero within its
    noise (its change under a v1 error at the tolerance), the sign phi takes after
    a probe step along ``mode`` that moves v1 by that tolerance."""
    n = y.size
    dv = tol.atol[n - 1] + tol.rtol * abs(y[n - 1])
    copy_into(y_tmp, y)
    y_tmp[n - 1] += dv
    guards(mode, t, y_tmp, p, g)
    phi_moved = g[k_phi]
    guards(mode, t, y, p, g)
    phi = g[k_phi]
    if abs(phi) > abs(phi_moved - phi):
        return 1 if phi > 0.0 else -1
    rhs(mode, t, y, p, f)
    if f[n - 1] == 0.0:
        return 1 if phi >= 0.0 else -1
    dt = dv / abs(f[n - 1])
    for i in range(n):
        y_tmp[i] = y[i] + dt * f[i]
    guards(mode, t + dt, y_tmp, p, g)
    return -1 if g[k_phi] < 0.0 else 1


@njit(error_model="numpy")
def _part(flank, tables, guards, t, y, p, g):
    """(mode, need) when the contact on ``flank`` lets go (its normal force reaches 0): free
    flight, or, where the clearance is zero, contact on the other flank at once."""
    m_free = _mode(M_FREE, 0, 0, tables)
    n = y.size
    y[n - 2] = 0.0  # the flanks part with no normal speed
    guards(m_free, t, y, p, g)
    if g[_guard(G_GAP_B if flank == 1 else G_GAP_A, tables.guard_kind)] > 0.0:
        return m_free, NEED_NOTHING
    v = y[n - 1]
    m = _mode(M_STICK, 0, 0, tables) if v == 0.0 else _mode(M_SLIDING, -flank, 1 if v > 0.0 else -1, tables)
    return m, (NEED_NOTHING if m >= 0 else NEED_STICK if v == 0.0 else NEED_FORWARD if v > 0.0 else NEED_BACKWARD)


@njit(error_model="numpy")
def _touching(guards, t, y, p, tables, g):
    """The flank in contact with a clearance (+1 a, -1 b: the one whose gap is 0), 0 without one."""
    m_free = _mode(M_FREE, 0, 0, tables)
    if m_free < 0:
        return 0
    guards(m_free, t, y, p, g)
    if g[_guard(G_GAP_A, tables.guard_kind)] <= 0.0:
        return 1
    if g[_guard(G_GAP_B, tables.guard_kind)] <= 0.0:
        return -1
    return 0


@njit(error_model="numpy")
def _sliding(direction, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f):
    """(mode, need) for sliding in ``direction`` from (t, y): without a clearance (``flank``
    0) on the flank the sign of phi gives; with one, on ``flank`` while phi keeps its contact
    force >= 0, else the flanks part."""
    m = _mode(M_SLIDING, flank, direction, tables)
    if m < 0:
        return -1, (NEED_FORWARD if direction > 0 else NEED_BACKWARD)
    k_phi = _guard(G_PHI, tables.guard_kind)
    if k_phi < 0:
        return m, NEED_NOTHING
    side = _phi_sign(rhs, guards, m, t, y, p, tol, k_phi, g, y_tmp, f)
    if flank != 0:
        return (m, NEED_NOTHING) if side == flank else _part(flank, tables, guards, t, y, p, g)
    m = _mode(M_SLIDING, side, direction, tables)
    if m < 0:  # one-sided: the contact force on the only flank vanishes (lift-off)
        return -1, NEED_FLANK
    return m, NEED_NOTHING


@njit(error_model="numpy")
def _at_rest(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, start):
    """(mode, status, need) at v1 = 0, at the start and whenever the run comes to rest: by the
    contact conditions (``_rest_by_contact``) where the model has contact forces to test (a jam
    factor: the consistent equations), else by the friction cones (``_rest_by_cones``)."""
    if _guard(G_JAM, tables.guard_kind) >= 0:
        return _rest_by_contact(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    return _outcome(*_rest_by_cones(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, start))


@njit(error_model="numpy")
def _rest_by_cones(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, start):
    """(mode, need) at v1 = 0 for the printed equations, which have no contact force to test:
    stick inside both friction cones, else sliding off in the direction whose cone is violated;
    with a clearance (contact on ``flank`` != 0) the flanks part where the statics press the
    other flank. Without a stick mode only a start can go on: in the direction its sliding
    acceleration points to."""
    ms = _mode(M_STICK, 0, 0, tables)
    if ms < 0:
        if not start:
            return -1, NEED_STICK
        for direction in (1, -1):
            m, need = _sliding(direction, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
            if m >= 0 and tables.kind[m] == M_SLIDING:
                rhs(m, t, y, p, f)
                if f[y.size - 1] * direction > 0.0:
                    return m, NEED_NOTHING
            elif m >= 0:
                return m, need
        return -1, NEED_STICK
    guards(ms, t, y, p, g)
    cone_f, cone_b = g[_guard(G_CONE_F, tables.guard_kind)], g[_guard(G_CONE_B, tables.guard_kind)]
    if flank != 0 and g[_guard(G_FLANK_N, tables.guard_kind)] * flank < 0.0:
        return _part(flank, tables, guards, t, y, p, g)
    if cone_f < 0.0:
        return _sliding(1, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    if cone_b < 0.0:
        return _sliding(-1, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    return ms, NEED_NOTHING


@njit(error_model="numpy")
def _filippov(mode, guards, t, y, p, tables, g):
    """The slide mode if phi = 0 attracts from both sides at (t, y), else -1."""
    ms = _mode(M_FILIPPOV, 0, tables.direction[mode], tables)
    if ms < 0:
        return -1
    guards(ms, t, y, p, g)
    exit_a, exit_b = g[_guard(G_SLIDE_A, tables.guard_kind)], g[_guard(G_SLIDE_B, tables.guard_kind)]
    return ms if exit_a > 0.0 and exit_b > 0.0 else -1


@njit(error_model="numpy")
def _outcome(m, need):
    """(mode, status, need) of a mode choice: FINISHED with mode ``m``, or UNDECLARED with ``need``."""
    return (m, FINISHED, NEED_NOTHING) if m >= 0 else (-1, UNDECLARED, need)


@njit(error_model="numpy")
def _select(mode, kind, rhs, guards, t, y, p, tol, tables, g, y_tmp, f):
    """(next mode, status, need) after guard ``kind`` fired in ``mode`` at (t, y)."""
    mode_kind, mode_dir, declared = tables.kind, tables.direction, tables.declared
    n = y.size
    direction = mode_dir[mode]
    if kind == G_D or kind == G_JAM:
        return -1, INCONSISTENT, NEED_NOTHING
    if kind == G_SLIDE_A or kind == G_SLIDE_B:
        m = _mode(M_SLIDING, 1 if kind == G_SLIDE_A else -1, direction, tables)
        return m, FINISHED, NEED_NOTHING
    if mode_kind[mode] == M_FREE:  # a law event in free flight
        return mode, FINISHED, NEED_NOTHING
    if mode_kind[mode] == M_MESH:
        return _outcome(*_mesh_select(mode, kind, guards, t, y, p, tables, g))
    flank = 0  # the touched flank with a clearance, 0 without one
    if _mode(M_FREE, 0, 0, tables) >= 0:
        flank = tables.flank[mode] if mode_kind[mode] == M_SLIDING else _touching(guards, t, y, p, tables, g)
    if kind == G_CONE_F or kind == G_CONE_B:  # breakaway from stick
        m, need = _sliding(1 if kind == G_CONE_F else -1, flank, rhs, guards, t, y, p, tol,
                           tables, g, y_tmp, f)
    elif kind == G_FLANK_N:  # the pressed flank changes while sticking: the flanks part if they can
        m, need = _part(flank, tables, guards, t, y, p, g) if flank != 0 else (mode, NEED_NOTHING)
    elif kind == G_V1 or mode_kind[mode] == M_STICK:  # came to rest, or a law event in stick
        y[n - 1] = 0.0
        return _at_rest(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, False)
    elif mode_kind[mode] == M_FILIPPOV:  # a law event while sliding along phi = 0
        guards(mode, t, y, p, g)
        m, need = mode, NEED_NOTHING
        if g[_guard(G_SLIDE_A, tables.guard_kind)] <= 0.0:
            m = _mode(M_SLIDING, 1, direction, tables)
        elif g[_guard(G_SLIDE_B, tables.guard_kind)] <= 0.0:
            m = _mode(M_SLIDING, -1, direction, tables)
    else:  # phi, or a law event while sliding: the flank from the sign of phi (or the flanks part)
        m, need = _sliding(direction, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
        ms = _filippov(mode, guards, t, y, p, tables, g) if kind == G_PHI else -1
        if ms >= 0:
            if declared[ms] == 0:
                return -1, SLIDING, NEED_NOTHING
            m = ms
    return _outcome(m, need)


@njit(error_model="numpy", refcounted=True)  # impact.collide (numba.njit: counted as its caller) allocates
def _collide(impact, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, frame, jump):
    """(next mode, status, need) after the gap closes on ``flank``: the impulse (``impact``
    module) changes v1 and gap_rate; the flanks stay together where the rebound is within the
    tolerances (its speed within the velocity tolerance, or the height of the next bounce,
    and so of every later one, within the gap's tolerance): this ends a sequence of ever
    smaller bounces at its accumulation point. Else free flight goes on. jump = (P_n, P_t,
    kinetic energy lost, v1 before); frame[0] on return: the flight time to the next impact
    on this flank if the free-flight acceleration stays (inf: none)."""
    n = y.size
    jump[3] = y[n - 1]
    impact(flank, t, y, p, frame)
    p_n, p_t, nu, s, lost, outcome = collision.collide(frame[0], frame[1], frame[2], frame[3], frame[4],
                                                       frame[5], frame[6])
    jump[0], jump[1], jump[2] = p_n, p_t, lost
    if outcome != collision.OK:
        return -1, INCONSISTENT, NEED_NOTHING
    m_free = _mode(M_FREE, 0, 0, tables)
    guards(m_free, t, y, p, g)
    y[n - 3] += -g[_guard(G_GAP_A, tables.guard_kind)] if flank == 1 else g[_guard(G_GAP_B, tables.guard_kind)]
    y[n - 2] = flank * nu
    y[n - 1] = frame[7] * y[n - 2] + frame[8] * s
    rhs(m_free, t, y, p, f)
    toward = -flank * f[n - 2]  # the normal acceleration of free flight back onto the flank
    if _settles(nu, toward, y[n - 1], y, tol):  # persistent contact
        y[n - 2], y[n - 1] = 0.0, frame[8] * s
        m, status, need = _moving_on(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    else:
        m, status, need = m_free, FINISHED, NEED_NOTHING
    frame[0] = 2.0 * nu / toward if toward > 0.0 and m == m_free else np.inf
    return m, status, need


@njit(error_model="numpy")
def _settles(nu, toward, speed, y, tol):
    """Whether a rebound at normal speed nu (> 0: apart) ends a sequence of bounces: its speed is
    within the velocity tolerance (scaled by ``speed``), or the height of the next bounce under the
    acceleration ``toward`` the contact, and so of every later one, within the gap's tolerance (the
    gap or the stem's travel is state n - 3, its rate n - 2)."""
    n = y.size
    gap_tol = tol.atol[n - 3] + tol.rtol * abs(y[n - 3])
    return nu <= tol.atol[n - 2] + tol.rtol * abs(speed) or (toward > 0.0 and nu * nu <= 2.0 * toward * gap_tol)


@njit(error_model="numpy")
def _moving_on(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f):
    """(mode, status, need) for the rigid wedge (touching ``flank`` with a clearance, else 0) from
    (t, y) after a jump in v1 or in the laws: at rest (``_at_rest``) or sliding the way v1 points."""
    v = y[y.size - 1]
    if v == 0.0:
        return _at_rest(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, False)
    return _outcome(*_sliding(1 if v > 0.0 else -1, flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f))


@njit(error_model="numpy", refcounted=True)  # impact.pickup (numba.njit: counted as its caller) allocates
def _pickup(impact, k, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, frame, jump):
    """(next mode, status, need) after body 2 reaches the stem (guard ``k``): the impulse through
    the wedge (``impact`` module) changes v1 and v3; where the rebound is within the tolerances
    (as for the flanks, ``_collide``) the impact is taken as plastic and body 2 carries the stem
    from then on (this ends a sequence of bounces with the momentum kept), else the stem flies
    ahead on its own. The first pickup starts the load on the stem (latch t_pickup), carrying
    sets t_engaged. jump = (P, 0, kinetic energy lost, v1 before); frame[0] on return: the
    flight time to the stem's next landing if the accelerations stay (inf: none)."""
    n = y.size
    jump[3] = y[n - 1]
    impact(0, t, y, p, frame)
    ratio = frame[11]
    impulse, v1, v3, lost, outcome = collision.pickup(frame)
    jump[0], jump[1], jump[2] = impulse, 0.0, lost
    if outcome != collision.OK:
        return -1, INCONSISTENT, NEED_NOTHING
    k_pickup, k_carry = tables.guard_latch[k], tables.guard_latch[_guard(G_STEM_N, tables.guard_kind)]
    p[k_pickup] = min(p[k_pickup], t)
    y[n - 1], y[n - 2] = v1, v3
    m, status, need = _moving_on(0, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    if status != FINISHED:
        return m, status, need
    rhs(m, t, y, p, f)
    nu = v3 - ratio * v1
    toward = ratio * f[n - 1] - f[n - 2]  # the stem's acceleration back onto body 2
    carried = _settles(nu, toward, v3, y, tol)
    if carried:  # the impact is taken as plastic: body 2 carries the stem
        frame[8] = 0.0  # (the frame is still the one before the impact)
        jump[0], v1, v3, jump[2], outcome = collision.pickup(frame)
        y[n - 1], y[n - 2] = v1, ratio * v1
        p[k_carry] = t
        m, status, need = _moving_on(0, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    frame[0] = 2.0 * nu / toward if toward > 0.0 and not carried else np.inf
    return m, status, need


@njit(error_model="numpy")
def _carry_at_start(impact, guards, t, y, p, tables, g, frame):
    """Body 2 starting at the stem (lost motion 0) carries it from the start, at its speed."""
    k = _guard(G_STEM_GAP, tables.guard_kind)
    if k < 0:
        return
    guards(0, t, y, p, g)
    if g[k] <= 0.0:
        impact(0, t, y, p, frame)
        p[tables.guard_latch[k]] = p[tables.guard_latch[_guard(G_STEM_N, tables.guard_kind)]] = t
        y[y.size - 2] = frame[11] * y[y.size - 1]


@njit(error_model="numpy")
def _released(mode, guards, t, y, p, tables, g):
    """Release the carried stem if its contact force is negative in ``mode`` at (t, y) (after an
    event that changed the laws it leaves body 2 at once: the guard would not see it); True if so."""
    k = _guard(G_STEM_N, tables.guard_kind)
    if k < 0:
        return False
    guards(mode, t, y, p, g)
    if g[k] >= 0.0:  # (1 when the stem is not carried)
        return False
    p[tables.guard_latch[k]] = np.inf
    return True


@njit(error_model="numpy")
def _need(m, direction):
    """What a missing sliding mode in ``direction`` needs (nothing when mode ``m`` exists)."""
    return NEED_NOTHING if m >= 0 else NEED_FORWARD if direction > 0 else NEED_BACKWARD


@njit(error_model="numpy")
def _mesh_rest(flank, guards, t, y, p, tables, g):
    """(mode, need) where the slip of a compliant contact on ``flank`` is 0: stick while both
    friction cones hold, else sliding the way the violated cone points."""
    ms = _mode(M_MESH, flank, 0, tables)
    if ms < 0:
        return -1, NEED_STICK
    guards(ms, t, y, p, g)
    direction = 1 if g[_guard(G_CONE_F, tables.guard_kind)] < 0.0 else (
        -1 if g[_guard(G_CONE_B, tables.guard_kind)] < 0.0 else 0)
    if direction == 0:
        return ms, NEED_NOTHING
    m = _mode(M_MESH, flank, direction, tables)
    return m, _need(m, direction)


@njit(error_model="numpy")
def _mesh_enter(flank, guards, t, y, p, tables, g):
    """(mode, need) for compliant contact on ``flank``: sliding with the sign of the slip, or
    as at rest (``_mesh_rest``) where the slip is 0."""
    m = _mode(M_MESH, flank, 1, tables)
    if m < 0:
        m = _mode(M_MESH, flank, -1, tables)
    if m < 0:
        return _mesh_rest(flank, guards, t, y, p, tables, g)
    guards(m, t, y, p, g)
    slip = g[_guard(G_SLIP, tables.guard_kind)]
    if slip == 0.0:
        return _mesh_rest(flank, guards, t, y, p, tables, g)
    direction = 1 if slip > 0.0 else -1
    m = _mode(M_MESH, flank, direction, tables)
    return m, _need(m, direction)


@njit(error_model="numpy")
def _mesh_select(mode, kind, guards, t, y, p, tables, g):
    """(next mode, need) after guard ``kind`` fired in compliant contact ``mode``: the normal
    force reached 0 (free flight), the slip stopped, a cone broke, or a law event."""
    flank = tables.flank[mode]
    if kind == G_MESH_N:
        return _mode(M_FREE, 0, 0, tables), NEED_NOTHING
    if kind == G_SLIP:
        return _mesh_rest(flank, guards, t, y, p, tables, g)
    if kind == G_CONE_F or kind == G_CONE_B:
        direction = 1 if kind == G_CONE_F else -1
        m = _mode(M_MESH, flank, direction, tables)
        return m, _need(m, direction)
    guards(mode, t, y, p, g)  # a law event: the contact may open, a stick may break
    if g[_guard(G_MESH_N, tables.guard_kind)] < 0.0:
        return _mode(M_FREE, 0, 0, tables), NEED_NOTHING
    if tables.direction[mode] == 0:
        return _mesh_rest(flank, guards, t, y, p, tables, g)
    return mode, NEED_NOTHING


@njit(error_model="numpy")
def _pressed(flank, rhs, t, y, p, tables, f):
    """Whether free flight would press the bodies onto ``flank`` (its normal acceleration)."""
    n = y.size
    rhs(_mode(M_FREE, 0, 0, tables), t, y, p, f)
    return -flank * f[n - 2] > 0.0


@njit(error_model="numpy")
def _consistent(mode, guards, t, y, p, tables, g):
    """False if D or the jam factor of ``mode`` is <= 0 at (t, y)."""
    guards(mode, t, y, p, g)
    for kind in (G_D, G_JAM):
        k = _guard(kind, tables.guard_kind)
        if k >= 0 and g[k] <= 0.0:
            return False
    return True


@njit(error_model="numpy")
def _inside(k, piece, guards, t, y, p, tables, g):
    """Whether (t, y) lies in ``piece`` of the law whose event is guard k (its guard is >= 0
    there); leaves that piece latched in p."""
    p[tables.guard_latch[k]] = piece
    guards(0, t, y, p, g)
    return g[k] >= 0.0


@njit(error_model="numpy")
def _locate_piece(k, guards, t, y, p, tables, g):
    """Latch in p the piece of guard k's law that (t, y) lies in, searched outward from the
    piece in force: an event passes one breakpoint, so this costs a few guard calls however
    many pieces the law has. On a breakpoint the later piece is taken (the right limit; a
    located event lies strictly past its breakpoint anyway). Returns the breakpoint passed,
    counted from 1 (the higher of the two pieces' numbers), 0 if the piece is unchanged."""
    last = tables.guard_pieces[k] - 1
    old = int(p[tables.guard_latch[k]])
    found = -1
    for d in range(last + 1):
        if old + d <= last and _inside(k, old + d, guards, t, y, p, tables, g):
            found = old + d
            break
        if 0 < d <= old and _inside(k, old - d, guards, t, y, p, tables, g):
            found = old - d
            break
    if found < 0:  # in no piece (a state that is not finite): keep the piece in force
        p[tables.guard_latch[k]] = old
        return 0
    while found < last and _inside(k, found + 1, guards, t, y, p, tables, g):
        found += 1
    p[tables.guard_latch[k]] = found
    return max(old, found) if found != old else 0


@njit(error_model="numpy")
def _latch_pieces(guards, t, y, p, tables, g):
    """Set every piecewise law's latched piece in p at the start: the piece (t, y) lies in."""
    for k in range(tables.guard_kind.size):
        if tables.guard_kind[k] == G_LAW:
            p[tables.guard_latch[k]] = 0.0
            _locate_piece(k, guards, t, y, p, tables, g)


@njit(error_model="numpy")
def _unbounded(observe, guards, mode, t, y, p, k_d, mon, obs, g):
    """Mark the observables' maxima unbounded at time t: +-inf with the sign they take as
    D -> 0+ in ``mode``, i.e. the sign of S D (continuous through D = 0, so a state just
    past the zero gives it too)."""
    observe(mode, t, y, p, obs)
    d = 1.0
    if k_d >= 0:
        guards(mode, t, y, p, g)
        d = g[k_d] if g[k_d] != 0.0 else 1.0
    for k in range(mon.shape[0]):
        mon[k, 0], mon[k, 1], mon[k, 2] = np.inf, np.inf if obs[k] * d >= 0.0 else -np.inf, t


@njit(error_model="numpy")
def _observe_max(observe, mode, t, y, p, mon, obs):
    """Update the running maxima of the observables with their values at (t, y)."""
    observe(mode, t, y, p, obs)
    for k in range(mon.shape[0]):
        if abs(obs[k]) > mon[k, 0]:
            mon[k, 0], mon[k, 1], mon[k, 2] = abs(obs[k]), obs[k], t


@njit(error_model="numpy")
def _log(log, n_ev, t, k, mode_from, mode_to, breakpoint, y, quad, jump):
    """Append an event (time, guard, from, to, breakpoint passed, state, impact jump) to the EventLog."""
    n = y.size
    copy_into(log.jump[n_ev], jump)
    log.t[n_ev] = t
    log.index[n_ev, 0], log.index[n_ev, 1], log.index[n_ev, 2], log.index[n_ev, 3] = k, mode_from, mode_to, breakpoint
    copy_into(log.state[n_ev, :n], y)
    copy_into(log.state[n_ev, n:], quad)
    return n_ev + 1


#: The mode machine's work arrays: guard values, a state and a rate, an impact's frame and jump,
#: the observables, and the segments' (``segment.segment_work``).
MachineWork = namedtuple("MachineWork", "g y_tmp f frame jump obs segment")


@njit(error_model="numpy", refcounted=True)
def _work(n, n_guards, n_quad, n_obs):
    """The machine's work arrays for n states, n_guards guards, n_quad integrals, n_obs observables."""
    return MachineWork(np.empty(n_guards), np.empty(n), np.empty(n), np.empty(IMPACT_FRAME), np.empty(JUMP_WIDTH),
                       np.empty(n_obs), segment.segment_work(n, n_guards, n_quad, n_obs))


@njit(error_model="numpy")
def _valid(tables, start, settings, record):
    """The sizes agree and the settings make sense (the array accesses below are unchecked)."""
    n, n_quad, out, log, steps = start.y.size, start.quad.size, record.out, record.log, record.steps
    cap = steps.f.shape[0]
    return (n >= 1 and settings.t_end > start.t and settings.tol.rtol > 0.0 and (n_quad == 0 or n_quad == n)
            and out.y.shape[1] == n + n_quad and out.mode.size == out.t.size
            and out.p.shape[0] == out.t.size and out.p.shape[1] == start.p.size
            and log.state.shape[1] == n + n_quad and tables.guard_direction.shape[0] == tables.kind.size
            and steps.f.shape[1] == 4 and steps.index.shape[0] == cap and steps.index.shape[1] == 2
            and steps.y_a.shape[0] == cap and steps.y_a.shape[1] == n + n_quad
            and steps.y_hi.shape[0] == cap and steps.y_hi.shape[1] == n + n_quad
            and steps.Q.shape[0] == cap and steps.Q.shape[1] == n + n_quad + 1 and steps.Q.shape[2] == 4
            and steps.seg_p.shape[0] == steps.seg_mode.size and steps.seg_p.shape[1] == start.p.size
            and steps.count.size == 2)


@njit(error_model="numpy")
def _slide_at_rest(m, flank, direction, rhs, guards, t, y, p, tables, g, f):
    """How sliding mode ``m`` (on ``flank``, in ``direction``) meets the contact conditions at
    rest at (t, y): REGULAR (D > 0, jam > 0, the contact force N >= 0 and a1 the way it slides),
    SINGULAR (the same with D <= 0: a Painleve solution no integration can follow), else NO.
    The contact force on ``flank`` has the sign of flank phi / D (S2 = -m1 m2 phi / D)."""
    guards(m, t, y, p, g)
    phi, d = g[_guard(G_PHI, tables.guard_kind)], g[_guard(G_D, tables.guard_kind)]
    k_jam = _guard(G_JAM, tables.guard_kind)
    rhs(m, t, y, p, f)
    if not direction * f[y.size - 1] > 0.0 or (k_jam >= 0 and g[k_jam] <= 0.0):
        return NO
    if d > 0.0:
        return REGULAR if flank * phi >= 0.0 else NO
    return SINGULAR if flank * phi * d >= 0.0 else NO


@njit(error_model="numpy")
def _rest_by_contact(flank, rhs, guards, t, y, p, tol, tables, g, y_tmp, f):
    """(mode, status, need) at rest (v1 = 0) in contact, at the start or where v1 reaches 0 (or a
    law changes while sticking), by the contact conditions: stick where both friction cones
    hold and the static contact force presses the touched flank; sliding in a direction where
    D > 0, the contact force is >= 0 and a1 points that way; parting where free flight opens
    the gap (its normal acceleration is -cos(gamma) phi: where touched flank phi < 0). ``flank``: the touched flank with a clearance, else 0 (both flanks, or a one-sided
    scene's only one). Exactly one must hold. Several (a Painleve solution with D <= 0 beside
    another) or none: status INDETERMINATE, need = the bit mask (1 << mode) of those that hold;
    a Painleve solution alone: INCONSISTENT in that mode. A mode that holds but the scene does
    not declare: UNDECLARED (a one-sided scene's parting: NEED_FLANK)."""
    has_a, has_b = _mode(M_SLIDING, 1, 1, tables) >= 0 or _mode(M_SLIDING, 1, -1, tables) >= 0, \
        _mode(M_SLIDING, -1, 1, tables) >= 0 or _mode(M_SLIDING, -1, -1, tables) >= 0
    one_sided = flank == 0 and has_a != has_b
    touched = flank if flank != 0 else ((1 if has_a else -1) if one_sided else 0)
    holds, mask, chosen, need, singular = 0, 0, -1, NEED_NOTHING, -1
    ms = _mode(M_STICK, 0, 0, tables)
    if ms >= 0:
        guards(ms, t, y, p, g)
        pressed = touched == 0 or g[_guard(G_FLANK_N, tables.guard_kind)] * touched >= 0.0
        if pressed and g[_guard(G_CONE_F, tables.guard_kind)] >= 0.0 and g[_guard(G_CONE_B, tables.guard_kind)] >= 0.0:
            holds, mask, chosen = holds + 1, mask | (1 << ms), ms
    for direction in (1, -1):
        found = -1
        for side in (1, -1):
            m = _mode(M_SLIDING, side, direction, tables)
            if m < 0 or (touched != 0 and side != touched):
                continue
            outcome = _slide_at_rest(m, side, direction, rhs, guards, t, y, p, tables, g, f)
            if outcome == SINGULAR:
                holds, mask, singular = holds + 1, mask | (1 << m), m
            elif outcome == REGULAR:  # on both flanks only where phi = 0: the probe picks one
                found = m if found < 0 else _sliding(direction, 0, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)[0]
        if found >= 0:
            holds, mask, chosen = holds + 1, mask | (1 << found), found
    if touched != 0 and touched * _phi(guards, t, y, p, tables, g) < 0.0:  # free flight opens the gap
        holds, chosen = holds + 1, _mode(M_FREE, 0, 0, tables)  # (one-sided: none, NEED_FLANK)
        mask, need = (mask | (1 << chosen), NEED_NOTHING) if chosen >= 0 else (mask, NEED_FLANK)
    if holds == 1 and singular >= 0:
        return singular, INCONSISTENT, NEED_NOTHING
    if holds == 1:
        return (chosen, FINISHED, NEED_NOTHING) if chosen >= 0 else (-1, UNDECLARED, need)
    if holds > 1:
        return -1, INDETERMINATE, mask
    return _missing_at_rest(ms, touched, rhs, guards, t, y, p, tables, g, f)


@njit(error_model="numpy")
def _phi(guards, t, y, p, tables, g):
    """The switching function phi at (t, y) (a guard of every sliding mode, the same in each)."""
    for m in range(tables.kind.size):
        if tables.kind[m] == M_SLIDING:
            guards(m, t, y, p, g)
            return g[_guard(G_PHI, tables.guard_kind)]
    return 0.0


@njit(error_model="numpy")
def _missing_at_rest(ms, touched, rhs, guards, t, y, p, tables, g, f):
    """(mode, status, need) where no declared mode meets the contact conditions at rest: the
    sliding mode the violated friction cone points to (on the touched flank, else the flank phi
    presses) is not declared (UNDECLARED), or has D <= 0 (INCONSISTENT: no contact force
    exists); without a stick mode, stick is missing; else INDETERMINATE with no mode (mask 0)."""
    if ms < 0:
        return -1, UNDECLARED, NEED_STICK
    guards(ms, t, y, p, g)
    direction = 1 if g[_guard(G_CONE_F, tables.guard_kind)] < 0.0 else (
        -1 if g[_guard(G_CONE_B, tables.guard_kind)] < 0.0 else 0)
    if direction == 0:
        return -1, INDETERMINATE, 0
    side = touched if touched != 0 else (1 if _phi(guards, t, y, p, tables, g) >= 0.0 else -1)
    m = _mode(M_SLIDING, side, direction, tables)
    if m < 0:
        return -1, UNDECLARED, NEED_FORWARD if direction > 0 else NEED_BACKWARD
    return (m, INCONSISTENT, NEED_NOTHING) if not _consistent(m, guards, t, y, p, tables, g) else (
        -1, INDETERMINATE, 0)


@njit(error_model="numpy")
def _entered(fns, tables, t0, y, p, tol, w):
    """(mode, status, need) the state (t0, y) enters: free flight off the flanks, compliant
    contact where pressed onto one, at rest as ``_at_rest`` decides, or sliding the way v1
    points."""
    rhs = fns.rhs  # (one name a line: numba unifies a tuple of functions, with a warning)
    guards = fns.guards
    g, y_tmp, f = w.g, w.y_tmp, w.f
    v = y[y.size - 1]
    m_free = _mode(M_FREE, 0, 0, tables)
    flank = _touching(guards, t0, y, p, tables, g)
    if m_free >= 0 and flank == 0:
        return m_free, FINISHED, NEED_NOTHING
    if _guard(G_MESH_N, tables.guard_kind) >= 0:
        if _pressed(flank, rhs, t0, y, p, tables, f):
            return _outcome(*_mesh_enter(flank, guards, t0, y, p, tables, g))
        return m_free, FINISHED, NEED_NOTHING
    if v == 0.0:
        return _at_rest(flank, rhs, guards, t0, y, p, tol, tables, g, y_tmp, f, True)
    return _outcome(*_sliding(1 if v > 0.0 else -1, flank, rhs, guards, t0, y, p, tol, tables, g, y_tmp, f))


@njit(error_model="numpy")
def _first_mode(fns, tables, start, y, p, tol, w):
    """(mode, status, need) the run starts in at (start.t, y): start.mode, or (-1) the mode the
    state enters (``_entered``); a carried stem pulled off at once is released first."""
    mode, status, need = start.mode, FINISHED, NEED_NOTHING
    if mode < 0:
        mode, status, need = _entered(fns, tables, start.t, y, p, tol, w)
    if status == FINISHED and _released(mode, fns.guards, start.t, y, p, tables, w.g):  # carried from the start
        mode, status, need = _entered(fns, tables, start.t, y, p, tol, w)
    return mode, status, need


@njit(error_model="numpy", refcounted=True)
def _segment(tables, mode, p, k_d, singular):
    """The Segment of ``mode``: its guards' directions; D's guard ``k_d`` as the one to hand over
    to the Painleve approach at (``singular``, and where D can end the mode), else none."""
    k_singular = k_d if singular and k_d >= 0 and tables.guard_direction[mode, k_d] != 0 else -1
    return Segment(mode, p, EventSettings(tables.guard_direction[mode], 0.0, 0.0, True, k_singular, True))


@njit(error_model="numpy")
def _latch(kind, k, t, y, p, tables, guards, g):
    """The laws' latches in p after guard k (of ``kind``) fired at (t, y); returns the breakpoint
    of a piecewise law passed there (``_locate_piece``), else 0."""
    if kind == G_TRIP:
        p[tables.guard_latch[k]] = t
    elif kind == G_LAW:
        return _locate_piece(k, guards, t, y, p, tables, g)
    return 0


@njit(error_model="numpy")
def _jump(fns, tables, tol, mode, kind, k, t, y, p, w):
    """(next mode, status, need) after guard k (of ``kind``) fired in ``mode``: an impact where a
    gap closes or body 2 reaches the stem (its jump into w.jump, the flight time to the next
    landing into w.frame[0], else inf), the stem's release, else the mode machine's choice."""
    rhs = fns.rhs
    guards = fns.guards
    g, y_tmp, f, frame, jump = w.g, w.y_tmp, w.f, w.frame, w.jump
    frame[0] = np.inf  # a collision or pickup leaves here the flight time to the next landing
    mesh = _guard(G_MESH_N, tables.guard_kind) >= 0  # compliant flanks: no impacts, contact by overlap
    if (kind == G_GAP_A or kind == G_GAP_B) and mesh:  # the flanks begin to overlap
        return _outcome(*_mesh_enter(1 if kind == G_GAP_A else -1, guards, t, y, p, tables, g))
    if kind == G_GAP_A or kind == G_GAP_B:  # the gap closed: a collision on that flank
        return _collide(fns.impact, 1 if kind == G_GAP_A else -1, rhs, guards, t, y, p, tol, tables, g, y_tmp, f,
                        frame, jump)
    if kind == G_STEM_GAP:  # body 2 reaches the stem: the pickup
        return _pickup(fns.impact, k, rhs, guards, t, y, p, tol, tables, g, y_tmp, f, frame, jump)
    if kind == G_STEM_N:  # the stem leaves body 2: the load and its mass leave with it
        p[tables.guard_latch[k]] = np.inf
        return _moving_on(0, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)
    return _select(mode, kind, rhs, guards, t, y, p, tol, tables, g, y_tmp, f)


@njit(error_model="numpy")
def _checked(fns, tables, tol, mode, new, status, need, t, y, p, w):
    """(mode, status, need) after a jump: a carried stem the new mode pulls off is released; a
    new mode without a consistent contact force stops the run (INCONSISTENT; the maxima keep the
    finite peaks reached up to the event: no force grew without bound before it)."""
    rhs = fns.rhs
    guards = fns.guards
    g = w.g
    if status == FINISHED and _released(new, guards, t, y, p, tables, g):
        new, status, need = _moving_on(0, rhs, guards, t, y, p, tol, tables, g, w.y_tmp, w.f)
    if status == FINISHED and not _consistent(new, guards, t, y, p, tables, g):
        status = INCONSISTENT
    return new, status, need


#: integrate_hybrid(functions, run_segment, tables, start, settings, record) -> (status, t_stop, events, last mode, need, first mode)
HYBRID_SIG = types.Tuple((types.int64, types.float64, types.int64, types.int64, types.int64,
                          types.int64))(segment.FUNCTIONS, segment.SegmentFunction, MODE_TABLES, START, SETTINGS,
                                        RECORD)


@cache_guard.compile_cached(HYBRID_SIG, error_model="numpy", nogil=True)
def integrate_hybrid(fns, run_segment, tables, start, settings, record):
    """Integrate the model from ``start`` to settings.t_end through its mode changes.

    fns: the Functions (the method's step; the model's rhs, jac, guards, observe and impact:
        its impact frame, a collision when a gap closes with a clearance, the stem's pickup
        with lost motion). run_segment: ``hybrid.segments.run_segment`` (a kernel of its own,
        called through its address). tables: the ModeTables from ``modes.tables``.
    start: Start. start.p: parameters and latches; the runtime writes the latches (a
        torque switch's trip time, the piece of each piecewise law, set at the start and
        at every law event), so pass a copy. start.quad: the integral of the states at
        start.t (x1 when v1 is the only state), carried in columns n: of out.y and
        log.state; size 0 for none. start.mode: the initial mode, or -1 to select it from
        start.y (at v1 = 0 from the friction cones).
    settings: Settings (method, t_end, Tolerances: rtol, atol per state, hmin, hmax;
        max_steps bounds step attempts).
    record: Record. steps: the StepLog (``steplog``), the accepted steps and the segments' modes
        and parameter vectors, for rows evaluated after the run. out: Outputs: times (sorted,
        >= t0) and the rows filled there:
        state, mode and the parameter vector with the latches in force (a row at an
        event time belongs to the segment that ends there: its left limit); rows after
        a stop keep their contents, mode -1. log: the EventLog (time; guard, from-mode,
        to-mode (-1: stop); state after the event; an impact's (P_n, P_t, energy lost,
        v1 before)), its capacity is log.t.size. mon: (K, 3) running max |observable k|
        as (|value|, value, t), K = number of observables; pass zeros. counters:
        int64[segment.N_COUNTERS] (steps, rejected, rhs calls, jac calls, method switches).

    A sequence of named steps: ``_first_mode``, then per segment ``_segment`` and ``run_segment`` (the step
    loop, and the Painleve approach where D heads for 0: it locates D = 0, status
    INCONSISTENT, event guard D; the maxima in mon are then +-inf: the reactions grow without
    bound there) and at its event ``_latch``, ``_jump``, ``_checked`` (a mode or impact without
    a consistent force stops the run with the finite maxima reached before it), ``_log``. A run
    that stops at its start (UNDECLARED, INDETERMINATE) integrated nothing: its maxima are NaN.

    Returns (status, t_stop, number of events, last mode (for INCONSISTENT the mode
    found inconsistent), need, initial mode).
    """
    t0 = start.t
    if not _valid(tables, start, settings, record):
        return INVALID_INPUT, t0, 0, -1, NEED_NOTHING, -1
    tables, start, settings, record = borrowed((tables, start, settings, record))
    out, log, mon, p, t_end = record.out, record.log, record.mon, start.p, settings.t_end
    guards = fns.guards
    observe = fns.observe
    n = start.y.size
    y, q = start.y.copy(), start.quad.copy()
    w = _work(n, tables.guard_direction.shape[1], q.size, mon.shape[0])
    g, jump = w.g, w.jump
    out.mode[:] = -1
    record.steps.count[:] = 0
    k_d = _guard(G_D, tables.guard_kind)
    _latch_pieces(guards, t0, y, p, tables, g)
    _carry_at_start(fns.impact, guards, t0, y, p, tables, g, w.frame)
    mode, status, need = _first_mode(fns, tables, start, y, p, settings.tol, w)
    if status != FINISHED and status != INCONSISTENT:  # UNDECLARED, or INDETERMINATE at rest
        for i in range(mon.shape[0]):  # nothing integrated: no maxima
            mon[i, 0], mon[i, 1], mon[i, 2] = np.nan, np.nan, t0
        return status, t0, 0, -1, need, -1
    if status == INCONSISTENT or not _consistent(mode, guards, t0, y, p, tables, g):
        _unbounded(observe, guards, mode, t0, y, p, -1, mon, w.obs, g)
        return INCONSISTENT, t0, 0, mode, NEED_NOTHING, mode
    first, status = mode, FINISHED
    t, i, n_ev, same, h = t0, 0, 0, 0, 0.0
    singular = True  # hand over to the Painleve approach when D heads for 0
    while True:
        i0 = i
        seg_status, t_new, k, i, h, singular = run_segment(fns, settings, _segment(tables, mode, p, k_d, singular),
                                                           State(t, y, q, h), record, i, w.segment)
        for r in range(i0, i):
            out.mode[r] = mode
            copy_into(out.p[r], p)
        steplog.end_segment(record.steps, mode, p)
        if seg_status == segment.APPROACH:  # back from the approach, on in t
            t = t_new
            continue
        same = same + 1 if t_new - t <= SAME_TIME_ULPS * (np.nextafter(t, np.inf) - t) else 0
        t = t_new
        if seg_status != segment.EVENT:
            status = FINISHED if seg_status == segment.REACHED_END else seg_status
            break
        if same >= MAX_SAME_TIME:
            status = CHATTERING
            break
        if n_ev == log.t.size:
            status = TOO_MANY_EVENTS
            break
        kind = tables.guard_kind[k]
        jump[:] = np.nan  # no impact, unless a collision or pickup fills it
        if kind == G_V1:  # at rest exactly: the left limits of the observables there, v1 = 0
            y[n - 1] = 0.0
            _observe_max(observe, mode, t, y, p, mon, w.obs)
        if kind == G_D or kind == G_JAM:  # D or the jam factor of this mode reached 0
            if mon.shape[0] > 0 and mon[0, 0] != np.inf:  # (the approach marked them already)
                _unbounded(observe, guards, mode, t, y, p, k_d, mon, w.obs, g)
            n_ev = _log(log, n_ev, t, k, mode, -1, 0, y, q, jump)
            status = INCONSISTENT
            break
        breakpoint = _latch(kind, k, t, y, p, tables, guards, g)
        new, status, need = _jump(fns, tables, settings.tol, mode, kind, k, t, y, p, w)
        if w.frame[0] < np.inf:  # a first step inside the bounce, so that the gap's guard is armed again
            h = 0.25 * w.frame[0] if h <= 0.0 else min(h, 0.25 * w.frame[0])
        new, status, need = _checked(fns, tables, settings.tol, mode, new, status, need, t, y, p, w)
        if status == FINISHED and new == mode and kind == G_PHI:
            continue  # phi crossed within its noise (the probe keeps the flank): no event
        n_ev = _log(log, n_ev, t, k, mode, new if status == FINISHED else -1, breakpoint, y, q, jump)
        if status != FINISHED:
            mode = new if status == INCONSISTENT else mode
            break
        mode = new
        if t == t_end:
            break
    return status, t, n_ev, mode, need, first
