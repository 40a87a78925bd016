"""Integrate one segment of a hybrid trajectory: fixed mode, until t_end or an event.

The step loop ``run`` is compiled into the mode machine's segment kernel
(``hybrid.segments``, ``SEGMENT_SIG``), whose explicit signature takes the model functions as numba first-class function
types (see ``signatures``). The method is chosen by a code (``DOPRI5`` explicit,
``ROSENBROCK23`` and ``RODAS4`` stiff); all share the step loop, step-size control and event
location below. Its step (``dopri5_attempt``, ``rosenbrock23_attempt``, ``rodas4_attempt``) is a
first-class function argument too (``attempt_function``), so the step loop and the
mode machine are compiled once for all methods and each method's step on its
first use: a run never compiles a method it does not use. ``AUTO`` takes DOPRI5's and
AUTO_STIFF's steps (``method_steps``) and exchanges them where DOPRI5's step is limited by
stability and back (``_stiff``, ``_judge``); the state goes on, each side's controller starts afresh.

Per accepted step [t_a, t_b]: guards are sampled on the dense output (unless their
values and rates at both ends show that none can reach zero) and a crossing is
located on it (``events``); the state AT the event is then obtained
by re-taking a full-order step of length t_event - t_a from (t_a, y_a). If that
state is still on the pre-crossing side of the guard (the interpolant and the
step differ by about the local error), the same Illinois iteration is continued
on the re-taken steps, so the returned state is on the far side of (or on) the
switching surface: a restart cannot fire the same crossing again.

Conventions: forward integration (t_end >= t0); the last step is clipped to land
exactly on t_end; the mode never changes inside a segment (error estimators are
not valid across a switch, scipy issue 18039), the caller restarts after events.

``single.integrate_segment`` calls ``run`` for one segment from Python (no noise
band, no quadrature, no monitored observables; for tests and tools, and compiled
only where they import it); the hybrid driver (``hybrid``) calls it with all three.
Arguments travel in the named structures of ``structures``: the functions
(Functions), the run's Settings, the Segment (mode, p, EventSettings), the State it
starts from, the Record it writes to, and its work arrays (``SegmentWork``). ``run``
is a sequence of named steps: ``_start``, then per step attempt ``_rejected`` or
``_accepted``, ``_first_event``, ``_advance``, ``_hold`` at a stable rest, ``_next_step``.
"""
from collections import namedtuple

import numba
import numpy as np
from numba import types

from tswm_runtime.jit import cache_guard
from tswm_runtime.integration import control
from tswm_runtime.integration import dopri5
from tswm_runtime.integration import events
from tswm_runtime.integration import painleve
from tswm_runtime.integration import rodas
from tswm_runtime.integration import rosenbrock
from tswm_runtime.integration import steady
from tswm_runtime.integration import steplog
from tswm_runtime.jit.arrays import copy_into, copy_rows
from tswm_runtime.jit.borrow import borrowed
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import JAC_SIG, VECTOR, GuardsFunction, JacFunction, RhsFunction, compiled
from tswm_runtime.jit.structures import (EVENT_SETTINGS, INTS, RECORD, SETTINGS, STEP_WORK, TOLERANCES, Functions,
                                         Segment, State, Step, StepWork)

# Method codes.
DOPRI5 = 0  # Dormand-Prince 5(4), explicit (dopri5.py).
ROSENBROCK23 = 1  # Shampine-Reichelt ode23s Rosenbrock 2(3), stiff, uses jac (rosenbrock.py).
AUTO = 2  # DOPRI5, switching to AUTO_STIFF where its steps are limited by stability, and back.
RODAS4 = 3  # Hairer-Wanner RODAS4 4(3), stiff, uses jac (rodas.py).
AUTO_STIFF = RODAS4  # AUTO's stiff method.

# Status codes of a segment.
REACHED_END = 0  # Integrated up to t_end exactly.
EVENT = 1  # Stopped at the first event; t and y_stop are the event's.
APPROACH = 2  # The singular guard (D) heads for zero: hand over to painleve.approach at t.
STEP_TOO_SMALL = -1  # Rejected step sizes fell below max(hmin, 10 ulp(t)).
MAX_STEPS = -2  # max_steps step attempts (accepted + rejected) were made.
NOT_FINITE = -3  # Non-finite state, derivative, Jacobian or guard at an accepted point.
INVALID_INPUT = -4  # Unknown method, inconsistent array sizes, t_end < t0, ...

# Indices into the counters array (incremented, never reset, by run).
N_STEPS = 0  # Accepted steps.
N_REJECTED = 1  # Rejected step attempts.
N_RHS = 2  # Calls of rhs.
N_JAC = 3  # Calls of jac.
N_SWITCHES = 4  # Switches of an AUTO run between its methods (odd: it is on AUTO_STIFF now).
N_COUNTERS = 5

MIN_STEP_ULPS = 10.0  # A step must exceed 10 ulp(t) to move t reliably (scipy's min_step).

