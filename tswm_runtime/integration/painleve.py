"""The Painleve approach: follow D -> 0+ in a time that stays regular there.

In a sliding mode a1 = N / D. Where D (the mode's denominator, its guard ``D``)
falls to 0 with N != 0, a1 grows without bound and the state reaches D = 0 in
finite time like a square root, v - v* ~ sqrt(t* - t): no step in t can resolve
it, and an explicit method either stalls (step-too-small) or steps across into
D < 0. With Sundman's transformation dt/dsigma = D the system

    dt/dsigma = D,   dy/dsigma = D f(t, y),   dq/dsigma = D y   (q = integral of y)

has bounded, smooth right-hand sides through D = 0 (D f = N stays finite), so
D = 0 is an ordinary zero crossing in sigma, located here like any event.
``approach`` runs DOPRI5 on the augmented state z = (t, y, q) from the state
where the segment loop saw D heading for zero, until

* D reaches 0 (ZERO): the Painleve point, located to the time tolerance;
* t reaches t_end (END);
* another guard of the mode changes sign first (OTHER): the state at the start
  of that step is returned, and the caller locates that event in t;
* D stops heading for 0: it would not reach 0 within CLEAR_STEPS steps at its
  present rate (CLEAR): the caller goes on in t.

Output rows inside the approach are filled by solving t(sigma) = t_out on
re-taken steps; the observables' running maxima are updated at step ends.
"""
import numpy as np
from tswm_runtime.jit.cache_guard import njit

from tswm_runtime.integration import control
from tswm_runtime.integration import dopri5
from tswm_runtime.integration import events

ZERO, END, OTHER, CLEAR = 0, 1, 2, 3  # outcomes besides the integrator's failure codes
TRIGGER_STEPS = 4.0  # The segment loop hands over when D would reach 0 within this many steps,
CLEAR_STEPS = 8.0  # and gets it back when it would not within this many (or D grows).
MAX_CHANGE = 2.0  # A step in t may change D by at most this factor, either way.


@njit(cache=True, error_model="numpy")
def heading_for_zero(d_start, d_end):
    """True when a step took D from d_start down to d_end > 0 at a rate that reaches 0
    within TRIGGER_STEPS more steps of the same length."""
    return 0.0 < d_end < d_start and d_end <= TRIGGER_STEPS * (d_start - d_end)


@njit(cache=True, error_model="numpy")
def too_steep(d_start, d_end):
    """True when a step in t changed D (> 0 at its start) by more than MAX_CHANGE either
    way: a step that long may have jumped across D = 0 (its stages beyond the zero, where
    a1 changes sign, and its error estimate blind to it), so the loop rejects it."""
    return not d_start / MAX_CHANGE < d_end < MAX_CHANGE * d_start


@njit(cache=True, error_model="numpy")
def _rate(rhs, guards, mode, p, k_d, n, z, g, y, f, dz):
    """dz = d(t, y, q)/dsigma at z; returns D."""
    y[:] = z[1:1 + n]
    guards(mode, z[0], y, p, g)
    d = g[k_d]
    rhs(mode, z[0], y, p, f)
    dz[0] = d
    for i in range(n):
        dz[1 + i] = d * f[i]
    for i in range(z.size - 1 - n):
        dz[1 + n + i] = d * y[i]
    return d


@njit(cache=True, error_model="numpy")
def _step(rhs, guards, mode, p, k_d, n, z, h, K, z_new, g, y, f):
    """One DOPRI5 step of size h in sigma from z (K[0] = rate at z on entry); fills K[6]."""
    m = z.size
    for s in range(1, dopri5.N_STAGES):
        for i in range(m):
            acc = 0.0
            for j in range(s):
                acc += dopri5.A[s, j] * K[j, i]
            z_new[i] = z[i] + h * acc
        _rate(rhs, guards, mode, p, k_d, n, z_new, g, y, f, K[s])
    for i in range(m):
        acc = 0.0
        for j in range(dopri5.N_STAGES):
            acc += dopri5.B[j] * K[j, i]
        z_new[i] = z[i] + h * acc
    return _rate(rhs, guards, mode, p, k_d, n, z_new, g, y, f, K[dopri5.N_STAGES])


@njit(cache=True, error_model="numpy")
def _retake(rhs, guards, mode, p, k_d, n, z, K0, h, K, z_out, g, y, f):
    """z_out = a full step of length h from z (K0: the rate at z); returns D there."""
    K[0, :] = K0
    return _step(rhs, guards, mode, p, k_d, n, z, h, K, z_out, g, y, f)


@njit(cache=True, error_model="numpy")
def _root(rhs, guards, mode, p, k_d, n, z, K0, h, K, z_out, g, y, f, which, target, tol, far):
    """sigma in (0, h] where component ``which`` of the re-taken step (D for which < 0)
    reaches ``target``, by Illinois; z_out holds the state on the far side of it (far)
    or on the near side. Returns that sigma."""
    f_a = (K0[0] if which < 0 else z[which]) - target
    d_b = _retake(rhs, guards, mode, p, k_d, n, z, K0, h, K, z_out, g, y, f)
    state = events.bracket_start(0.0, f_a, h, (d_b if which < 0 else z_out[which]) - target)
    z_far, z_near = z_out.copy(), z.copy()
    while not events.bracket_done(state, tol):
        c = events.bracket_next(state, tol)
        d_c = _retake(rhs, guards, mode, p, k_d, n, z, K0, c, K, z_out, g, y, f)
        state = events.bracket_update(state, c, (d_c if which < 0 else z_out[which]) - target)
        if state[2] == c:
            z_far[:] = z_out
        else:
            z_near[:] = z_out
    z_out[:] = z_far if far else z_near
    return state[2] if far else state[0]


