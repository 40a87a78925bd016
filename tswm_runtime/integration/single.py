"""One segment integrated from Python: the step loop ``segment.run`` behind an explicit,
cached signature, for tests and tools.

Kept apart from ``segment`` so that the runtime's import path (``hybrid.machine``) does not
compile it: an eagerly compiled entry point costs seconds on a cold numba cache.
"""
import numpy as np
from numba import types

from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.integration.steplog import no_steps
from tswm_runtime.integration.segment import (DOPRI5, INVALID_INPUT, N_COUNTERS, RODAS4, ROSENBROCK23, AttemptFunction,
                                              run, segment_work)
from tswm_runtime.jit.signatures import MATRIX, VECTOR, GuardsFunction, JacFunction, RhsFunction
from tswm_runtime.jit.structures import (EVENT_SETTINGS, INDEX_WIDTH, JUMP_WIDTH, TOLERANCES, EventLog, Functions,
                                         Outputs, Record, Segment, Settings, State)

_VEC_I64 = types.int64[::1]


@njit(error_model="numpy")
def _valid(method, t0, y0, t_end, tol, max_steps, ev, out, i_out, y_stop, counters):
    """Argument checks that keep the unchecked array accesses below in bounds."""
    n = y0.size
    sizes = n > 0 and tol.atol.size == n and y_stop.size == n and counters.size >= N_COUNTERS
    outputs = 0 <= i_out <= out.t.size and (out.t.size == 0 or (
        out.y.shape[0] >= out.t.size and out.y.shape[1] == n))
    numbers = t_end >= t0 and tol.rtol > 0.0 and tol.hmax > 0.0 and max_steps >= 0
    for a in tol.atol:
        numbers = numbers and a >= 0.0
    for d in ev.directions:
        numbers = numbers and -1 <= d <= 1
    return (method == DOPRI5 or method == ROSENBROCK23 or method == RODAS4) and sizes and outputs and numbers



SEGMENT_SIG = types.Tuple((types.int64, types.float64, types.int64, types.int64, types.float64))(
    types.int64, AttemptFunction,  # method, attempt
    RhsFunction, JacFunction, GuardsFunction,
    types.int64, VECTOR,  # mode, p
    types.float64, VECTOR, types.float64,  # t0, y0, t_end
    TOLERANCES, types.int64, types.float64,  # tol, max_steps, h0
    EVENT_SETTINGS,  # ev
    VECTOR, types.int64, MATRIX,  # t_out, i_out, y_out
    VECTOR, _VEC_I64,  # y_stop, counters
)


@cache_guard.compile_cached(SEGMENT_SIG, error_model="numpy")
def integrate_segment(method, attempt, rhs, jac, guards, mode, p, t0, y0, t_end, tol, max_steps, h0, ev, t_out,
                      i_out, y_out, y_stop, counters):
    """Integrate y' = rhs(mode, t, y, p) from (t0, y0) to t_end or the first event.

    method: DOPRI5, ROSENBROCK23 or RODAS4 (the stiff two call jac once per accepted step;
        DOPRI5 runs may pass ``no_jacobian``); attempt: its step, ``attempt_function(method)``.
    rhs, jac, guards: the model, compiled with the signatures in ``signatures``.
    mode, p: discrete mode and parameter vector, passed through to the model.
    t0, y0, t_end: start and end (t_end >= t0); y0 is not modified.
    tol: Tolerances(rtol, atol per component, hmin: smallest step after a rejection,
        hmax: largest step, np.inf for none). max_steps: bound on step attempts.
    h0: first trial step, e.g. the h returned by the previous segment; <= 0 selects
        it automatically (Hairer).
    ev: EventSettings: directions, one entry per guard (its size is the number of
        guards): +1 rising, -1 falling, 0 both; gtol: guards with |g| <= gtol count as
        zero (no sign): a guard zero at t0 is disarmed until it leaves zero; ttol: extra
        relative time tolerance of event location (0 gives 4 eps); noise_band; singular.
    t_out, i_out, y_out: sorted output times; rows y_out[i_out:] are filled for the
        times t_out[i_out:] in [t0, t_stop] (t_out[i_out] >= t0 is assumed), from the
        dense output; a time equal to t_stop gets exactly y_stop.
    y_stop: receives the state at the returned time. counters: int64[N_COUNTERS], incremented
        (N_STEPS, N_REJECTED, N_RHS, N_JAC).

    Returns (status, t_stop, event guard index or -1, number of output rows written,
    proposed next step size for a warm restart). status: REACHED_END, EVENT,
    STEP_TOO_SMALL, MAX_STEPS, NOT_FINITE or INVALID_INPUT (t_stop is then the last
    accepted time and y_stop its state).
    """
    out = Outputs(t_out, y_out, np.empty(0, np.int64), np.empty((0, 0)))
    if not _valid(method, t0, y0, t_end, tol, max_steps, ev, out, i_out, y_stop, counters):
        return INVALID_INPUT, t0, -1, 0, h0
    copy_into(y_stop, y0)
    i = i_out
    while i < t_out.size and t_out[i] <= t0:
        copy_into(y_out[i], y0)
        i += 1
    scratch = segment_work(y0.size, ev.directions.size, 0, 0)
    log = EventLog(np.empty(0), np.empty((0, INDEX_WIDTH), np.int64), np.empty((0, 0)), np.empty((0, JUMP_WIDTH)))
    status, t, k, i, h_next = run(Functions(attempt, rhs, jac, guards, guards, guards, attempt),
                                  Settings(method, t_end, tol, max_steps), Segment(mode, p, ev),
                                  State(t0, y_stop, np.empty(0), h0),
                                  Record(out, log, np.empty((0, 3)), counters, no_steps(y0.size, p.size)), i, scratch)
    return status, t, k, i - i_out, h_next

