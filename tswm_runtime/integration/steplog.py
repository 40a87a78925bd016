"""The step log: a run's accepted steps, kept so that its rows and dense solution are evaluated after it.

The step loops write each accepted step into the ``StepLog`` (``jit.structures``) and the mode
machine each segment's mode and parameter vector; ``states_at`` then evaluates the states (and
their integral) at any times with the interpolant of the step that covers each:

* a step in t (DOPRI5, Rosenbrock): y(t_a + theta h) = y_a + h sum_j Q[:, j] theta^(j+1), its
  integral exact for that polynomial (``events.dense_eval``, ``events.dense_integral``), as the
  rows were written during the run;
* a held equilibrium (``steady``): y = y_a, its integral growing by y_a (t - t_a);
* a step of the Painleve approach in Sundman time sigma (``painleve``): the DOPRI5 dense output of
  z = (t, y, q) in sigma; t(sigma) = t is solved on it by bisection (t grows with sigma while
  D > 0), up to theta_hi, where the step landed on D = 0 or on t_end, in the time left to that
  end (exact in double near it, where v1 - v* ~ sqrt(t* - t) makes every ulp of t count).

At its end t_hi every step gives y_hi, the state the run went on from (an event's, located on
the re-taken step). A time at an event belongs to the step that ends there, the left limit, as
the output rows do; side 1 takes the step that starts there instead: the right limit (after an
impact's jump, in the mode entered).
"""
import numpy as np
from numba import types

from tswm_runtime.integration import events
from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.arrays import copy_into, copy_rows
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import MATRIX, VECTOR
from tswm_runtime.jit.structures import INTS, STEP_LOG, StepLog

T_STEP, HELD, SUNDMAN = 0, 1, 2  # the kinds of step
BISECTIONS = 200  # a bound; bisection on theta stops when the bracket no longer shrinks


@njit(error_model="numpy", refcounted=True)
def no_steps(width, n_params):
    """A StepLog of no rows (it only counts): for runs whose rows are written as they go."""
    return StepLog(np.empty((0, 4)), np.empty((0, 2), np.int64), np.empty((0, width)), np.empty((0, width)),
                   np.empty((0, width + 1, 4)), np.empty(0, np.int64), np.empty((0, n_params)), np.zeros(2, np.int64))


@njit(error_model="numpy")
def _slot(steps, kind, t_a, h, t_hi, theta_hi):
    """The row for the next step, its times and kind written; -1 for a log of no rows. Every step
    is counted, so that the caller sees how many there were; when the log is full, its last row
    takes each further step: a full log always ends with the run's last step (its final state)."""
    k = steps.count[0]
    steps.count[0] = k + 1
    if steps.f.shape[0] == 0:
        return -1
    k = min(k, steps.f.shape[0] - 1)
    steps.f[k, 0], steps.f[k, 1], steps.f[k, 2], steps.f[k, 3] = t_a, h, t_hi, theta_hi
    steps.index[k, 0], steps.index[k, 1] = kind, steps.count[1]
    return k


@njit(error_model="numpy")
def log_step(steps, t_a, h, t_hi, y_a, quad, y_hi, Q):
    """A step in t from (t_a, y_a) with dense output Q, used up to t_hi where the state is y_hi;
    quad: the integral at t_a (size 0: none)."""
    k = _slot(steps, T_STEP, t_a, h, t_hi, (t_hi - t_a) / h)
    if k < 0:
        return
    n = y_a.size
    copy_into(steps.y_a[k, :n], y_a)
    copy_into(steps.y_hi[k, :n], y_hi)
    copy_rows(steps.Q[k, :n], Q)
    if quad.size > 0:
        copy_into(steps.y_a[k, n:], quad)
        end = steps.y_hi[k, n:]
        events.dense_integral(y_a, h, Q, (t_hi - t_a) / h, end)
        for j in range(quad.size):
            end[j] = quad[j] + end[j]


@njit(error_model="numpy")
def log_held(steps, t_a, t_hi, y, quad):
    """The state y held from t_a to t_hi (quad: its integral at t_a)."""
    if not t_hi > t_a:
        return
    k = _slot(steps, HELD, t_a, t_hi - t_a, t_hi, 1.0)
    if k < 0:
        return
    n = y.size
    copy_into(steps.y_a[k, :n], y)
    copy_into(steps.y_hi[k, :n], y)
    for j in range(quad.size):
        steps.y_a[k, n + j] = quad[j]
        steps.y_hi[k, n + j] = quad[j] + y[j] * (t_hi - t_a)


