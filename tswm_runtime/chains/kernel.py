"""A chain's whole run in one compiled call: its segments (the mode machine's segment kernel, through its
address), its events, the decision at each (``rules.settle``: the latches, then the next mode) and
its resting phases, written into a ChainRecord from which ``chains/run.py`` builds the result.

Per phase (a stretch in one mode, or at rest) the record keeps its mode, times, latches, the range of its samples
and its peaks; a sliding phase's samples are (t, q0, v0, stage forces, the last body's coordinate) at its start, at
every output time inside it and where it ends (its event, t_end or a stop). Its peaks are per stage force the
largest |value| of the continuous solution in the phase, signed, and its time (NaN: undetermined in the whole phase,
a stuck group's force; a resting phase has none). A stage force is affine in the bodies' forces, which depend on the
coordinates (springs, the seat while its latch holds), on v0 through a motor's torque and on nothing else (no time).
Without a powered motor it is affine in q0, monotone in a sliding phase (v0 = 0 is an event), so its largest |value|
is at a phase end, a sample; in a clearance's open phase a closed stage's force depends on its own group's bodies
only (derivation/chain/clearance.py ``open_phase``: the open stage carries nothing), so on q0 or on qk, each
monotone there (a group's speed reaching 0 is an event, except for a stuck one, whose forces are NaN). While a motor
is powered the segment kernel monitors the module's observables (``observe``: the stage forces) in every step and
refines their maxima on its dense output (``segment._monitor``, ``_refine``); the peaks are the larger of those and
the samples (a phase that ends where D reaches 0 keeps its samples': the forces grow without bound there and the run
stops).
Per event: the guard (START at the start), the modes before and after (NO_MODE: the run stops), the
decision's outcome, the state and the latches the decision saw. The trip: what the chain carried just before
the switch cut the motor.
"""
from collections import namedtuple

import numpy as np
from numba import types

from tswm_runtime.chains.backlash import IMPACT_COLUMNS, strike
from tswm_runtime.hybrid.addressed import ADDRESSES, model_functions, segment_function
from tswm_runtime.chains.rules import (NO_MODE, NONE, RESTING, RESTING_GROUP, SEVERAL, START, ChainFunctions,
                                             ChainTables, chain_work, clearance_index, current_index, decide, is_open,
                                             last_coordinate, settle)
from tswm_runtime.integration import segment
from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.addresses import guards_at
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.borrow import borrowed
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import MATRIX, VECTOR
from tswm_runtime.jit.structures import INTS, RECORD, SETTINGS, EventSettings, Record, Segment, State

# Status codes besides FINISHED (0) and the integrator's (segment's negative codes).
FINISHED = 0
UNDECIDED = -20       # the decision found no consistent mode
INDETERMINATE = -21   # the decision found several
SINGULAR = -22        # D or the jam factor reached 0 in the mode: no contact force keeps the stages together
TOO_MANY_EVENTS = -23
CHATTERING = -24
INCONSISTENT_START = -25  # D or the jam factor <= 0 where a mode begins
RECORD_FULL = -26     # more phases, events or samples than the record holds: run again with more room
GROUP_AT_REST = -27   # a group at rest while the stage with the clearance is open can neither stay nor leave rest
IMPACT_JAMMED = -28   # the impulse cannot stop the flanks' approach (dnu/dP_n <= 0)
TWO_OPEN = -29        # a second stage with a clearance would open while one is open (not modelled)
MAX_SAME_TIME = 8     # decisions at one instant before the run stops

#: Where the run writes (sizes from ``chains/run.py``): phases (mode, first sample, end of samples) and
#: phase_f (t_start, t_end, p); samples (t, q0, v0, 3 stage forces per stage, q_N); events (guard, from, to,
#: outcome) and event_f (t, y: q0, v0 and with a clearance qk, vk, p); trip (t, q0, v0, drive, stage forces, q_N, mode;
#: t NaN: no cut);
#: counts (phases, samples, events, impacts); impacts (backlash.IMPACT_COLUMNS per impact, as many rows as events);
#: peaks per phase (the 3 per stage stage forces' maxima, signed, then their times).
ChainRecord = namedtuple("ChainRecord", "phases phase_f samples events event_f trip counts impacts peaks")
INT_MATRIX = types.int64[:, ::1]
CHAIN_RECORD = types.NamedTuple((INT_MATRIX, MATRIX, MATRIX, INT_MATRIX, MATRIX, VECTOR, INTS, MATRIX, MATRIX),
                                ChainRecord)


