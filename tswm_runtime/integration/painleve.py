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
re-taken steps; each step's dense output in sigma goes into the step log (``steplog``);
the observables' running maxima are updated at step ends.
"""
from collections import namedtuple

import numpy as np

from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit

from tswm_runtime.integration import control
from tswm_runtime.integration import dopri5
from tswm_runtime.integration import events
from tswm_runtime.integration import steplog

ZERO, END, OTHER, CLEAR = 0, 1, 2, 3  # outcomes besides the integrator's failure codes
TRIGGER_STEPS = 4.0  # The segment loop hands over when D would reach 0 within this many steps,
CLEAR_STEPS = 8.0  # and gets it back when it would not within this many (or D grows).
MAX_CHANGE = 2.0  # A step in t may change D by at most this factor, either way.


@njit(error_model="numpy")
def heading_for_zero(d_start, d_end):
    """True when a step took D from d_start down to d_end > 0 at a rate that reaches 0
    within TRIGGER_STEPS more steps of the same length."""
    return 0.0 < d_end < d_start and d_end <= TRIGGER_STEPS * (d_start - d_end)


@njit(error_model="numpy")
def too_steep(d_start, d_end):
    """True when a step in t changed D (> 0 at its start) by more than MAX_CHANGE either
    way: a step that long may have jumped across D = 0 (its stages beyond the zero, where
    a1 changes sign, and its error estimate blind to it), so the loop rejects it."""
    return not d_start / MAX_CHANGE < d_end < MAX_CHANGE * d_start


#: The approach's work arrays: the augmented state z = (t, y, q) at a step's start, at its end
#: and on a re-taken step (z_tmp), the error estimate, the stages K and the rate at z (K_row),
#: the model's state y and rate f, the guards at a step's start (g) and end (g_new), the
#: observables, and z's absolute tolerances.
Sundman = namedtuple("Sundman", "z z_new z_tmp err K K_row y f g g_new obs atol")


@njit(error_model="numpy", refcounted=True)
def _work(n, n_quad, n_guards, n_obs):
    """The Sundman work arrays for n states, n_quad integrals, n_guards guards, n_obs observables."""
    m = 1 + n + n_quad
    return Sundman(np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty((dopri5.N_STAGES + 1, m)),
                   np.empty(m), np.empty(n), np.empty(n), np.empty(n_guards), np.empty(n_guards), np.empty(n_obs),
                   np.empty(m))


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _rate(fns, seg, z, g, dz, w):
    """dz = d(t, y, q)/dsigma at z (the guards there into g); returns D."""
    n = w.y.size
    copy_into(w.y, z[1:1 + n])
    fns.guards(seg.mode, z[0], w.y, seg.p, g)
    d = g[seg.ev.singular]
    fns.rhs(seg.mode, z[0], w.y, seg.p, w.f)
    dz[0] = d
    for i in range(n):
        dz[1 + i] = d * w.f[i]
    for i in range(z.size - 1 - n):
        dz[1 + n + i] = d * w.y[i]
    return d


@njit(error_model="numpy")
def _step(fns, seg, z, h, z_new, g, w):
    """One DOPRI5 step of size h in sigma from z (w.K[0] = rate at z on entry); fills w.K[6]."""
    K = w.K
    m = z.size
    for s in range(1, dopri5.N_STAGES):
        for i in range(m):
            acc = 0.0
            for j in range(s):
                acc += dopri5.A[s, j] * K[j, i]
            z_new[i] = z[i] + h * acc
        _rate(fns, seg, z_new, g, K[s], w)
    for i in range(m):
        acc = 0.0
        for j in range(dopri5.N_STAGES):
            acc += dopri5.B[j] * K[j, i]
        z_new[i] = z[i] + h * acc
    return _rate(fns, seg, z_new, g, K[dopri5.N_STAGES], w)


@njit(error_model="numpy")
def _retake(fns, seg, h, z_out, w):
    """z_out = a full step of length h from w.z (w.K_row: the rate there); returns D there."""
    copy_into(w.K[0], w.K_row)
    return _step(fns, seg, w.z, h, z_out, w.g_new, w)


@njit(error_model="numpy", refcounted=True)
def _root(fns, seg, h, z_out, w, which, target, tol, far):
    """sigma in (0, h] where component ``which`` of the step re-taken from w.z (D for which < 0)
    reaches ``target``, by Illinois; z_out holds the state on the far side of it (far) or on
    the near side. Returns that sigma."""
    z = w.z
    f_a = (w.K_row[0] if which < 0 else z[which]) - target
    d_b = _retake(fns, seg, h, z_out, w)
    state = events.bracket_start(0.0, f_a, h, (d_b if which < 0 else z_out[which]) - target)
    z_far, z_near = z_out.copy(), z.copy()
    while not events.bracket_done(state, tol):
        c = events.bracket_next(state, tol)
        d_c = _retake(fns, seg, c, z_out, w)
        state = events.bracket_update(state, c, (d_c if which < 0 else z_out[which]) - target)
        if state[2] == c:
            copy_into(z_far, z_out)
        else:
            copy_into(z_near, z_out)
    copy_into(z_out, z_far if far else z_near)
    return state[2] if far else state[0]


@njit(error_model="numpy")
def _begin(fns, settings, seg, state, w):
    """z and its absolute tolerances from the state; returns D there (the rate into w.K[0],
    the guards into w.g)."""
    n, z = state.y.size, w.z
    w.atol[0] = settings.tol.rtol * max(abs(state.t), 1e-3)
    copy_into(w.atol[1:1 + n], settings.tol.atol)
    for i_q in range(state.quad.size):
        w.atol[1 + n + i_q] = settings.tol.atol[i_q]
    z[0] = state.t
    copy_into(z[1:1 + n], state.y)
    copy_into(z[1 + n:], state.quad)
    return _rate(fns, seg, z, w.g, w.K[0], w)


@njit(error_model="numpy")
def _stop_inside(fns, seg, t_end, d_new, w):
    """What ends the approach inside the accepted step from w.z to w.z_new (ZERO before END before
    OTHER: the order in sigma), -1 if nothing does."""
    if not d_new > 0.0:
        return ZERO
    z_new = w.z_new
    if z_new[0] >= t_end:
        return END
    n = w.y.size
    directions, g, g_new = seg.ev.directions, w.g, w.g_new
    copy_into(w.y, z_new[1:1 + n])
    fns.guards(seg.mode, z_new[0], w.y, seg.p, g_new)
    stop = -1
    for k in range(directions.size):
        if k == seg.ev.singular or g[k] == 1.0 and g_new[k] == 1.0:
            continue
        crossed = (g[k] > 0.0) != (g_new[k] > 0.0)
        wanted = directions[k] == 0 or (directions[k] > 0) == (g_new[k] > 0.0)
        if crossed and wanted:
            stop = OTHER
    return stop


@njit(error_model="numpy")
def _unbounded(fns, seg, mon, w):
    """D reaches 0: the reactions grow without bound, with the signs they have at w.z (D > 0)."""
    n = w.y.size
    copy_into(w.y, w.z[1:1 + n])
    fns.observe(seg.mode, w.z[0], w.y, seg.p, w.obs)
    for k in range(mon.shape[0]):
        mon[k, 0], mon[k, 1] = np.inf, np.inf if w.obs[k] >= 0.0 else -np.inf


@njit(error_model="numpy")
def _land(fns, seg, stop, t_end, h, d, tol_t, w):
    """w.z_new on D = 0 (ZERO) or on t = t_end (END), located in the step of size h; returns the
    sigma of it. END: the far side (t >= t_end, then set to t_end); ZERO: the near side, where
    D > 0 still: the state's formulas there are the limits at the Painleve point."""
    which, target = (-1, 0.0) if stop == ZERO else (0, t_end)
    sigma = _root(fns, seg, h, w.z_new, w, which, target, tol_t / max(d, 1e-300) if stop == END else 1e-15 * h,
                  stop == END)
    if stop == END:
        w.z_new[0] = t_end
    return sigma


