"""Many runs of one model in one numba call, in parallel over the cores.

``run_batch`` integrates case after case (one row of parameters each) with
``hybrid.integrate_hybrid``, in a ``prange`` loop: every case has its own work
arrays (parameter copy, event log, monitor, counters; allocated once per chunk of CHUNK_CASES
cases and reset per case), one output point (t_end),
and writes one row of results. The functions come as addresses (``entry.functions``:
the mode machine, the method's step, the model's, the segment kernel), so, like ``integrate_hybrid``, the
batch function is compiled once with an explicit signature, cached on disk and reused
for every model. Calling ``integrate_hybrid`` from Python costs about 20 us per call for
unboxing its arguments (a run to t_end = 1e-9 s through its entry point, session 7);
inside this loop a case costs only its integration. ``integrate_hybrid`` is called
through its address: its compiled code is not linked into this kernel, whose cold
compile then skips re-optimizing the whole mode machine (issue 13: 24 s of 72).
Arguments travel as named structures: the run's Start (its p unused: each case's is a
row of P) and Settings, and the Results it writes.

Per case the result rows hold:
    out_f[c] = (t_stop, S1m, tS1m, S2m, tS2m, x1, v1, impact energy)   (x1, v1 at t_stop;
                NaN when the run stopped inside a step (max-steps, step-too-small,
                not-finite); the kinetic energy lost in impacts)
    out_i[c] = (status, n_events, steps, rejected, rhs calls, jac calls, first mode,
                n_modes, impacts (collisions and pickups))
    seq[c, :n_modes] = the sequence of modes visited (the first mode, then every
                event's to-mode that differs from the mode before; at most
                seq.shape[1], the rest is cut off and n_modes counts them all).
"""
from collections import namedtuple

import numpy as np
from numba import prange, types

from tswm_runtime.hybrid import addressed
from tswm_runtime.hybrid.machine import HYBRID_SIG
from tswm_runtime.integration import segment
from tswm_runtime.integration.steplog import no_steps
from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.addresses import function_at
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import MATRIX
from tswm_runtime.jit.structures import (INDEX_WIDTH, JUMP_WIDTH, MODE_TABLES, SETTINGS, START, EventLog, Outputs,
                                         Record, Settings, Start, Tolerances)

F_T_STOP, F_S1M, F_TS1M, F_S2M, F_TS2M, F_X1, F_V1, F_IMPACT_E = range(8)
N_F = 8
I_STATUS, I_EVENTS, I_STEPS, I_REJECTED, I_RHS, I_JAC, I_FIRST, I_NMODES, I_IMPACTS, I_SWITCHES = range(10)
N_I = 10

#: Where run_batch writes, one row per case: out_f (N_F floats), out_i (N_I integers), seq.
Results = namedtuple("Results", "f i seq")
RESULTS = types.NamedTuple((MATRIX, types.int64[:, ::1], types.int64[:, ::1]), Results)

CHUNK_CASES = 64  # cases that share one record (its ~20 arrays allocated once per chunk, not per case)

#: The mode machine at its address (the C wrapper: a case's failure is its status).
_machine_at = function_at(types.FunctionType(HYBRID_SIG))

BATCH_SIG = types.none(
    addressed.ADDRESSES, MODE_TABLES,  # functions: entry.functions(method, model); mode tables
    MATRIX, START,  # P (cases x parameters, latches included); start (start.p is not used: a row of P is)
    SETTINGS, types.int64, types.int64,  # settings, max_events, number of observables
    RESULTS,
)


@njit(error_model="numpy", refcounted=True)
def _case_record(t_end, width, n_params, max_events, n_obs):
    """A case's Record: one output point (the state at t_end), an event log of max_events, the
    maxima of n_obs observables, the counters, no step log."""
    out = Outputs(np.full(1, t_end), np.full((1, width), np.nan), np.empty(1, np.int64), np.empty((1, n_params)))
    log = EventLog(np.empty(max_events), np.empty((max_events, INDEX_WIDTH), np.int64), np.empty((max_events, width)),
                   np.zeros((max_events, JUMP_WIDTH)))
    return Record(out, log, np.zeros((n_obs, 3)), np.zeros(segment.N_COUNTERS, np.int64), no_steps(width, n_params))