def chain_record(phases, samples, n_states, n_p, stages):
    """An empty ChainRecord with room for ``phases`` phases and ``samples`` samples of a chain of ``stages`` stages
    with n_states states and n_p slots of p: plain Python for one run (chains/run.py), compiled as
    ``chain_record_compiled`` for the batch's cases (chains/batch.py)."""
    forces = 3 * stages
    return ChainRecord(np.empty((phases, 3), np.int64), np.empty((phases, 2 + n_p)), np.empty((samples, 4 + forces)),
                       np.empty((phases, 4), np.int64), np.empty((phases, 1 + n_states + n_p)), np.empty(6 + forces),
                       np.zeros(4, np.int64), np.empty((phases, len(IMPACT_COLUMNS))), np.empty((phases, 2 * forces)))


chain_record_compiled = njit(error_model="numpy", refcounted=True)(chain_record)   # it allocates
CHAIN_TABLES = types.NamedTuple((INTS, INT_MATRIX, *(types.int64,) * 10, types.float64, types.float64,
                                 types.float64, INT_MATRIX, types.int64, INTS, *(types.int64,) * 8), ChainTables)
#: run_chain_at(functions, chain functions (stage_forces, body_forces_into, impact), tables, settings, y, p, record,
#: chain record, max_events) -> (status, t_stop)
CHAIN_SIG = types.Tuple((types.int64, types.float64))(ADDRESSES, types.UniTuple(types.int64, 3), CHAIN_TABLES,
                                                       SETTINGS, VECTOR, VECTOR, RECORD, CHAIN_RECORD, types.int64)


@njit(error_model="numpy")
def _sample(chain_fns, c, rec, mode, t, y, p, forces):
    """Append (t, q0, v0, stage forces in mode, the last body's coordinate) to the samples; False when the record
    is full."""
    s = rec.counts[1]
    if s >= rec.samples.shape[0]:
        return False
    row = rec.samples[s]
    row[0], row[1], row[2] = t, y[0], y[1]
    chain_fns.stage_forces(mode, t, y, p, forces)
    copy_into(row[3:3 + forces.size], forces)
    row[3 + forces.size] = last_coordinate(c, y, p)
    rec.counts[1] = s + 1
    return True


@njit(error_model="numpy")
def _unmonitored(mon):
    """The maxima made ready for a phase: none yet (a NaN force never replaces them: abs(NaN) > -1 is False)."""
    mon[:, 0] = -1.0
    mon[:, 1] = np.nan
    mon[:, 2] = np.nan


@njit(error_model="numpy")
def _keep_peaks(mon, row):
    """The phase's maxima (values, then times) into its row of the record's peaks; not the inf the Painleve
    approach marks where D reaches 0 (the run stops there: the samples' largest, at the near side, stands)."""
    m = mon.shape[0]
    for k in range(m):
        if np.isfinite(mon[k, 0]):
            row[k], row[m + k] = mon[k, 1], mon[k, 2]


@njit(error_model="numpy")
def _open(rec, mode, t, p):
    k = rec.counts[0]
    rec.phases[k, 0], rec.phases[k, 1], rec.phases[k, 2] = mode, rec.counts[1], rec.counts[1]
    rec.phase_f[k, 0], rec.phase_f[k, 1] = t, t
    copy_into(rec.phase_f[k, 2:], p)
    rec.peaks[k, :] = np.nan
    rec.counts[0] = k + 1


@njit(error_model="numpy")
def _close(rec, t):
    """End the phase at t; its peaks: per force the first of largest magnitude of its monitored maximum (if
    any) and its samples, a NaN never."""
    k = rec.counts[0] - 1
    rec.phase_f[k, 1] = t
    rec.phases[k, 2] = rec.counts[1]
    peaks, m = rec.peaks[k], rec.peaks.shape[1] // 2
    for s in range(rec.phases[k, 1], rec.counts[1]):
        row = rec.samples[s]
        for j in range(m):
            if abs(row[3 + j]) > abs(peaks[j]) or (np.isnan(peaks[j]) and not np.isnan(row[3 + j])):
                peaks[j], peaks[m + j] = row[3 + j], row[0]


@njit(error_model="numpy")
def _event(rec, t, guard, before, after, outcome, y, p):
    e = rec.counts[2]
    rec.events[e, 0], rec.events[e, 1], rec.events[e, 2], rec.events[e, 3] = guard, before, after, outcome
    rec.event_f[e, 0] = t
    copy_into(rec.event_f[e, 1:1 + y.size], y)
    copy_into(rec.event_f[e, 1 + y.size:], p)
    rec.counts[2] = e + 1