@njit(error_model="numpy")
def _write_rows(fns, seg, out, i, h, d, tol_t, w):
    """Output rows in (t, t_new] of the step from w.z to w.z_new: t(sigma) = t_out solved on
    re-taken steps. Returns the next row."""
    n, t_out, z_new, z_tmp = w.y.size, out.t, w.z_new, w.z_tmp
    while i < t_out.size and t_out[i] <= z_new[0]:
        if t_out[i] == z_new[0]:
            copy_into(z_tmp, z_new)
        else:
            _root(fns, seg, h, z_tmp, w, 0, t_out[i], tol_t / max(d, 1e-300), True)
        copy_into(out.y[i, :n], z_tmp[1:1 + n])
        copy_into(out.y[i, n:], z_tmp[1 + n:])
        i += 1
    return i


@njit(error_model="numpy")
def _observe_max(fns, seg, mon, w):
    """The observables' running maxima with their values at w.z."""
    n, z = w.y.size, w.z
    copy_into(w.y, z[1:1 + n])
    fns.observe(seg.mode, z[0], w.y, seg.p, w.obs)
    for k in range(mon.shape[0]):
        if abs(w.obs[k]) > mon[k, 0]:
            mon[k, 0], mon[k, 1], mon[k, 2] = abs(w.obs[k]), w.obs[k], z[0]