@njit(cache=True, error_model="numpy")
def approach(rhs, guards, observe, mode, p, ev, t, y_io, q_io, t_end, h_t, tol, max_steps, out, i,
             mon, counters):
    """Follow the mode from (t, y_io, q_io) in Sundman time; see the module docstring.

    ev: the segment's EventSettings (ev.singular is D's guard); tol: Tolerances; h_t:
    the last step in t; out: Outputs, rows from i on. y_io, q_io are updated to the
    returned state. Returns (outcome, t, next output row): outcome ZERO, END, OTHER,
    CLEAR or -1 (step too small), -2 (max steps) as the segment's codes.
    """
    k_d, directions, rtol, atol = ev.singular, ev.directions, tol.rtol, tol.atol
    t_out, y_out = out.t, out.y
    n, nq = y_io.size, q_io.size
    m = 1 + n + nq
    z, z_new, z_tmp, err = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    K, K_row = np.empty((dopri5.N_STAGES + 1, m)), np.empty(m)
    y, f = np.empty(n), np.empty(n)
    n_g = directions.size
    g, g_new, obs = np.empty(n_g), np.empty(n_g), np.empty(mon.shape[0])
    scale_atol = np.empty(m)
    scale_atol[0] = rtol * max(abs(t), 1e-3)
    scale_atol[1:1 + n] = atol
    for i_q in range(nq):
        scale_atol[1 + n + i_q] = atol[i_q]
    z[0], z[1:1 + n], z[1 + n:] = t, y_io, q_io
    d = _rate(rhs, guards, mode, p, k_d, n, z, g, y, f, K[0])   # also the guards at z, into g
    counters[2] += 1
    if not d > 0.0:
        return ZERO, t, i
    h = h_t / d
    tol_t = events.time_tolerance(t, 0.0)
    outcome = -2
    for _ in range(max_steps):
        K_row[:] = K[0]
        d_new = _step(rhs, guards, mode, p, k_d, n, z, h, K, z_new, g_new, y, f)
        counters[2] += dopri5.N_STAGES
        dopri5.error_estimate(h, K, err)
        e = control.error_norm(err, z, z_new, scale_atol, rtol)
        factor = control.step_factor(e, dopri5.ERROR_ORDER, dopri5.SAFETY, dopri5.MIN_FACTOR,
                                     dopri5.MAX_FACTOR)
        if not (e < 1.0 and np.isfinite(e)):
            counters[1] += 1
            K[0, :] = K_row
            h *= factor
            if h * max(d, 1e-300) <= 10.0 * (np.nextafter(z[0], np.inf) - z[0]):
                outcome = -1
                break
            continue
        counters[0] += 1
        # What ends the approach inside this step, in the order of sigma.
        stop = -1
        if not d_new > 0.0:
            stop = ZERO
        elif z_new[0] >= t_end:
            stop = END
        else:
            y[:] = z_new[1:1 + n]
            guards(mode, z_new[0], y, p, g_new)
            for k in range(n_g):
                if k == k_d or g[k] == 1.0 and g_new[k] == 1.0:
                    continue
                crossed = (g[k] > 0.0) != (g_new[k] > 0.0)
                wanted = directions[k] == 0 or (directions[k] > 0) == (g_new[k] > 0.0)
                if crossed and wanted:
                    stop = OTHER
        if stop == ZERO:  # the reactions grow without bound, with the signs they have here (D > 0)
            y[:] = z[1:1 + n]
            observe(mode, z[0], y, p, obs)
            for k in range(mon.shape[0]):
                mon[k, 0], mon[k, 1] = np.inf, np.inf if obs[k] >= 0.0 else -np.inf
        if stop == ZERO or stop == END:
            which, target = (-1, 0.0) if stop == ZERO else (0, t_end)
            # END: the far side (t >= t_end, then set to t_end); ZERO: the near side, where
            # D > 0 still: the state's formulas there are the limits at the Painleve point.
            _root(rhs, guards, mode, p, k_d, n, z, K_row, h, K, z_new, g_new, y, f, which, target,
                  tol_t / max(d, 1e-300) if stop == END else 1e-15 * h, stop == END)
            if stop == END:
                z_new[0] = t_end
        if stop == OTHER:
            outcome = OTHER
            break
        # Output rows in (t, t_new]: solve t(sigma) = t_out on re-taken steps.
        while i < t_out.size and t_out[i] <= z_new[0]:
            if t_out[i] == z_new[0]:
                z_tmp[:] = z_new
            else:
                _root(rhs, guards, mode, p, k_d, n, z, K_row, h, K, z_tmp, g_new, y, f, 0,
                      t_out[i], tol_t / max(d, 1e-300), True)
            y_out[i, :n] = z_tmp[1:1 + n]
            y_out[i, n:] = z_tmp[1 + n:]
            i += 1
        z[:] = z_new
        if stop == ZERO:
            for k in range(mon.shape[0]):
                mon[k, 2] = z[0]
            outcome = ZERO
            break
        y[:] = z[1:1 + n]
        observe(mode, z[0], y, p, obs)
        for k in range(mon.shape[0]):
            if abs(obs[k]) > mon[k, 0]:
                mon[k, 0], mon[k, 1], mon[k, 2] = abs(obs[k]), obs[k], z[0]
        if stop == END:
            outcome = END
            break
        d_prev = d
        d = _rate(rhs, guards, mode, p, k_d, n, z, g, y, f, K[0])   # and the guards at z, into g
        counters[2] += 1
        if d >= d_prev or d > CLEAR_STEPS * (d_prev - d):
            outcome = CLEAR
            break
        h *= factor
    y_io[:] = z[1:1 + n]
    q_io[:] = z[1 + n:]
    return outcome, z[0], i
