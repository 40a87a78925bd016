"""Integrate one segment of a hybrid trajectory: fixed mode, until t_end or an event.

``integrate_segment`` is compiled once, eagerly, with an explicit signature in
which the model functions are numba first-class function types (see
``signatures``), and cached on disk: every model in every process reuses it.
The method is chosen by a code (``DOPRI5`` explicit, ``ROSENBROCK23`` stiff);
both share the step loop, step-size control and event location below.

Per accepted step [t_a, t_b]: guards are sampled on the dense output and a
crossing is located on it (``events``); the state AT the event is then obtained
by re-taking a full-order step of length t_event - t_a from (t_a, y_a). If that
state is still on the pre-crossing side of the guard (the interpolant and the
step differ by about the local error), the same Illinois iteration is continued
on the re-taken steps, so the returned state is on the far side of (or on) the
switching surface: a restart cannot fire the same crossing again.

Conventions: forward integration (t_end >= t0); the last step is clipped to land
exactly on t_end; the mode never changes inside a segment (error estimators are
not valid across a switch, scipy issue 18039), the caller restarts after events.

Caching caveat: numba keys the on-disk cache of integrate_segment on the content
of this file only, while the cached code contains dopri5, rosenbrock and events.
After editing one of those, delete tswm_runtime/__pycache__/*.nb[ic] (or the
NUMBA_CACHE_DIR), otherwise the old code keeps running.
"""
import numpy as np
from numba import njit, types

from tswm_runtime import dopri5, events, rosenbrock
from tswm_runtime.signatures import (JAC_SIG, MATRIX, VECTOR, GuardsFunction,
                                     JacFunction, RhsFunction)

# Method codes.
DOPRI5 = 0  # Dormand-Prince 5(4), explicit (dopri5.py).
ROSENBROCK23 = 1  # Shampine-Reichelt ode23s Rosenbrock 2(3), stiff, uses jac (rosenbrock.py).

# Status codes returned by integrate_segment.
REACHED_END = 0  # Integrated up to t_end exactly.
EVENT = 1  # Stopped at the first event; t and y_stop are the event's.
STEP_TOO_SMALL = -1  # Rejected step sizes fell below max(hmin, 10 ulp(t)).
MAX_STEPS = -2  # max_steps step attempts (accepted + rejected) were made.
NOT_FINITE = -3  # Non-finite state, derivative, Jacobian or guard at an accepted point.
INVALID_INPUT = -4  # Unknown method, inconsistent array sizes, t_end < t0, ...

# Indices into the counters array (incremented, never reset, by integrate_segment).
N_STEPS = 0  # Accepted steps.
N_REJECTED = 1  # Rejected step attempts.
N_RHS = 2  # Calls of rhs.
N_JAC = 3  # Calls of jac.
N_COUNTERS = 4

MIN_STEP_ULPS = 10.0  # A step must exceed 10 ulp(t) to move t reliably (scipy's min_step).

_VEC_I64 = types.int64[::1]


@njit(JAC_SIG, cache=True)
def no_jacobian(mode, t, y, p, J, dfdt):
    """Placeholder ``jac`` for DOPRI5 runs (DOPRI5 never calls it); fills NaN."""
    J[:, :] = np.nan
    dfdt[:] = np.nan


@njit(cache=True, error_model="numpy")
def _all_finite(x):
    """True if no entry of x (any shape) is NaN or infinite."""
    for v in x.ravel():
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True, error_model="numpy")
def _eval_guards(guards, mode, t, y, p, g):
    """Guards into g (skipped when the model has none); True if all are finite."""
    if g.size > 0:
        guards(mode, t, y, p, g)
    return _all_finite(g)


@njit(cache=True, error_model="numpy")
def _controller(method):
    """(error order, safety, min factor, max factor) of the method's step control."""
    if method == DOPRI5:
        return dopri5.ERROR_ORDER, dopri5.SAFETY, dopri5.MIN_FACTOR, dopri5.MAX_FACTOR
    return rosenbrock.ERROR_ORDER, rosenbrock.SAFETY, rosenbrock.MIN_FACTOR, rosenbrock.MAX_FACTOR