# AUTO's switch (Hairer & Wanner's DOPRI5 stiffness test, dopri5.f): STIFF_VERDICTS accepted steps
# with h rho > STIFF_H_RHO (CALM_VERDICTS in a row below it reset the count) switch to
# AUTO_STIFF; CALM_VERDICTS steps in a row whose next step DOPRI5 could take stably (h rho <= the
# limit, rho from the Jacobian; the step no longer growing fast) switch back. Each return doubles
# the stiff verdicts needed to leave again (at most STIFF_VERDICTS << MAX_BACKOFF): no flip-flopping.
STIFF_VERDICTS = 15
# Below Hairer's 3.25 (``dopri5.STABILITY_LIMIT``): at tight rtol DOPRI5's controller holds the step a
# little inside the stability region, h |J| 2.81 to 3.23 (5 to 95 %) on slow-load's stability-limited
# tail at rtol 1e-9 (3.25 never fired there), 2.82 to 3.77 at rtol 1e-6.
STIFF_H_RHO = 0.85 * dopri5.STABILITY_LIMIT
CALM_VERDICTS = 6
MAX_BACKOFF = 6
SETTLED_GROWTH = 2.0  # AUTO_STIFF's step grows by less than this: accuracy limits it



@cache_guard.compile_cached(JAC_SIG)   # after the stale-cache check, which would purge it
def no_jacobian(mode, t, y, p, J, dfdt):
    """Placeholder ``jac`` for DOPRI5 runs (DOPRI5 never calls it); fills NaN."""
    J[:, :] = np.nan
    dfdt[:] = np.nan


@njit(error_model="numpy")
def _all_finite(x):
    """True if no entry of x (any shape) is NaN or infinite (``flat``: ``ravel`` made a view, its
    reference counted, at every call)."""
    for v in x.flat:
        if not np.isfinite(v):
            return False
    return True


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _eval_guards(fns, seg, t, y, g):
    """Guards into g (skipped when the model has none); True if all are finite."""
    if g.size > 0:
        fns.guards(seg.mode, t, y, seg.p, g)
    return _all_finite(g)


@njit(error_model="numpy")
def _error_order(method):
    """Order of the method's error estimator (for the initial step)."""
    if method == DOPRI5:
        return dopri5.ERROR_ORDER
    return rodas.ERROR_ORDER if method == RODAS4 else rosenbrock.ERROR_ORDER


@njit(error_model="numpy")
def _step_tolerance(method, rtol):
    """The fraction of the tolerance a step's error is held to (1 for DOPRI5, which advances with
    its 5th-order solution, and RODAS4, with its 4th-order one; less for ROSENBROCK23 at tight rtol:
    ``control.proportional_tolerance``)."""
    if method != ROSENBROCK23:
        return 1.0
    return control.proportional_tolerance(rtol, rosenbrock.ERROR_ORDER, rosenbrock.PROPORTIONAL_RTOL,
                                          rosenbrock.STEP_RTOL_FLOOR)


@njit(error_model="numpy")
def _judged(e, y_new, order, safety, lo, hi):
    """(scaled error norm e, step factor): inf and the smallest factor if anything is not finite."""
    if not (np.isfinite(e) and _all_finite(y_new)):
        e = np.inf
    return e, control.step_factor(e, order, safety, lo, hi)


@njit(cache=True, error_model="numpy", no_cfunc_wrapper=False)  # a first-class function value
def dopri5_attempt(rhs, mode, t, y, p, h, f0, work, y_new, f_new, err, tol, counters, estimate):
    """DOPRI5's step of size h from (t, y), f0 = f(t, y): y_new; with ``estimate`` also
    f_new = f(t + h, y_new), the dense output work.Q, and returns (scaled error norm, step
    factor) for the controller (inf and the smallest factor when anything is not finite)."""
    copy_into(work.K[0], f0)
    dopri5.stages(rhs, mode, t, y, p, h, work.K, y_new, work.y6)
    counters[N_RHS] += dopri5.N_STAGES - 1
    if not estimate:
        return np.inf, dopri5.MIN_FACTOR
    rhs(mode, t + h, y_new, p, f_new)
    counters[N_RHS] += 1
    copy_into(work.K[dopri5.N_STAGES], f_new)
    dopri5.error_estimate(h, work.K, err)
    dopri5.dense_coeffs(work.K, work.Q)
    e = control.error_norm(err, y, y_new, tol.atol, tol.rtol)
    dense = work.K[3]  # the dense output's error (the stages are spent)
    dopri5.dense_error(rhs, mode, t, y, p, h, work.K, work.Q, dense)
    counters[N_RHS] += 2
    e_dense = control.error_norm(dense, y, y_new, tol.atol, tol.rtol)
    if e_dense > e or not np.isfinite(e_dense):
        e = e_dense
    return _judged(e, y_new, dopri5.ERROR_ORDER, dopri5.SAFETY, dopri5.MIN_FACTOR, dopri5.MAX_FACTOR)


@njit(cache=True, error_model="numpy", no_cfunc_wrapper=False)  # a first-class function value
def rosenbrock23_attempt(rhs, mode, t, y, p, h, f0, work, y_new, f_new, err, tol, counters, estimate):
    """ROSENBROCK23's step, as ``dopri5_attempt``; work.J and work.dfdt hold the Jacobian at (t, y)."""
    rosenbrock.stages(rhs, mode, t, y, p, h, f0, work.J, work.dfdt, work.LU, work.piv, work.K, y_new)
    counters[N_RHS] += 1
    if not estimate:
        return np.inf, rosenbrock.MIN_FACTOR
    rhs(mode, t + h, y_new, p, f_new)
    counters[N_RHS] += 1
    rosenbrock.error_estimate(h, f0, f_new, work.dfdt, work.LU, work.piv, work.K, err)
    err /= _step_tolerance(ROSENBROCK23, tol.rtol)
    rosenbrock.dense_coeffs(work.K, work.Q)
    return _judged(control.error_norm(err, y, y_new, tol.atol, tol.rtol), y_new, rosenbrock.ERROR_ORDER, rosenbrock.SAFETY, rosenbrock.MIN_FACTOR,
                   rosenbrock.MAX_FACTOR)