@njit(error_model="numpy")
def _consistent(guards, mode, t, y, p, g):
    """D and the jam factor of ``mode`` are > 0 at (t, y)."""
    guards(mode, t, y, p, g)
    return g[0] > 0.0 and g[1] > 0.0


@njit(refcounted=True, error_model="numpy")
def _slide(fns, run_segment, settings, c, mode, t, y, p, record, i, h, scratch):
    """Integrate in ``mode`` from (t, y), first trying step h (<= 0: chosen), to its first event or the
    end, handing over to the Painleve approach where D heads for 0 and on in t after it; returns
    (status, t, guard, next output row, next step)."""
    q, singular = np.empty(0), True
    while True:
        k_singular = 0 if singular and c.guard_direction[mode, 0] != 0 else -1
        ev = EventSettings(c.guard_direction[mode], 0.0, 0.0, True, k_singular, True)
        status, t, k, i, h, singular = run_segment(fns, settings, Segment(mode, p, ev), State(t, y, q, h), record, i,
                                                   scratch)
        if status != segment.APPROACH:
            return status, t, k, i, h


@njit(error_model="numpy")
def _run(functions, chain_addresses, c, settings, y, p, record, rec, max_events, w, scratch):
    """``run_chain_at`` from the state y (written in place), with its work arrays w and scratch; every array
    borrowed: handing them on to the segments, the decisions and the record costs no reference counting."""
    c, settings, y, p, record, rec, w, scratch = borrowed((c, settings, y, p, record, rec, w, scratch))
    fns, run_segment = model_functions(functions), segment_function(functions)
    chain_fns = ChainFunctions(guards_at(chain_addresses[0]), guards_at(chain_addresses[1]),
                               guards_at(chain_addresses[2]))
    out, counters = record.out, record.counters
    quiet = Record(out, record.log, record.mon[:0], counters, record.steps)   # its segments monitor nothing
    stages, n_guards, n_states = c.stages, c.guard_direction.shape[1], y.size
    rec.counts[0], rec.counts[1], rec.counts[2], rec.counts[3] = 0, 0, 0, 0
    rec.trip[0] = np.nan
    t, t_end = 0.0, settings.t_end
    outcome, mode = settle(fns, chain_fns, c, t, y, p, RESTING, START, w, rec.trip)
    _event(rec, t, START, RESTING, mode, outcome, y, p)
    status, same, h = FINISHED, 0, 0.0
    while True:
        if rec.counts[0] + 1 >= rec.phases.shape[0] or rec.counts[2] + 1 >= rec.events.shape[0]:
            status = RECORD_FULL
            break
        if mode == NO_MODE:
            status = INDETERMINATE if outcome == SEVERAL else GROUP_AT_REST if outcome == RESTING_GROUP else UNDECIDED
            break
        if mode == RESTING:
            t_cut = p[c.p_pick] + p[c.p_delay] if p[c.p_switch] == c.picked else np.inf
            _open(rec, RESTING, t, p)
            _close(rec, min(t_cut, t_end))
            h = 0.0   # leaving rest: a step chosen afresh
            for r in range(out.t.size):
                if out.t[r] >= t:
                    for j in range(n_states):
                        out.y[r, j] = 0.0 if j % 2 == 1 else y[j]
            if t_cut >= t_end:
                t = t_end
                break
            t = t_cut
            outcome, mode = settle(fns, chain_fns, c, t, y, p, RESTING, n_guards - 1, w, rec.trip)
            _event(rec, t, n_guards - 1, RESTING, mode, outcome, y, p)
            continue
        if rec.counts[2] >= max_events:
            status = TOO_MANY_EVENTS
            break
        _open(rec, mode, t, p)
        if not _sample(chain_fns, c, rec, mode, t, y, p, w.forces):
            status = RECORD_FULL
            break
        if not _consistent(fns.guards, mode, t, y, p, w.g):
            status = INCONSISTENT_START
            break
        i = np.searchsorted(out.t, t)
        i0 = i
        watched = c.motor != 0 and p[c.p_switch] != c.tripped   # a powered motor: the peaks may lie inside
        if watched:
            _unmonitored(record.mon)
        if counters[segment.N_SWITCHES] % 2 == 1:  # each phase starts on DOPRI5 (method auto): its step chosen
            h = 0.0
        counters[segment.N_SWITCHES] = 0
        # the last phase's next step is carried over the event (as the mode machine does): no fresh
        # initial step and no climb from it in each phase; DOPRI5's defect check judges it as any step
        seg_status, t_new, k, i, h = _slide(fns, run_segment, settings, c, mode, t, y, p,
                                            record if watched else quiet, i, h, scratch)
        if watched:
            _keep_peaks(record.mon, rec.peaks[rec.counts[0] - 1])
        for r in range(i0, i):
            if not _sample(chain_fns, c, rec, mode, out.t[r], out.y[r], p, w.forces):
                status = RECORD_FULL
        same = same + 1 if t_new == t else 0
        t = t_new
        if status != FINISHED or seg_status != segment.EVENT:
            if status == FINISHED and not (i > i0 and out.t[i - 1] == t):   # the end, unless an output time
                if not _sample(chain_fns, c, rec, mode, t, y, p, w.forces):
                    status = RECORD_FULL
            _close(rec, t)
            if status == FINISHED and seg_status != segment.REACHED_END:
                status = seg_status
            break
        if k == stages + 2:   # v0 reached 0: at rest exactly (the whole chain unless a stage is open)
            y[1] = 0.0
            if n_states == 4 and not is_open(c, mode):
                y[3] = 0.0
        if is_open(c, mode) and k == stages + 5:   # the output group stopped
            y[3] = 0.0
        if not _sample(chain_fns, c, rec, mode, t, y, p, w.forces):
            status = RECORD_FULL
            break
        _close(rec, t)
        if k <= 1:            # D or the jam factor reached 0
            _event(rec, t, k, mode, NO_MODE, NONE, y, p)
            status = SINGULAR
            break
        if is_open(c, mode) and 2 <= k < 2 + stages and clearance_index(c, k - 1) >= 0:
            status = TWO_OPEN   # a closed stage with a clearance would open too in an open phase
            _event(rec, t, k, mode, NO_MODE, NONE, y, p)
            break
        if is_open(c, mode) and (k == stages + 3 or k == stages + 4):   # the flanks meet
            i_row = rec.counts[3]
            rec.counts[3] = i_row + 1
            struck, flight = strike(fns, chain_fns, c, 1 if k == stages + 3 else -1, t, y, p, settings.tol, w,
                                    rec.impacts[i_row])
            if not struck:
                _event(rec, t, k, mode, NO_MODE, NONE, y, p)
                status = IMPACT_JAMMED
                break
            if p[c.p_contact + current_index(c, p)] == 0.0:   # a rebound: its first step short enough for the gap's
                # guard to see it end
                h = flight / 4.0 if flight < np.inf else 0.0
        outcome, new = settle(fns, chain_fns, c, t, y, p, mode, k, w, rec.trip)
        _event(rec, t, k, mode, new, outcome, y, p)
        if same >= MAX_SAME_TIME:
            status = CHATTERING
            break
        mode = new
    return status, t