@njit(cache=True, error_model="numpy")
def _stages(method, rhs, mode, t, y, p, h, f0, work, y_new, counters):
    """y_new = one step of size h from (t, y) with f0 = f(t, y); no error estimate."""
    K, _, J, dfdt, LU, piv = work
    if method == DOPRI5:
        K[0, :] = f0
        dopri5.stages(rhs, mode, t, y, p, h, K, y_new)
        counters[N_RHS] += dopri5.N_STAGES - 1
    else:
        rosenbrock.stages(rhs, mode, t, y, p, h, f0, J, dfdt, LU, piv, K, y_new)
        counters[N_RHS] += 1


@njit(cache=True, error_model="numpy")
def _error_norm(method, h, y, f0, y_new, f_new, work, err, atol, rtol):
    """Scaled RMS error of the step just staged (inf if anything is non-finite)."""
    K, _, _, dfdt, LU, piv = work
    if method == DOPRI5:
        K[dopri5.N_STAGES, :] = f_new
        dopri5.error_estimate(h, K, err)
    else:
        rosenbrock.error_estimate(h, f0, f_new, dfdt, LU, piv, K, err)
    e = dopri5.error_norm(err, y, y_new, atol, rtol)
    if np.isfinite(e) and _all_finite(y_new):
        return e
    return np.inf


@njit(cache=True, error_model="numpy")
def _dense(method, work):
    """Dense-output coefficients Q of the step just accepted."""
    K, Q = work[0], work[1]
    if method == DOPRI5:
        dopri5.dense_coeffs(K, Q)
    else:
        rosenbrock.dense_coeffs(K, Q)


@njit(cache=True, error_model="numpy")
def _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, t, work, y, g, counters):
    """y = state at t in [t_a, t_b] by a full step from t_a (exact at the ends); g = guards."""
    if t == t_b:
        y[:] = y_b
    elif t == t_a:
        y[:] = y_a
    else:
        _stages(method, rhs, mode, t_a, y_a, p, t - t_a, f_a, work, y, counters)
    _eval_guards(guards, mode, t, y, p, g)


@njit(cache=True, error_model="numpy")
def _event_state(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, k, t_star, j, G,
                 gtol, ttol, work, y_ev, y_tmp, g_tmp, counters):
    """Event time and state y_ev for guard k crossing at t_star (found on the dense output).

    The state comes from a re-taken step. If guard k is still on its old side there,
    Illinois continues on phi(t) = g_k(t, step(t_a, y_a, t - t_a)) between t_star and
    sample j (where the crossing was seen), keeping the far-side end.
    """
    post = G[j, k]
    _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, t_star, work, y_ev, g_tmp,
              counters)
    g_star = g_tmp[k]
    if g_star * post >= 0.0 or abs(g_star) <= gtol:
        return t_star
    t_hi = events.sample_time(t_a, t_b, j)
    _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, t_hi, work, y_tmp, g_tmp,
              counters)
    if g_tmp[k] * post <= 0.0:
        return t_star  # The re-taken steps show no crossing: keep the dense-output root.
    y_ev[:] = y_tmp
    state = events.bracket_start(t_star, g_star, t_hi, g_tmp[k])
    tol = events.time_tolerance(t_hi, ttol)
    while not events.bracket_done(state, tol):
        c = events.bracket_next(state, tol)
        _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, c, work, y_tmp, g_tmp,
                  counters)
        state = events.bracket_update(state, c, g_tmp[k])
        if state[2] == c:
            y_ev[:] = y_tmp
    return state[2]


@njit(cache=True, error_model="numpy")
def _write_samples(t_out, i, y_out, t_a, y_a, h, Q, t_hi, y_hi):
    """Rows y_out[i:] for the output times in (t_a, t_hi]; returns the next free index."""
    while i < t_out.size and t_out[i] <= t_hi:
        if t_out[i] == t_hi:
            y_out[i, :] = y_hi
        else:
            events.dense_eval(y_a, h, Q, (t_out[i] - t_a) / h, y_out[i])
        i += 1
    return i