@njit(cache=True, error_model="numpy", no_cfunc_wrapper=False)  # a first-class function value
def rodas4_attempt(rhs, mode, t, y, p, h, f0, work, y_new, f_new, err, tol, counters, estimate):
    """RODAS4's step, as ``rosenbrock23_attempt``; judged by the larger of its error and its dense
    output's (``rodas.dense_error``)."""
    rodas.stages(rhs, mode, t, y, p, h, f0, work.J, work.dfdt, work.LU, work.piv, work.K, y_new)
    counters[N_RHS] += rodas.N_STAGES - 1
    if not estimate:
        return np.inf, rodas.MIN_FACTOR
    rhs(mode, t + h, y_new, p, f_new)
    counters[N_RHS] += 1
    rodas.error_estimate(work.K, err)
    rodas.dense_coeffs(h, y, y_new, work.K, work.Q)
    e = control.error_norm(err, y, y_new, tol.atol, tol.rtol)
    rodas.dense_error(rhs, mode, t, y, p, h, work.LU, work.piv, work.K, work.Q, err)
    counters[N_RHS] += 1
    e_dense = control.error_norm(err, y, y_new, tol.atol, tol.rtol)
    if e_dense > e or not np.isfinite(e_dense):
        e = e_dense
    return _judged(e, y_new, rodas.ERROR_ORDER, rodas.SAFETY, rodas.MIN_FACTOR, rodas.MAX_FACTOR)


#: attempt(rhs, mode, t, y, p, h, f0, work, y_new, f_new, err, tol, counters, estimate) -> (error, factor)
ATTEMPT_SIG = types.UniTuple(types.float64, 2)(
    RhsFunction, types.int64, types.float64, VECTOR, VECTOR, types.float64, VECTOR, STEP_WORK, VECTOR, VECTOR,
    VECTOR, TOLERANCES, INTS, types.boolean)
AttemptFunction = types.FunctionType(ATTEMPT_SIG)
#: The numba type of ``structures.Functions``.
FUNCTIONS = types.NamedTuple((AttemptFunction, RhsFunction, JacFunction, GuardsFunction, GuardsFunction,
                              GuardsFunction, AttemptFunction), Functions)
_ATTEMPTS = {DOPRI5: dopri5_attempt, ROSENBROCK23: rosenbrock23_attempt, RODAS4: rodas4_attempt}


def attempt_function(method):
    """The step attempt of ``method`` as the first-class function value ``run`` takes. Compiled,
    or loaded from numba's cache, on first use: a run compiles only its own method's step (after
    the stale-cache check, which a cached step must not precede). An unknown ``method`` is a
    ValueError that names it."""
    if method not in _ATTEMPTS:
        raise ValueError(f"method {method!r}: expected {DOPRI5} (dopri5), {ROSENBROCK23} (rosenbrock23) "
                         f"or {RODAS4} (rodas4)")
    cache_guard.check_kernel_caches()
    return compiled(_ATTEMPTS[method], ATTEMPT_SIG)


def method_steps(method):
    """(attempt, stiff): the steps of Functions for ``method``, ``attempt_function``'s values.
    AUTO starts with DOPRI5's and switches to AUTO_STIFF's (both compiled or loaded); any
    other method's step is both (it never switches)."""
    if method == AUTO:
        return attempt_function(DOPRI5), attempt_function(AUTO_STIFF)
    attempt = attempt_function(method)
    return attempt, attempt


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _swapped(fns):
    """``fns`` with its two steps exchanged: an AUTO run's switch of method."""
    return Functions(fns.stiff, fns.rhs, fns.jac, fns.guards, fns.observe, fns.impact, fns.attempt)


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _state_at(fns, seg, tol, step, t, y, s, counters):
    """y = state at t in the step by a full step from t_a (exact at the ends); s.g_tmp = guards."""
    if t == step.t_b:
        copy_into(y, step.y_b)
    elif t == step.t_a:
        copy_into(y, step.y_a)
    else:
        fns.attempt(fns.rhs, seg.mode, step.t_a, step.y_a, seg.p, t - step.t_a, step.f_a, s.work, y, y, y, tol,
                    counters, False)
    _eval_guards(fns, seg, t, y, s.g_tmp)