@njit(error_model="numpy", refcounted=True)
def _write_floats(row, t_stop, n_ev, n, record, case):
    """t_stop, the maxima of S1 and S2, and x1, v1 at t_stop into ``row`` (out_f[c])."""
    out, log, mon = record.out, record.log, record.mon
    width = out.y.shape[1]
    n_obs = mon.shape[0]
    row[F_T_STOP] = t_stop
    # The state at t_stop: the output point at t_end, else the last event's state
    # if the run stopped at it, else the start's if it stopped there, else unknown (NaN).
    ys = out.y[0]
    if out.mode[0] < 0:
        ys = np.full(width, np.nan)
        if n_ev > 0 and log.t[n_ev - 1] == t_stop:
            ys = log.state[n_ev - 1].copy()
        elif n_ev == 0 and t_stop == case.t:
            copy_into(ys[:n], case.y)
            copy_into(ys[n:], case.quad)
    row[F_X1] = ys[n] if n == 1 else ys[0]
    row[F_V1] = ys[n - 1]
    if n_obs > 0:
        row[F_S1M], row[F_TS1M] = mon[0, 1], mon[0, 2]
    else:
        row[F_S1M], row[F_TS1M] = np.nan, np.nan
    if n_obs > 1:
        row[F_S2M], row[F_TS2M] = mon[1, 1], mon[1, 2]
    else:
        row[F_S2M], row[F_TS2M] = np.nan, np.nan


@njit(error_model="numpy")
def _write_sequence(row_f, row_i, seq_row, first, n_ev, log):
    """The modes visited into seq_row and their number, the impacts and the energy they took."""
    n_seq = seq_row.size
    n_modes = 0
    prev = -1
    if first >= 0:
        if n_seq > 0:
            seq_row[0] = first
        n_modes, prev = 1, first
    impacts, lost = 0, 0.0
    for e in range(n_ev):
        to = log.index[e, 2]
        if to >= 0 and to != prev:
            if n_modes < n_seq:
                seq_row[n_modes] = to
            n_modes += 1
            prev = to
        if not np.isnan(log.jump[e, 0]):  # an impact (the log's jump is NaN for other events)
            impacts += 1
            lost += log.jump[e, 2]
    row_i[I_NMODES] = n_modes
    row_i[I_IMPACTS], row_f[F_IMPACT_E] = impacts, lost


@njit(error_model="numpy")
def _reset(record, p, row):
    """The chunk's record made ready for its next case (no maxima, no counts, no row written; the
    mode machine resets the step log and the rows' modes), and the case's parameters into p."""
    record.mon[:, :] = 0.0
    record.counters[:] = 0
    record.out.y[:, :] = np.nan
    copy_into(p, row)


@cache_guard.compile_cached(BATCH_SIG, parallel=True, error_model="numpy")
def run_batch(functions, tables, P, start, settings, max_events, n_obs, results):
    """Integrate every row of P from ``start`` to settings.t_end; results into ``results``. The cases
    go in chunks of CHUNK_CASES, each with one record and parameter vector, reset per case."""
    n = start.y.size
    width = n + start.quad.size
    # The prange body takes a named tuple only as an argument or built by a call: no tuple of
    # tuples, none unpacked from one.
    method, t_end, max_steps = settings.method, settings.t_end, settings.max_steps
    tol = Tolerances(settings.tol.rtol, settings.tol.atol, settings.tol.hmin, settings.tol.hmax)
    n_cases = P.shape[0]
    for chunk in prange((n_cases + CHUNK_CASES - 1) // CHUNK_CASES):
        record = _case_record(t_end, width, P.shape[1], max_events, n_obs)
        p = np.empty(P.shape[1])
        for c in range(chunk * CHUNK_CASES, min((chunk + 1) * CHUNK_CASES, n_cases)):
            _reset(record, p, P[c])
            case = Start(start.t, start.y, start.quad, start.mode, p)
            integrate = _machine_at(functions[0])
            status, t_stop, n_ev, last, need, first = integrate(addressed.model_functions(functions),
                                                                addressed.segment_function(functions), tables,
                                                                case, Settings(method, t_end, tol, max_steps), record)
            _write_floats(results.f[c], t_stop, n_ev, n, record, case)
            out_i = results.i[c]
            out_i[I_STATUS], out_i[I_EVENTS] = status, n_ev
            for k in range(4):
                out_i[I_STEPS + k] = record.counters[k]
            out_i[I_FIRST] = first
            out_i[I_SWITCHES] = record.counters[segment.N_SWITCHES]
            _write_sequence(results.f[c], out_i, results.seq[c], first, n_ev, record.log)