@njit(cache=True, error_model="numpy")
def _valid(method, t0, y0, t_end, rtol, atol, hmax, max_steps, directions, t_out, i_out, y_out,
           y_stop, counters):
    """Argument checks that keep the unchecked array accesses below in bounds."""
    n = y0.size
    sizes = n > 0 and atol.size == n and y_stop.size == n and counters.size >= N_COUNTERS
    outputs = 0 <= i_out <= t_out.size and (t_out.size == 0 or (
        y_out.shape[0] >= t_out.size and y_out.shape[1] == n))
    numbers = t_end >= t0 and rtol > 0.0 and hmax > 0.0 and max_steps >= 0
    for a in atol:
        numbers = numbers and a >= 0.0
    for d in directions:
        numbers = numbers and -1 <= d <= 1
    return (method == DOPRI5 or method == ROSENBROCK23) and sizes and outputs and numbers


@njit(cache=True, error_model="numpy")
def _run(method, rhs, jac, guards, mode, p, t0, t_end, rtol, atol, h0, hmin, hmax, max_steps,
         directions, gtol, ttol, t_out, i, y_out, y, counters):
    """The step loop of integrate_segment; y is the current state (updated in place).

    Returns (status, t, event index, next output index, proposed next step).
    """
    n = y.size
    m = directions.size
    work = (np.empty((dopri5.N_STAGES + 1, n)), np.zeros((n, 4)), np.empty((n, n)),
            np.empty(n), np.empty((n, n)), np.empty(n, np.int64))
    Q, J, dfdt = work[1], work[2], work[3]
    f_a, y_b, f_b, err = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    y_ev, y_tmp = np.empty(n), np.empty(n)
    G = np.empty((events.GUARD_SUBINTERVALS + 1, m))
    g_b = G[events.GUARD_SUBINTERVALS]
    g_tmp, sgn, cand = np.empty(m), np.zeros(m, np.int64), np.zeros(m, np.bool_)
    t = t0
    if t_end == t0:
        return REACHED_END, t, -1, i, h0
    rhs(mode, t, y, p, f_a)
    counters[N_RHS] += 1
    if not (_eval_guards(guards, mode, t, y, p, G[0]) and _all_finite(y) and _all_finite(f_a)):
        return NOT_FINITE, t, -1, i, h0
    events.arm_guards(G[0], gtol, sgn)
    order, safety, min_factor, max_factor = _controller(method)
    h_prop = h0
    if h_prop <= 0.0:
        h_prop = dopri5.select_initial_step(rhs, mode, t, y, p, f_a, t_end, hmax, order, rtol,
                                            atol, y_b, f_b)
        counters[N_RHS] += 1
    rejected = False
    jac_current = False
    for _ in range(max_steps):
        if method == ROSENBROCK23 and not jac_current:
            jac(mode, t, y, p, J, dfdt)
            counters[N_JAC] += 1
            jac_current = True
            if not (_all_finite(J) and _all_finite(dfdt)):
                return NOT_FINITE, t, -1, i, h_prop
        h_want = min(h_prop, hmax)
        h = h_want
        t_new = t + h
        if t_new >= t_end:
            t_new = t_end
            h = t_end - t
        _stages(method, rhs, mode, t, y, p, h, f_a, work, y_b, counters)
        rhs(mode, t_new, y_b, p, f_b)
        counters[N_RHS] += 1
        e = _error_norm(method, h, y, f_a, y_b, f_b, work, err, atol, rtol)
        factor = dopri5.step_factor(e, order, safety, min_factor, max_factor)
        if not e < 1.0:
            counters[N_REJECTED] += 1
            rejected = True
            h_prop = h * factor
            if h_prop < max(hmin, MIN_STEP_ULPS * (np.nextafter(t, np.inf) - t)):
                return STEP_TOO_SMALL, t, -1, i, h_prop
            continue
        counters[N_STEPS] += 1
        if rejected:
            factor = min(1.0, factor)
        # A step clipped to land on t_end says nothing against the step wanted.
        h_prop = max(h * factor, h_want) if h < h_want else h * factor
        _dense(method, work)
        if not _eval_guards(guards, mode, t_new, y_b, p, g_b):
            return NOT_FINITE, t, -1, i, h_prop
        if m > 0:
            k, t_star, j = events.find_event(guards, mode, p, t, y, h, t_new, Q, G, directions,
                                             gtol, ttol, sgn, t_new == t_end, cand, y_tmp, g_tmp)
            if k >= 0:
                t_ev = _event_state(method, rhs, guards, mode, p, t, y, f_a, t_new, y_b, k,
                                    t_star, j, G, gtol, ttol, work, y_ev, y_tmp, g_tmp, counters)
                i = _write_samples(t_out, i, y_out, t, y, h, Q, t_ev, y_ev)
                y[:] = y_ev
                return EVENT, t_ev, k, i, h_prop
        i = _write_samples(t_out, i, y_out, t, y, h, Q, t_new, y_b)
        t = t_new
        y[:] = y_b
        f_a[:] = f_b
        G[0, :] = g_b
        rejected = False
        jac_current = False
        if t == t_end:
            return REACHED_END, t, -1, i, h_prop
    return MAX_STEPS, t, -1, i, h_prop