@njit(error_model="numpy")
def _event_state(fns, seg, tol, step, k, t_star, j, s, counters):
    """(event time, True) and state s.y_ev for guard k crossing at t_star (found on the
    dense output); (t_star, False) if the re-taken steps show no crossing (the
    interpolant's error made it: no event).

    The root is refined on the re-taken steps, phi(t) = g_k(t, step(t_a, y_a, t - t_a)),
    whose error is the step's local error, not the interpolant's: Illinois between a
    pre- and a post-crossing point, keeping the far-side end (and its state in y_ev).
    The first bracket is tight about t_star: [t_star - w, t_star] or [t_star, t_star
    + w] with w 1e-3 of the step, widened to [t_a, .] or [., sample j] if needed.
    """
    ev, y_ev, y_tmp, g_tmp = seg.ev, s.y_ev, s.y_tmp, s.g_tmp
    post = s.G[j, k]
    _state_at(fns, seg, tol, step, t_star, y_ev, s, counters)
    g_star = g_tmp[k]
    t_far = events.sample_time(step.t_a, step.t_b, j)
    if (g_star != 0.0 and abs(g_star) <= ev.gtol) or (g_star == 0.0 and t_star >= t_far):
        return t_star, True  # within gtol, or a zero at the segment end (nothing lies beyond)
    far = g_star * post > 0.0
    w = 1e-3 * step.h
    t_probe = max(t_star - w, step.t_a) if far else min(t_star + w, t_far)
    _state_at(fns, seg, tol, step, t_probe, y_tmp, s, counters)
    g_probe = g_tmp[k]
    if (g_probe * post > 0.0) == far:  # the probe is on the same side: widen to the ends
        t_probe = step.t_a if far else t_far
        _state_at(fns, seg, tol, step, t_probe, y_tmp, s, counters)
        g_probe = g_tmp[k]
        if (g_probe * post > 0.0) == far:
            if far:  # already across at t_a (it crossed inside the noise band): report t_a
                copy_into(y_ev, y_tmp)
                return t_probe, True
            return t_star, False
    if far:
        state = events.bracket_start(t_probe, g_probe, t_star, g_star)
    else:
        copy_into(y_ev, y_tmp)
        state = events.bracket_start(t_star, g_star, t_probe, g_probe)
    ttol = events.time_tolerance(state[2], ev.ttol)
    while not events.bracket_done(state, ttol):
        c = events.bracket_next(state, ttol)
        _state_at(fns, seg, tol, step, c, y_tmp, s, counters)
        state = events.bracket_update(state, c, g_tmp[k])
        if state[2] == c:
            copy_into(y_ev, y_tmp)
    return state[2], True


@njit(error_model="numpy")
def _write_samples(out, i, step, t_hi, y_hi, quad, q_tmp):
    """Rows out.y[i:] for the output times in (t_a, t_hi]; returns the next free index.

    With quadrature (quad.size = n), columns n: of a row get quad (the integral up
    to t_a) plus the integral of the dense output from t_a to the row's time.
    """
    n = step.y_a.size
    while i < out.t.size and out.t[i] <= t_hi:
        theta = (out.t[i] - step.t_a) / step.h
        if out.t[i] == t_hi:
            copy_into(out.y[i, :n], y_hi)
        else:
            events.dense_eval(step.y_a, step.h, step.Q, theta, out.y[i, :n])
        if quad.size > 0:
            events.dense_integral(step.y_a, step.h, step.Q, theta, q_tmp)
            for j in range(quad.size):  # elementwise: ``quad + q_tmp`` would allocate per row
                out.y[i, n + j] = quad[j] + q_tmp[j]
        i += 1
    return i


@njit(error_model="numpy")
def _hold_samples(out, i, t, t_hi, y, quad):
    """Rows for the output times in (t, t_hi] while the state is held at y (steady)."""
    n = y.size
    while i < out.t.size and out.t[i] <= t_hi:
        copy_into(out.y[i, :n], y)
        for j in range(quad.size):
            out.y[i, n + j] = quad[j] + y[j] * (out.t[i] - t)
        i += 1
    return i


MaxWindow = namedtuple("MaxWindow", "f y Q s")  # per observable: 2 steps' (t_a, h, t_hi), y_a, Q; fill


@njit(error_model="numpy")
def _monitor(fns, seg, t, y, mon, step, t_hi, obs, win):
    """Track max |observable k| at (t, y) in mon[k] = (|value|, value, t).

    A new maximum at the end of ``step`` (None at a segment start) remembers that step's
    dense output in slot 0 of the refinement window, and the following step in slot 1:
    the true maximum lies in one of the two (``_refine``).
    """
    fns.observe(seg.mode, t, y, seg.p, obs)
    for k in range(mon.shape[0]):
        if abs(obs[k]) > mon[k, 0]:
            mon[k, 0], mon[k, 1], mon[k, 2] = abs(obs[k]), obs[k], t
            slot, win.s[k] = 0, (0 if step is None else 1)
        elif win.s[k] == 1:
            slot, win.s[k] = 1, 2
        else:
            continue
        if step is not None:
            win.f[k, slot, 0], win.f[k, slot, 1], win.f[k, slot, 2] = step.t_a, step.h, t_hi
            copy_into(win.y[k, slot], step.y_a)
            copy_rows(win.Q[k, slot], step.Q)


REFINE_XTOL = 1e-9  # Maxima are located to 1e-9 of their window (plus sqrt(eps) relative to t: Brent's floor).
REFINE_MAX_CALLS = 100  # A bound on observable calls per window (Brent converges in about 10).
_SQRT_EPS = np.sqrt(np.finfo(np.float64).eps)
_GOLDEN = 0.5 * (3.0 - np.sqrt(5.0))


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _window_value(fns, seg, k, t, s):
    """|Observable k| at t, from the window slot whose step contains t."""
    win = s.win
    slot = 0 if (t <= win.f[k, 0, 2] or win.s[k] < 2) else 1
    t_a, h = win.f[k, slot, 0], win.f[k, slot, 1]
    events.dense_eval(win.y[k, slot], h, win.Q[k, slot], (t - t_a) / h, s.y_tmp)
    fns.observe(seg.mode, t, s.y_tmp, seg.p, s.obs)
    return abs(s.obs[k])