@njit(error_model="numpy", refcounted=True)
def approach(fns, settings, seg, state, record, i):
    """Follow the mode from ``state`` in Sundman time; see the module docstring.

    fns: the segment's Functions; settings: Settings (t_end, tol, max_steps: the attempts
    left); seg: the Segment (seg.ev.singular is D's guard); state: the State where the segment
    loop stopped (state.h: its last step in t), whose y and quad are updated to the returned
    state; record: the Record (record.out: rows from i on). Returns (outcome, t, next output
    row): outcome ZERO, END, OTHER, CLEAR or -1 (step too small), -2 (max steps) as the
    segment's codes.
    """
    t_end, counters, mon = settings.t_end, record.counters, record.mon
    n = state.y.size
    w = _work(n, state.quad.size, seg.ev.directions.size, mon.shape[0])
    z, z_new, K = w.z, w.z_new, w.K
    Qz = np.empty((z.size, 4))  # a step's dense output in sigma, for the step log
    d = _begin(fns, settings, seg, state, w)
    counters[2] += 1
    if not d > 0.0:
        return ZERO, state.t, i
    h = state.h / d
    tol_t = events.time_tolerance(state.t, 0.0)
    outcome = -2
    for _ in range(settings.max_steps):
        copy_into(w.K_row, K[0])
        d_new = _step(fns, seg, z, h, z_new, w.g_new, w)
        counters[2] += dopri5.N_STAGES
        dopri5.error_estimate(h, K, w.err)
        e = control.error_norm(w.err, z, z_new, w.atol, settings.tol.rtol)
        factor = control.step_factor(e, dopri5.ERROR_ORDER, dopri5.SAFETY, dopri5.MIN_FACTOR,
                                     dopri5.MAX_FACTOR)
        if not (e < 1.0 and np.isfinite(e)):
            counters[1] += 1
            copy_into(K[0], w.K_row)
            h *= factor
            if h * max(d, 1e-300) <= 10.0 * (np.nextafter(z[0], np.inf) - z[0]):
                outcome = -1
                break
            continue
        counters[0] += 1
        stop = _stop_inside(fns, seg, t_end, d_new, w)
        if stop == OTHER:
            outcome = OTHER
            break
        dopri5.dense_coeffs(K, Qz)  # before _land re-takes steps over K
        if stop == ZERO:
            _unbounded(fns, seg, mon, w)
        theta_hi = 1.0
        if stop == ZERO or stop == END:
            theta_hi = _land(fns, seg, stop, t_end, h, d, tol_t, w) / h
        i = _write_rows(fns, seg, record.out, i, h, d, tol_t, w)
        steplog.log_sundman(record.steps, z, h, z_new, Qz, theta_hi)
        copy_into(z, z_new)
        if stop == ZERO:
            for k in range(mon.shape[0]):
                mon[k, 2] = z[0]
            outcome = ZERO
            break
        _observe_max(fns, seg, mon, w)
        if stop == END:
            outcome = END
            break
        d_prev = d
        d = _rate(fns, seg, z, w.g, K[0], w)   # and the guards at z, into g
        counters[2] += 1
        if d >= d_prev or d > CLEAR_STEPS * (d_prev - d):
            outcome = CLEAR
            break
        h *= factor
    copy_into(state.y, z[1:1 + n])
    copy_into(state.quad, z[1 + n:])
    return outcome, z[0], i
