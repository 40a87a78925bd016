"""Many runs of one model in one numba call, in parallel over the cores.

``run_batch`` integrates case after case (one row of parameters each) with
``hybrid.integrate_hybrid``, in a ``prange`` loop: every case has its own work
arrays (parameter copy, event log, monitor, counters), one output point (t_end),
and writes one row of results. The model functions are numba first-class
function arguments (``signatures``), so, like ``integrate_hybrid``, the batch
function is compiled once with an explicit signature, cached on disk and reused
for every model (numba's ``parallel=True`` accepts function-typed arguments: the
prange body is outlined into a gufunc that takes the function pointers as
arguments). Calling ``integrate_hybrid`` from Python costs about 20 us per call for
unboxing its arguments (a run to t_end = 1e-9 s through its entry point, session 7);
inside this loop a case costs only its integration. ``integrate_hybrid`` itself is such an argument (``INTEGRATE``): called
through its address, its compiled code is not linked into this kernel, whose cold
compile then skips re-optimizing the whole mode machine (issue 13: 24 s of 72).

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
import numpy as np
from numba import prange, types

from tswm_runtime.hybrid import machine as hybrid

from tswm_runtime.jit import cache_guard
from tswm_runtime.integration import segment
from tswm_runtime.jit.signatures import MATRIX, VECTOR, GuardsFunction, JacFunction, RhsFunction, compiled
from tswm_runtime.jit.structures import JUMP_WIDTH, MODE_TABLES, TOLERANCES, EventLog, Outputs

F_T_STOP, F_S1M, F_TS1M, F_S2M, F_TS2M, F_X1, F_V1, F_IMPACT_E = range(8)
N_F = 8
I_STATUS, I_EVENTS, I_STEPS, I_REJECTED, I_RHS, I_JAC, I_FIRST, I_NMODES, I_IMPACTS = range(9)
N_I = 9

#: hybrid.integrate_hybrid as the first-class function value run_batch takes.
INTEGRATE = compiled(hybrid.integrate_hybrid, hybrid.HYBRID_SIG)

BATCH_SIG = types.none(
    types.FunctionType(hybrid.HYBRID_SIG),  # integrate: INTEGRATE
    types.int64, segment.AttemptFunction,  # method, attempt: segment.attempt_function(method)
    RhsFunction, JacFunction, GuardsFunction, GuardsFunction, GuardsFunction,  # rhs, jac, guards, observe, impact
    MATRIX, MODE_TABLES,  # P (cases x parameters, latches included), mode tables
    VECTOR, VECTOR, types.float64,  # y0, quad, t_end
    TOLERANCES, types.int64, types.int64,  # tol, max_steps, max_events
    types.int64,  # number of observables
    MATRIX, types.int64[:, ::1], types.int64[:, ::1],  # out_f, out_i, seq
)


@cache_guard.compile_cached(BATCH_SIG, parallel=True, error_model="numpy")
def run_batch(integrate, method, attempt, rhs, jac, guards, observe, impact, P, tables, y0, quad, t_end, tol, max_steps,
              max_events, n_obs, out_f, out_i, seq):
    """Integrate every row of P from (0, y0) to t_end; results into out_f, out_i, seq."""
    n = y0.size
    width = n + quad.size
    n_seq = seq.shape[1]
    for c in prange(P.shape[0]):
        p = P[c].copy()
        out = Outputs(np.full(1, t_end), np.full((1, width), np.nan), np.empty(1, np.int64),
                      np.empty((1, p.size)))  # one output point: the state at t_end
        log = EventLog(np.empty(max_events), np.empty((max_events, 3), np.int64), np.empty((max_events, width)),
                       np.zeros((max_events, JUMP_WIDTH)))
        mon = np.zeros((n_obs, 3))
        counters = np.zeros(segment.N_COUNTERS, np.int64)
        status, t_stop, n_ev, last, need, first = integrate(
            method, attempt, rhs, jac, guards, observe, impact, p, tables, 0.0, y0, quad, -1, t_end, tol, max_steps,
            out, log, mon, counters)
        out_f[c, F_T_STOP] = t_stop
        # The state at t_stop: the output point at t_end, else the last event's state
        # if the run stopped at it, else unknown (NaN).
        ys = out.y[0]
        if out.mode[0] < 0:
            ys = np.full(width, np.nan)
            if n_ev > 0 and log.t[n_ev - 1] == t_stop:
                ys = log.state[n_ev - 1].copy()
        out_f[c, F_X1] = ys[n] if n == 1 else ys[0]
        out_f[c, F_V1] = ys[n - 1]
        if n_obs > 0:
            out_f[c, F_S1M], out_f[c, F_TS1M] = mon[0, 1], mon[0, 2]
        else:
            out_f[c, F_S1M], out_f[c, F_TS1M] = np.nan, np.nan
        if n_obs > 1:
            out_f[c, F_S2M], out_f[c, F_TS2M] = mon[1, 1], mon[1, 2]
        else:
            out_f[c, F_S2M], out_f[c, F_TS2M] = np.nan, np.nan
        out_i[c, I_STATUS], out_i[c, I_EVENTS] = status, n_ev
        for k in range(4):
            out_i[c, I_STEPS + k] = counters[k]
        out_i[c, I_FIRST] = first
        n_modes = 0
        prev = -1
        if first >= 0:
            if n_seq > 0:
                seq[c, 0] = first
            n_modes, prev = 1, first
        impacts, lost = 0, 0.0
        for e in range(n_ev):
            to = log.index[e, 2]
            if to >= 0 and to != prev:
                if n_modes < n_seq:
                    seq[c, n_modes] = to
                n_modes += 1
                prev = to
            if not np.isnan(log.jump[e, 0]):  # an impact (the log's jump is NaN for other events)
                impacts += 1
                lost += log.jump[e, 2]
        out_i[c, I_NMODES] = n_modes
        out_i[c, I_IMPACTS], out_f[c, F_IMPACT_E] = impacts, lost