@njit(error_model="numpy")
def _brent_max(fns, seg, k, s, a, b, x):
    """(t, |observable k|) at its largest on [a, b], from x: Brent's bounded method (parabolic
    steps with a golden-section fallback; scipy's fminbound), to REFINE_XTOL of b - a."""
    xatol = REFINE_XTOL * (b - a)
    fx = -_window_value(fns, seg, k, x, s)
    v, w, fv, fw = x, x, fx, fx
    rat, e = 0.0, 0.0
    for _ in range(REFINE_MAX_CALLS):
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(x) + xatol / 3.0
        tol2 = 2.0 * tol1
        if abs(x - xm) <= tol2 - 0.5 * (b - a):
            break
        golden = True
        if abs(e) > tol1:  # try a parabola through x, w, v
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            num = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                num = -num
            q = abs(q)
            r, e = e, rat
            if abs(num) < abs(0.5 * q * r) and q * (a - x) < num < q * (b - x):
                golden = False
                rat = num / q
                if (x + rat - a) < tol2 or (b - x - rat) < tol2:
                    rat = tol1 if xm >= x else -tol1
        if golden:
            e = (a - x) if x >= xm else (b - x)
            rat = _GOLDEN * e
        u = x + (max(abs(rat), tol1) if rat >= 0.0 else -max(abs(rat), tol1))
        fu = -_window_value(fns, seg, k, u, s)
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, fv, w, fw = w, fw, u, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
    return x, -fx


@njit(error_model="numpy")
def _rising_to_end(fns, seg, k, mon, s):
    """True if |observable k| rises to its largest value at the end of its window's single step
    (``win.s[k] == 1``: the largest step end is the segment's last), so that no maximum lies inside:
    the cubic Hermite interpolant of |observable| through the step's two ends, with the slopes of
    one-sided differences on the dense output (``events.RATE_STEP`` of the step), peaks at the end,
    and the dense output there finds no more than the step's own end state gave. 4 observable calls
    instead of Brent's search, which on a rising observable closes in on the end (15 calls or so)."""
    win = s.win
    t_a, t_hi = win.f[k, 0, 0], win.f[k, 0, 2]
    width = t_hi - t_a
    d = min(max(events.RATE_STEP * width, 64.0 * (np.nextafter(t_hi, np.inf) - t_hi)), 0.5 * width)
    v_hi = _window_value(fns, seg, k, t_hi, s)
    if not (width > 0.0 and v_hi <= mon[k, 0]):
        return False
    v_a = _window_value(fns, seg, k, t_a, s)
    slope_a = (_window_value(fns, seg, k, t_a + d, s) - v_a) * (width / d)
    slope_b = (v_hi - _window_value(fns, seg, k, t_hi - d, s)) * (width / d)
    # s = -1 as an int64, the type clear_of_zero's guard signs give it: one compiled hermite_lowest, not two
    return -events.hermite_lowest(-1, v_a, v_hi, slope_a, slope_b) <= v_hi


@njit(error_model="numpy")
def _refine(fns, seg, mon, s):
    """Locate max |observable| in each pending window (Brent, from the largest step end, unless it
    rises to the window's end: ``_rising_to_end``) and reset them."""
    win = s.win
    for k in range(mon.shape[0]):
        if win.s[k] == 0:
            continue
        if win.s[k] == 2 or not _rising_to_end(fns, seg, k, mon, s):
            lo, hi, t_m = win.f[k, 0, 0], win.f[k, win.s[k] - 1, 2], mon[k, 2]
            t_best, best = _brent_max(fns, seg, k, s, lo, hi, min(max(t_m, lo), hi))
            if best > mon[k, 0]:
                _window_value(fns, seg, k, t_best, s)
                mon[k, 0], mon[k, 1], mon[k, 2] = best, s.obs[k], t_best
        win.s[k] = 0


#: The scratch arrays of ``run`` (``segment_work``): allocated once by its caller and reused by every segment.
SegmentWork = namedtuple("SegmentWork", "work f_a y_a y_b f_b err y_ev y_tmp y_pert q_tmp G g_tmp sgn cand ignore "
                                        "rate_a rate_b obs win")


@njit(refcounted=True, error_model="numpy")
def segment_work(n, m, n_quad, n_obs):
    """Scratch arrays for ``run``: n states, m guards, n_quad integrals, n_obs monitored observables."""
    return SegmentWork(
        StepWork(np.empty((dopri5.N_STAGES + 1, n)), np.zeros((n, 4)), np.empty((n, n)), np.empty(n),
                 np.empty((n, n)), np.empty(n, np.int64), np.empty(n), np.empty((n, n))),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n_quad), np.empty((events.GUARD_SUBINTERVALS + 1, m)), np.empty(m), np.zeros(m, np.int64),
        np.zeros(m, np.bool_), np.zeros(m, np.bool_), np.empty(m), np.empty(m), np.empty(n_obs),
        MaxWindow(np.zeros((n_obs, 2, 3)), np.zeros((n_obs, 2, n)), np.zeros((n_obs, 2, n, 4)),
                  np.zeros(n_obs, np.int64)))


