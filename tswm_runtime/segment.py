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

``integrate_segment`` is the single-segment entry point (no noise band, no
quadrature, no monitored observables); the hybrid driver (``hybrid``) calls the
step loop ``_run`` with all three.
"""
import numpy as np
from numba import njit, types

from tswm_runtime import cache_guard, dopri5, events, painleve, rosenbrock
from tswm_runtime.signatures import (JAC_SIG, MATRIX, VECTOR, GuardsFunction,
                                     JacFunction, RhsFunction)

# Method codes.
DOPRI5 = 0  # Dormand-Prince 5(4), explicit (dopri5.py).
ROSENBROCK23 = 1  # Shampine-Reichelt ode23s Rosenbrock 2(3), stiff, uses jac (rosenbrock.py).

# Status codes returned by integrate_segment.
REACHED_END = 0  # Integrated up to t_end exactly.
EVENT = 1  # Stopped at the first event; t and y_stop are the event's.
APPROACH = 2  # The singular guard (D) heads for zero: hand over to painleve.approach at t.
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
    """(event time, True) and state y_ev for guard k crossing at t_star (found on the
    dense output); (t_star, False) if the re-taken steps show no crossing (the
    interpolant's error made it: no event).

    The root is refined on the re-taken steps, phi(t) = g_k(t, step(t_a, y_a, t - t_a)),
    whose error is the step's local error, not the interpolant's: Illinois between a
    pre- and a post-crossing point, keeping the far-side end (and its state in y_ev).
    The first bracket is tight about t_star: [t_star - w, t_star] or [t_star, t_star
    + w] with w 1e-3 of the step, widened to [t_a, .] or [., sample j] if needed.
    """
    post = G[j, k]
    _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, t_star, work, y_ev, g_tmp,
              counters)
    g_star = g_tmp[k]
    t_far = events.sample_time(t_a, t_b, j)
    if (g_star != 0.0 and abs(g_star) <= gtol) or (g_star == 0.0 and t_star >= t_far):
        return t_star, True  # within gtol, or a zero at the segment end (nothing lies beyond)
    far = g_star * post > 0.0
    w = 1e-3 * (t_b - t_a)
    t_probe = max(t_star - w, t_a) if far else min(t_star + w, t_far)
    _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, t_probe, work, y_tmp, g_tmp,
              counters)
    g_probe = g_tmp[k]
    if (g_probe * post > 0.0) == far:  # the probe is on the same side: widen to the ends
        t_probe = t_a if far else t_far
        _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, t_probe, work, y_tmp,
                  g_tmp, counters)
        g_probe = g_tmp[k]
        if (g_probe * post > 0.0) == far:
            if far:  # already across at t_a (it crossed inside the noise band): report t_a
                y_ev[:] = y_tmp
                return t_probe, True
            return t_star, False
    if far:
        state = events.bracket_start(t_probe, g_probe, t_star, g_star)
    else:
        y_ev[:] = y_tmp
        state = events.bracket_start(t_star, g_star, t_probe, g_probe)
    tol = events.time_tolerance(state[2], ttol)
    while not events.bracket_done(state, tol):
        c = events.bracket_next(state, tol)
        _state_at(method, rhs, guards, mode, p, t_a, y_a, f_a, t_b, y_b, c, work, y_tmp, g_tmp,
                  counters)
        state = events.bracket_update(state, c, g_tmp[k])
        if state[2] == c:
            y_ev[:] = y_tmp
    return state[2], True


@njit(cache=True, error_model="numpy")
def _write_samples(t_out, i, y_out, t_a, y_a, h, Q, t_hi, y_hi, quad, q_tmp):
    """Rows y_out[i:] for the output times in (t_a, t_hi]; returns the next free index.

    With quadrature (quad.size = n), columns n: of a row get quad (the integral up
    to t_a) plus the integral of the dense output from t_a to the row's time.
    """
    n = y_a.size
    while i < t_out.size and t_out[i] <= t_hi:
        theta = (t_out[i] - t_a) / h
        if t_out[i] == t_hi:
            y_out[i, :n] = y_hi
        else:
            events.dense_eval(y_a, h, Q, theta, y_out[i, :n])
        if quad.size > 0:
            events.dense_integral(y_a, h, Q, theta, q_tmp)
            y_out[i, n:] = quad + q_tmp
        i += 1
    return i


@njit(cache=True, error_model="numpy")
def _monitor(observe, mode, t, y, p, mon, obs, t_a, h, y_a, Q, t_hi, win_f, win_y, win_Q, win_s):
    """Track max |observable k| at (t, y) in mon[k] = (|value|, value, t).

    A new maximum at the end of the step [t_a, t_hi] (h > 0) remembers that step's
    dense output in slot 0 of the refinement window, and the following step in slot
    1: the true maximum lies in one of the two (``_refine``).
    """
    observe(mode, t, y, p, obs)
    for k in range(mon.shape[0]):
        if abs(obs[k]) > mon[k, 0]:
            mon[k, 0], mon[k, 1], mon[k, 2] = abs(obs[k]), obs[k], t
            slot, win_s[k] = 0, (1 if h > 0.0 else 0)
        elif win_s[k] == 1:
            slot, win_s[k] = 1, 2
        else:
            continue
        if h > 0.0:
            win_f[k, slot, 0], win_f[k, slot, 1], win_f[k, slot, 2] = t_a, h, t_hi
            win_y[k, slot] = y_a
            win_Q[k, slot] = Q


REFINE_ITERATIONS = 40  # Golden-section steps: the window shrinks by 0.618^40 = 4e-9.


@njit(cache=True, error_model="numpy")
def _window_value(observe, mode, p, k, t, win_f, win_y, win_Q, win_s, y_tmp, obs):
    """Observable k at t, from the window slot whose step contains t."""
    slot = 0 if (t <= win_f[k, 0, 2] or win_s[k] < 2) else 1
    t_a, h = win_f[k, slot, 0], win_f[k, slot, 1]
    events.dense_eval(win_y[k, slot], h, win_Q[k, slot], (t - t_a) / h, y_tmp)
    observe(mode, t, y_tmp, p, obs)
    return obs[k]


@njit(cache=True, error_model="numpy")
def _refine(observe, mode, p, mon, obs, win_f, win_y, win_Q, win_s, y_tmp):
    """Golden-section search of max |observable| on each pending window; resets them."""
    r = 0.5 * (np.sqrt(5.0) - 1.0)
    for k in range(mon.shape[0]):
        if win_s[k] == 0:
            continue
        lo, hi = win_f[k, 0, 0], win_f[k, win_s[k] - 1, 2]
        c, d = hi - r * (hi - lo), lo + r * (hi - lo)
        fc = abs(_window_value(observe, mode, p, k, c, win_f, win_y, win_Q, win_s, y_tmp, obs))
        fd = abs(_window_value(observe, mode, p, k, d, win_f, win_y, win_Q, win_s, y_tmp, obs))
        for _ in range(REFINE_ITERATIONS):
            if fc >= fd:
                hi, d, fd = d, c, fc
                c = hi - r * (hi - lo)
                fc = abs(_window_value(observe, mode, p, k, c, win_f, win_y, win_Q, win_s, y_tmp, obs))
            else:
                lo, c, fc = c, d, fd
                d = lo + r * (hi - lo)
                fd = abs(_window_value(observe, mode, p, k, d, win_f, win_y, win_Q, win_s, y_tmp, obs))
        t_best = c if fc >= fd else d
        value = _window_value(observe, mode, p, k, t_best, win_f, win_y, win_Q, win_s, y_tmp, obs)
        if abs(value) > mon[k, 0]:
            mon[k, 0], mon[k, 1], mon[k, 2] = abs(value), value, t_best
        win_s[k] = 0


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
def _run(method, rhs, jac, guards, observe, mode, p, t0, t_end, rtol, atol, h0, hmin, hmax,
         max_steps, directions, gtol, band, ttol, t_out, i, y_out, y, quad, mon, counters,
         k_singular):
    """The step loop of integrate_segment; y is the current state (updated in place).

    observe and mon: observables tracked for their maxima (mon.shape[0] of them,
    none if 0); quad: the integral of y, carried along if quad.size == y.size.
    k_singular: a guard (D) whose zero the model cannot be integrated to in t; the
    loop stops with APPROACH after a step that takes it towards 0 fast (-1: none).
    Returns (status, t, event index, next output index, proposed next step).
    """
    n = y.size
    m = directions.size
    work = (np.empty((dopri5.N_STAGES + 1, n)), np.zeros((n, 4)), np.empty((n, n)),
            np.empty(n), np.empty((n, n)), np.empty(n, np.int64))
    Q, J, dfdt = work[1], work[2], work[3]
    f_a, y_b, f_b, err = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    y_ev, y_tmp, y_pert, q_tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(quad.size)
    G = np.empty((events.GUARD_SUBINTERVALS + 1, m))
    g_b = G[events.GUARD_SUBINTERVALS]
    g_tmp, sgn, cand = np.empty(m), np.zeros(m, np.int64), np.zeros(m, np.bool_)
    ignore = np.zeros(m, np.bool_)
    n_mon = mon.shape[0]
    obs = np.empty(n_mon)
    win_f, win_y = np.zeros((n_mon, 2, 3)), np.zeros((n_mon, 2, n))
    win_Q, win_s = np.zeros((n_mon, 2, n, 4)), np.zeros(n_mon, np.int64)
    t = t0
    if n_mon > 0:
        _monitor(observe, mode, t, y, p, mon, obs, t, 0.0, y, Q, t, win_f, win_y, win_Q, win_s)
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
    status, k = MAX_STEPS, -1
    for _ in range(max_steps):
        if method == ROSENBROCK23 and not jac_current:
            jac(mode, t, y, p, J, dfdt)
            counters[N_JAC] += 1
            jac_current = True
            if not (_all_finite(J) and _all_finite(dfdt)):
                status = NOT_FINITE
                break
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
                status = STEP_TOO_SMALL
                break
            continue
        if k_singular >= 0:  # no step in t may change D by more than a factor 2: it could jump its zero
            _eval_guards(guards, mode, t_new, y_b, p, g_b)
            if painleve.too_steep(G[0, k_singular], g_b[k_singular]):
                counters[N_REJECTED] += 1
                rejected = True
                h_prop = 0.5 * h
                if h_prop < max(hmin, MIN_STEP_ULPS * (np.nextafter(t, np.inf) - t)):
                    status = STEP_TOO_SMALL
                    break
                continue
        counters[N_STEPS] += 1
        if rejected:
            factor = min(1.0, factor)
        # A step clipped to land on t_end says nothing against the step wanted.
        h_prop = max(h * factor, h_want) if h < h_want else h * factor
        _dense(method, work)
        if not _eval_guards(guards, mode, t_new, y_b, p, g_b):
            status = NOT_FINITE
            break
        k, j = -1, 1
        ignore[:] = False
        for _ in range(m):  # each pass finds an event or ignores one more guard
            k, t_star, j = events.find_event(guards, mode, p, t, y, h, t_new, y_b, Q, G,
                                             directions, gtol, band, atol, rtol, ttol, sgn,
                                             t_new == t_end, cand, y_tmp, g_tmp, y_pert, j, ignore)
            if k < 0:
                break
            t_ev, real = _event_state(method, rhs, guards, mode, p, t, y, f_a, t_new, y_b, k,
                                      t_star, j, G, gtol, ttol, work, y_ev, y_tmp, g_tmp, counters)
            if real:
                t_new = t_ev
                y_b[:] = y_ev
                break
            ignore[k] = True  # an artefact of the interpolant: look on from sample j
            k = -1
        i = _write_samples(t_out, i, y_out, t, y, h, Q, t_new, y_b, quad, q_tmp)
        if quad.size > 0:
            events.dense_integral(y, h, Q, (t_new - t) / h, q_tmp)
            quad += q_tmp
        if n_mon > 0:
            _monitor(observe, mode, t_new, y_b, p, mon, obs, t, h, y, Q, t_new, win_f, win_y,
                     win_Q, win_s)
        t = t_new
        y[:] = y_b
        if k >= 0:
            status = EVENT
            break
        if (k_singular >= 0 and t < t_end
                and painleve.heading_for_zero(G[0, k_singular], g_b[k_singular])):
            status = APPROACH
            break
        f_a[:] = f_b
        G[0, :] = g_b
        rejected = False
        jac_current = False
        if t == t_end:
            status = REACHED_END
            break
    if n_mon > 0:
        _refine(observe, mode, p, mon, obs, win_f, win_y, win_Q, win_s, y_tmp)
    return status, t, k, i, h_prop


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


@cache_guard.compile_cached(SEGMENT_SIG, error_model="numpy")
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
    status, t, k, i, h_next = _run(method, rhs, jac, guards, guards, mode, p, t0, t_end, rtol,
                                   atol, h0, hmin, hmax, max_steps, directions, gtol, False, ttol,
                                   t_out, i, y_out, y_stop, np.empty(0), np.empty((0, 3)),
                                   counters, -1)
    return status, t, k, i - i_out, h_next