@cache_guard.compile_cached(CHAIN_SIG, error_model="numpy", nogil=True)
def run_chain_at(functions, chain_addresses, c, settings, y0, p, record, rec, max_events):
    """The chain's run from (0, y0) under p (its latches written; its derived slots filled by the module's
    prepare) to settings.t_end: phases, events and their
    decisions, the trip, into rec, each sliding phase's maxima of the module's observables (record.mon's rows:
    3 per stage) into rec.peaks; output rows into record.out.y (q0, v0; a row at an event time keeps the
    later phase's value, rows after a stop NaN). With clearances y0 is (q0, v0, qk, vk) of the current clearance
    stage k and vk is set here to c_k v0 of p (the chain starts moving as one body: the gaps' rates 0). Returns
    (status, t_stop).
    Its work arrays are made here and kept alive for ``_run``, which borrows them (``borrow``) with its
    arguments."""
    n_guards = c.guard_direction.shape[1]
    w = chain_work(n_guards, c.stages, c.direction.size, p.size, y0.size)
    scratch = segment.segment_work(y0.size, n_guards, 0, record.mon.shape[0])
    y = y0.copy()
    if y.size == 4:
        y[3] = p[c.p_speed_k] * y[1]
    return _run(functions, chain_addresses, c, settings, y, p, record, rec, max_events, w, scratch)


@njit(cache=True, error_model="numpy", no_cpython_wrapper=False, refcounted=True)  # chain_work allocates
def decide_at(functions, chain_addresses, c, t, y, p, current):
    """The compiled decision (``rules.decide``) called from Python: (outcome, mode) at (t, y) under p."""
    fns = model_functions(functions)
    chain_fns = ChainFunctions(guards_at(chain_addresses[0]), guards_at(chain_addresses[1]),
                               guards_at(chain_addresses[2]))
    w = chain_work(c.guard_direction.shape[1], c.stages, c.direction.size, p.size, y.size)
    return decide(fns, chain_fns, c, t, y, p, current, w)