#: The numba types of a ``Segment``, a ``State`` and ``segment_work``'s arrays (numba's type of its value).
SEGMENT = types.NamedTuple((types.int64, VECTOR, EVENT_SETTINGS), Segment)
STATE = types.NamedTuple((types.float64, VECTOR, VECTOR, types.float64), State)
SEGMENT_WORK = numba.typeof(getattr(segment_work, "py_func", segment_work)(1, 1, 0, 0))
#: The mode machine's segment (``hybrid.segments.run_segment``), a kernel of its own called through its
#: address: (functions, settings, segment, state, record, next row, scratch) -> (status, t, guard, next row,
#: next step, whether the next segment may hand over again).
SEGMENT_SIG = types.Tuple((types.int64, types.float64, types.int64, types.int64, types.float64, types.boolean))(
    FUNCTIONS, SETTINGS, SEGMENT, STATE, RECORD, types.int64, SEGMENT_WORK)
SegmentFunction = types.FunctionType(SEGMENT_SIG)

#: The step-size controller's memory in a segment: whether the last attempt at t was rejected,
#: that rejected step and its error, and the last accepted step and its error.
Control = namedtuple("Control", "rejected h_rej e_rej h_acc e_acc")
_STEPPING = 3  # _start's code for a segment that has steps to take


@njit(error_model="numpy")
def _start(fns, settings, method, seg, state, record, s):
    """Set up the segment at ``state`` for ``method`` (not AUTO): the maxima there,
    f_a and the guards G[0] (armed), their rates, the first step. Returns (_STEPPING, first step),
    or (REACHED_END or NOT_FINITE, state.h) when there is nothing to step."""
    t, y, counters = state.t, state.y, record.counters
    s.win.s[:] = 0
    if record.mon.shape[0] > 0:
        _monitor(fns, seg, t, y, record.mon, None, t, s.obs, s.win)
    if settings.t_end == t:
        return REACHED_END, state.h
    fns.rhs(seg.mode, t, y, seg.p, s.f_a)
    counters[N_RHS] += 1
    if not (_eval_guards(fns, seg, t, y, s.G[0]) and _all_finite(y) and _all_finite(s.f_a)):
        return NOT_FINITE, state.h
    events.arm_guards(s.G[0], seg.ev.gtol, s.sgn)
    h = state.h
    if h <= 0.0:
        tol = settings.tol
        h = control.select_initial_step(fns.rhs, seg.mode, t, y, seg.p, s.f_a, settings.t_end, tol.hmax,
                                        _error_order(method), tol.rtol, tol.atol, s.y_b, s.f_b)
        h *= _step_tolerance(method, tol.rtol) ** (1.0 / (_error_order(method) + 1))
        counters[N_RHS] += 1
    events.guard_rates(fns.guards, seg.mode, t, y, s.f_a, seg.p, s.G[0], h, s.y_tmp, s.g_tmp, s.rate_a)
    return _STEPPING, h


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _jacobian(fns, seg, t, y, work, counters):
    """The Jacobian and df/dt at (t, y) into work; True if they are finite."""
    fns.jac(seg.mode, t, y, seg.p, work.J, work.dfdt)
    counters[N_JAC] += 1
    return _all_finite(work.J) and _all_finite(work.dfdt)


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _rejected(ctl, h, e, factor, counters):
    """After a step of size h rejected with error e: (control, the next step size)."""
    counters[N_REJECTED] += 1
    if ctl.rejected and ctl.e_rej > e > 0.0 and ctl.h_rej > h:  # rejected again at t: the order the error shows
        factor = min(factor, control.observed_order_factor(e, np.log(ctl.e_rej / e) / np.log(ctl.h_rej / h)))
    return Control(True, h, e, ctl.h_acc, ctl.e_acc), h * factor


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _too_steep(ctl, h, counters):
    """After a step of size h rejected for changing D too much: (control, half the step)."""
    counters[N_REJECTED] += 1
    return Control(True, ctl.h_rej, 0.0, ctl.h_acc, ctl.e_acc), 0.5 * h


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _accepted(ctl, h, h_want, e, factor, order, counters):
    """After a step of size h (h_want before it was clipped to t_end) accepted with error e:
    (control, the next step size)."""
    counters[N_STEPS] += 1
    if ctl.h_acc > 0.0 and e > 0.0:  # Gustafsson's predictive controller: follow the trend of the steps
        factor = min(factor, control.predictive_factor(h, e, ctl.h_acc, ctl.e_acc, order))
    if ctl.rejected:
        factor = min(1.0, factor)
    # A step clipped to land on t_end says nothing against the step wanted.
    h_next = max(h * factor, h_want) if h < h_want else h * factor
    return Control(ctl.rejected, ctl.h_rej, ctl.e_rej, h, max(e, control.PREDICTIVE_MIN_ERR)), h_next


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _first_event(fns, seg, tol, step, t_end, s, counters):
    """(guard, time) of the first event in the accepted ``step`` (its state into s.y_ev), or
    (-1, step.t_b); the guards' rates at t_b into s.rate_b."""
    G, g_b, ignore = s.G, s.G[events.GUARD_SUBINTERVALS], s.ignore
    k, j = -1, 1
    t_new = step.t_b
    ignore[:] = False
    events.guard_rates(fns.guards, seg.mode, t_new, step.y_b, s.f_b, seg.p, g_b, step.h, s.y_tmp, s.g_tmp, s.rate_b)
    clear = events.clear_of_zero(G[0], g_b, s.rate_a, s.rate_b, step.h, s.sgn, seg.ev.gtol)
    for _ in range(0 if clear else seg.ev.directions.size):  # each pass finds an event or ignores one more guard
        k, t_star, j = events.find_event(fns.guards, seg.mode, seg.p, step, G, seg.ev, tol, s.sgn, t_new == t_end,
                                         s.cand, s.y_tmp, s.g_tmp, s.y_pert, j, ignore)
        if k < 0:
            break
        t_ev, real = _event_state(fns, seg, tol, step, k, t_star, j, s, counters)
        if real:
            t_new = t_ev
            break
        ignore[k] = True  # an artefact of the interpolant: look on from sample j
        k = -1
    return k, t_new


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _advance(fns, seg, record, i, step, t_new, y_hi, quad, s):
    """The rows, the step log, the integral and the maxima up to t_new (state y_hi) in ``step``;
    returns the next output row."""
    i = _write_samples(record.out, i, step, t_new, y_hi, quad, s.q_tmp)
    steplog.log_step(record.steps, step.t_a, step.h, t_new, step.y_a, quad, y_hi, step.Q)
    if quad.size > 0:
        events.dense_integral(step.y_a, step.h, step.Q, (t_new - step.t_a) / step.h, s.q_tmp)
        quad += s.q_tmp
    if record.mon.shape[0] > 0:
        _monitor(fns, seg, t_new, y_hi, record.mon, step, t_new, s.obs, s.win)
    return i


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _stable_rest(fns, seg, tol, t, y, quad, s, counters):
    """True if (t, y) is a stable equilibrium of the autonomous scalar segment (``steady``); the
    Jacobian there is left in s.work."""
    work = s.work
    fns.jac(seg.mode, t, y, seg.p, work.J, work.dfdt)
    counters[N_JAC] += 1
    return steady.at_stable_rest(s.f_b, work.J, work.dfdt, tol, y, quad)