SEGMENT_SIG = types.Tuple((types.int64, types.float64, types.int64, types.int64, types.float64))(
    types.int64,  # method
    RhsFunction, JacFunction, GuardsFunction,
    types.int64,  # mode
    VECTOR,  # p
    types.float64, VECTOR, types.float64,  # t0, y0, t_end
    types.float64, VECTOR,  # rtol, atol
    types.float64, types.float64, types.float64, types.int64,  # h0, hmin, hmax, max_steps
    _VEC_I64, types.float64, types.float64,  # directions, gtol, ttol
    VECTOR, types.int64, MATRIX,  # t_out, i_out, y_out
    VECTOR, _VEC_I64,  # y_stop, counters
)


@njit(SEGMENT_SIG, cache=True, error_model="numpy")
def integrate_segment(method, rhs, jac, guards, mode, p, t0, y0, t_end, rtol, atol, h0, hmin,
                      hmax, max_steps, directions, gtol, ttol, t_out, i_out, y_out, y_stop,
                      counters):
    """Integrate y' = rhs(mode, t, y, p) from (t0, y0) to t_end or the first event.

    method: DOPRI5 or ROSENBROCK23 (the latter calls jac once per accepted step;
        DOPRI5 runs may pass ``no_jacobian``).
    rhs, jac, guards: the model, compiled with the signatures in ``signatures``.
    mode, p: discrete mode and parameter vector, passed through to the model.
    t0, y0, t_end: start and end (t_end >= t0); y0 is not modified.
    rtol, atol: local error tolerances, scalar rtol and one atol per component.
    h0: first trial step, e.g. the h returned by the previous segment; <= 0 selects
        it automatically (Hairer). hmin: smallest step allowed after a rejection.
        hmax: largest step (np.inf for none). max_steps: bound on step attempts.
    directions: one entry per guard (its size is the number of guards):
        +1 rising, -1 falling, 0 both. gtol: guards with |g| <= gtol count as zero
        (no sign): a guard zero at t0 is disarmed until it leaves zero. ttol: extra
        relative time tolerance of event location (0 gives 4 eps).
    t_out, i_out, y_out: sorted output times; rows y_out[i_out:] are filled for the
        times t_out[i_out:] in [t0, t_stop] (t_out[i_out] >= t0 is assumed), from the
        dense output; a time equal to t_stop gets exactly y_stop.
    y_stop: receives the state at the returned time. counters: int64[4], incremented
        (N_STEPS, N_REJECTED, N_RHS, N_JAC).

    Returns (status, t_stop, event guard index or -1, number of output rows written,
    proposed next step size for a warm restart). status: REACHED_END, EVENT,
    STEP_TOO_SMALL, MAX_STEPS, NOT_FINITE or INVALID_INPUT (t_stop is then the last
    accepted time and y_stop its state).
    """
    if not _valid(method, t0, y0, t_end, rtol, atol, hmax, max_steps, directions, t_out, i_out,
                  y_out, y_stop, counters):
        return INVALID_INPUT, t0, -1, 0, h0
    y_stop[:] = y0
    i = i_out
    while i < t_out.size and t_out[i] <= t0:
        y_out[i, :] = y0
        i += 1
    status, t, k, i, h_next = _run(method, rhs, jac, guards, mode, p, t0, t_end, rtol, atol, h0,
                                   hmin, hmax, max_steps, directions, gtol, ttol, t_out, i, y_out,
                                   y_stop, counters)
    return status, t, k, i - i_out, h_next