@njit(error_model="numpy")
def log_sundman(steps, z, h, z_hi, Qz, theta_hi):
    """A step of size h in Sundman time from z = (t, y, q) with dense output Qz (one row per
    component of z), used up to theta_hi of it, where z is z_hi."""
    k = _slot(steps, SUNDMAN, z[0], h, z_hi[0], theta_hi)
    if k < 0:
        return
    width = z.size - 1
    copy_into(steps.y_a[k], z[1:])
    copy_into(steps.y_hi[k], z_hi[1:])
    copy_rows(steps.Q[k, :width], Qz[1:])
    copy_into(steps.Q[k, width], Qz[0])


@njit(error_model="numpy")
def end_segment(steps, mode, p):
    """Close the segment whose steps were just logged: its mode and parameter vector."""
    s = steps.count[1]
    steps.count[1] = s + 1
    if s < steps.seg_mode.size:
        steps.seg_mode[s] = mode
        copy_into(steps.seg_p[s], p)


@njit(error_model="numpy")
def _covering(f, n_steps, t, side):
    """The step that covers t: the first that ends at or after it (side 0), the last that starts
    at or before it (side 1); -1 outside [start of the first, end of the last] or for NaN."""
    if n_steps == 0 or not (f[0, 0] <= t <= f[n_steps - 1, 2]):
        return -1
    lo, hi = 0, n_steps - 1
    if side == 0:
        while lo < hi:  # first k with t_hi >= t
            mid = (lo + hi) // 2
            if f[mid, 2] >= t:
                hi = mid
            else:
                lo = mid + 1
        return lo
    while lo < hi:  # last k with t_a <= t
        mid = (lo + hi + 1) // 2
        if f[mid, 0] <= t:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(error_model="numpy")
def _sundman_theta(h, q, theta_hi, left):
    """theta in [0, theta_hi] where the time left to the step's end, t_hi - t(theta) = h (P(theta_hi)
    - P(theta)) with P(theta) = theta (q0 + q1 theta + q2 theta^2 + q3 theta^3), equals ``left``
    (t_hi - t, exact in double near t_hi), by bisection to the resolution of theta. Anchored at the
    end, not at t_a: t_a + h P(theta) is rounded to ulp(t) (7e-18 s at t = 0.04 s), and near D = 0
    (v1 - v* ~ sqrt(t* - t), |a1| ~ 1e8 m/s^2 at 2.7e-16 s before t*) 1.7 ulp of t made 1.1e-9 m/s."""
    end = theta_hi * (q[0] + theta_hi * (q[1] + theta_hi * (q[2] + theta_hi * q[3])))
    lo, hi = 0.0, theta_hi
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if h * (end - mid * (q[0] + mid * (q[1] + mid * (q[2] + mid * q[3])))) > left:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@njit(error_model="numpy")
def _evaluate(steps, k, n, t, out):
    """out = the n states and their integral (out[n:]) at t from step k."""
    t_a, h, t_hi = steps.f[k, 0], steps.f[k, 1], steps.f[k, 2]
    kind, y_a, Q = steps.index[k, 0], steps.y_a[k], steps.Q[k]
    if t == t_hi:
        copy_into(out, steps.y_hi[k])
    elif kind == SUNDMAN:
        width = out.size
        events.dense_eval(y_a, h, Q[:width], _sundman_theta(h, Q[width], steps.f[k, 3], t_hi - t), out)
    elif kind == HELD:
        for j in range(out.size):
            out[j] = y_a[j] if j < n else y_a[j] + y_a[j - n] * (t - t_a)
    else:
        theta = (t - t_a) / h
        events.dense_eval(y_a[:n], h, Q[:n], theta, out[:n])
        if out.size > n:
            events.dense_integral(y_a[:n], h, Q[:n], theta, out[n:])
            for j in range(n, out.size):
                out[j] = y_a[j] + out[j]


STATES_AT_SIG = types.none(STEP_LOG, types.int64, VECTOR, types.int64, MATRIX, INTS)


@cache_guard.compile_cached(STATES_AT_SIG, error_model="numpy", nogil=True)
def states_at(steps, n, t, side, out, segment):
    """out[r] = the n states and their integral at t[r] (NaN outside the steps), segment[r] = the
    segment it lies in (-1 outside), for any times t in any order; side 0: an event's time takes
    its left limit, side 1 its right one. The log must hold every step of the run (count <= capacity)."""
    n_steps = min(steps.count[0], steps.f.shape[0])
    for r in range(t.size):
        k = _covering(steps.f, n_steps, t[r], side)
        if k < 0:
            out[r, :] = np.nan
            segment[r] = -1
        else:
            _evaluate(steps, k, n, t[r], out[r])
            segment[r] = steps.index[k, 1]