@njit(refcounted=True, error_model="numpy")
def _hold(fns, seg, t_end, t, state, record, i, s):
    """Hold the state at its equilibrium (one Newton step onto it) up to the next guard crossing
    or t_end, its observables in the maxima (the rows carry the held state, so must the maxima).
    Returns (t, guard or -1, next output row)."""
    y, quad, g_b = state.y, state.quad, s.G[events.GUARD_SUBINTERVALS]
    y[0] -= s.f_b[0] / s.work.J[0, 0]  # one Newton step onto the equilibrium itself
    if record.mon.shape[0] > 0:
        _refine(fns, seg, record.mon, s)  # the steps before the hold, then the held state itself
        _monitor(fns, seg, t, y, record.mon, None, t, s.obs, s.win)
    fns.guards(seg.mode, t, y, seg.p, g_b)
    t_hold, k = steady.hold(fns.guards, seg.mode, t, y, seg.p, t_end, g_b, seg.ev, s.g_tmp)
    i = _hold_samples(record.out, i, t, t_hold, y, quad)
    steplog.log_held(record.steps, t, t_hold, y, quad)
    if quad.size > 0:
        quad += y * (t_hold - t)
    return t_hold, k, i


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _stiff(method, work, h, h_next, y_new):
    """Whether DOPRI5's stability limits the step: after DOPRI5's step h, h rho from its last two
    stages (``dopri5.stiffness``); after AUTO_STIFF's, the next step h_next times a bound of rho
    from its Jacobian (``control.spectral_radius``), above ``STIFF_H_RHO``, or h_next
    still growing by more than SETTLED_GROWTH (as after a restart: its size says nothing yet)."""
    if method == DOPRI5:
        return dopri5.stiffness(h, work.K, y_new, work.y6) > STIFF_H_RHO
    if h_next > SETTLED_GROWTH * h:
        return True
    return h_next * control.spectral_radius(work.J, work.M, work.LU) > STIFF_H_RHO


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _judge(method, stiff, verdicts, calm, switches):
    """AUTO's hysteresis after an accepted step (``STIFF_VERDICTS``): (stiff verdicts, calm
    verdicts in a row, whether to switch method now); ``switches`` made so far in the run."""
    calm = 0 if stiff else calm + 1
    if method != DOPRI5:
        return verdicts, calm, calm >= CALM_VERDICTS
    if stiff:
        verdicts += 1
    elif calm >= CALM_VERDICTS:
        verdicts = 0
    return verdicts, calm, verdicts >= STIFF_VERDICTS << min(switches // 2, MAX_BACKOFF)


@njit(error_model="numpy", forceinline=True)  # a step of its caller: inlined by LLVM, typed once
def _next_step(s):
    """The end of the accepted step becomes the start of the next."""
    copy_into(s.f_a, s.f_b)
    copy_into(s.G[0], s.G[events.GUARD_SUBINTERVALS])
    copy_into(s.rate_a, s.rate_b)


@njit(error_model="numpy")
def run(fns, settings, seg, state, record, i, scratch):
    """The step loop of one segment from ``state``, whose y and quad are updated in place.

    fns: Functions (fns.attempt, fns.stiff: ``method_steps(settings.method)``; fns.impact is not
    called). settings: Settings (max_steps: the step attempts allowed; method AUTO starts on
    the method the last segment ended with: counters[N_SWITCHES] odd, AUTO_STIFF).
    seg: Segment; seg.ev.singular: a guard (D) whose zero the model cannot be integrated to
    in t, the loop stops with APPROACH after a step that takes it towards 0 fast (-1: none).
    state: State; state.quad, the integral of y, is carried along if its size is y's.
    record: Record; rows of record.out from i on are filled, the accepted steps logged in
    record.steps (``steplog``); the observables are tracked for
    their maxima in record.mon (none if it has no rows); record.log is not used.
    scratch: ``segment_work(y.size, guards, quad.size, mon.shape[0])``. Every array
    argument is borrowed (``borrow``) for the step loop.
    Returns (status, t, event index, next output index, proposed next step).
    """
    settings, seg, state, record, scratch = borrowed((settings, seg, state, record, scratch))
    tol, t_end, counters, y, k_sing = settings.tol, settings.t_end, record.counters, state.y, seg.ev.singular
    work, G, g_b = scratch.work, scratch.G, scratch.G[events.GUARD_SUBINTERVALS]
    auto, method = settings.method == AUTO, settings.method
    if auto:  # on the method the run's last segment ended with
        method = AUTO_STIFF if counters[N_SWITCHES] % 2 == 1 else DOPRI5
        if method != DOPRI5:
            fns = _swapped(fns)
    status, h_prop = _start(fns, settings, method, seg, state, record, scratch)
    t = state.t
    if status != _STEPPING:
        return status, t, -1, i, h_prop
    order = _error_order(method)
    ctl = Control(False, 0.0, 0.0, 0.0, 0.0)
    jac_current = False
    verdicts, calm, stiff = 0, 0, False  # AUTO's stiffness verdicts (``_judge``)
    status, k = MAX_STEPS, -1
    for _ in range(settings.max_steps):
        if method != DOPRI5 and not jac_current:
            jac_current = True
            if not _jacobian(fns, seg, t, y, work, counters):
                status = NOT_FINITE
                break
        h_want = min(h_prop, tol.hmax)
        h = h_want
        t_new = t + h
        if t_new >= t_end:
            t_new = t_end
            h = t_end - t
        e, factor = fns.attempt(fns.rhs, seg.mode, t, y, seg.p, h, scratch.f_a, work, scratch.y_b, scratch.f_b,
                                scratch.err, tol, counters, True)
        too_short = max(tol.hmin, MIN_STEP_ULPS * (np.nextafter(t, np.inf) - t))
        if not e < 1.0:
            ctl, h_prop = _rejected(ctl, h, e, factor, counters)
            if h_prop < too_short:
                status = STEP_TOO_SMALL
                break
            continue
        guards_finite = _eval_guards(fns, seg, t_new, scratch.y_b, g_b)
        # no step in t may change D by more than a factor 2: it could jump its zero
        if k_sing >= 0 and painleve.too_steep(G[0, k_sing], g_b[k_sing]):
            ctl, h_prop = _too_steep(ctl, h, counters)
            if h_prop < too_short:
                status = STEP_TOO_SMALL
                break
            continue
        ctl, h_prop = _accepted(ctl, h, h_want, e, factor, order, counters)
        if auto:  # before the event search, which may re-take (part of) the step
            stiff = _stiff(method, work, h, min(h_prop, tol.hmax), scratch.y_b)
        if not guards_finite:
            status = NOT_FINITE
            break
        copy_into(scratch.y_a, y)
        step = Step(t, scratch.y_a, scratch.f_a, h, t_new, scratch.y_b, work.Q)
        k, t_new = _first_event(fns, seg, tol, step, t_end, scratch, counters)
        y_hi = scratch.y_ev if k >= 0 else scratch.y_b
        i = _advance(fns, seg, record, i, step, t_new, y_hi, state.quad, scratch)
        t = t_new
        copy_into(y, y_hi)
        if k >= 0:
            status = EVENT
            break
        if k_sing >= 0 and t < t_end and painleve.heading_for_zero(G[0, k_sing], g_b[k_sing]):
            status = APPROACH
            break
        fresh_jac = False  # J at the new point, for the next Rosenbrock step
        if seg.ev.hold and t < t_end and steady.worth_checking(scratch.f_b, h, tol, y):
            fresh_jac = True
            if _stable_rest(fns, seg, tol, t, y, state.quad, scratch, counters):
                t, k, i = _hold(fns, seg, t_end, t, state, record, i, scratch)
                status = EVENT if k >= 0 else REACHED_END
                break
        _next_step(scratch)
        ctl = Control(False, ctl.h_rej, ctl.e_rej, ctl.h_acc, ctl.e_acc)
        jac_current = fresh_jac
        if auto:
            verdicts, calm, switch = _judge(method, stiff, verdicts, calm, counters[N_SWITCHES])
            if switch:  # the state goes on; the new method's controller starts afresh from h_prop
                counters[N_SWITCHES] += 1
                fns = _swapped(fns)
                method = AUTO_STIFF if method == DOPRI5 else DOPRI5
                order = _error_order(method)
                ctl = Control(False, 0.0, 0.0, 0.0, 0.0)
                verdicts, calm = 0, 0
        if t == t_end:
            status = REACHED_END
            break
    if record.mon.shape[0] > 0:
        _refine(fns, seg, record.mon, scratch)
    return status, t, k, i, h_prop
