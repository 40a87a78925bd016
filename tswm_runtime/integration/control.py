"""Step-size control shared by both methods: error norm, step factor, initial step, and the
spectral radius the auto method's switch back to the explicit method is judged by.

The elementary controller of scipy's ``_ivp/rk.py`` (``step_factor``), scipy's RMS
error norm, and Hairer's initial step selection ("Solving ODEs I", Sec. II.4, as
scipy's ``select_initial_step``). Each method module gives its own constants (error
order, safety, smallest and largest step factor). ``segment.run`` takes the smaller of
the elementary factor and two corrections (issue 13: a fifth of all step attempts were
rejected):

* ``predictive_factor``, after an accepted step: Gustafsson's predictive controller, as
  RADAU5 uses it ("Solving ODEs II", Sec. IV.8). Where the steps shrink step after step
  (v1 running down to rest: the error scale rtol |v1| shrinks with it) the elementary
  controller proposes the last accepted step again, which fails, in turn with every
  accepted one; the predictive factor follows the trend.
* ``observed_order_factor``, after a second rejection at the same t: the order the error
  showed between the two tries. At a kink of the right-hand side (the friction law at
  v1 = 0) the error falls like h, not like h^(q+1), and the elementary controller's cuts
  by 0.7 are rejected up to seven times in a row.
"""
import numpy as np
from tswm_runtime.jit.arrays import copy_rows
from tswm_runtime.jit.cache_guard import njit

# Hairer's initial step selection (Sec. II.4): thresholds of scipy's common.py.
H0_TINY_NORM = 1e-5  # ||y0|| or ||f0|| (scaled) below this: start from H0_FALLBACK.
H0_FALLBACK = 1e-6  # First trial step when the scaled norms carry no information.
H0_TINY_DERIV = 1e-15  # ||f0|| and ||f'|| both below this: h = max(1e-6, 1e-3 h0).
H0_FRACTION = 0.01  # Target: first step changes y by ~1% of its scale.
H0_GROWTH = 100.0  # The initial step is at most 100 times the trial step.


@njit(error_model="numpy")
def error_norm(err, y, y_new, atol, rtol):
    """RMS norm of err_i / (atol_i + rtol * max(|y_i|, |y_new_i|)) (scipy's convention)."""
    s = 0.0
    for i in range(err.size):
        scale = atol[i] + rtol * max(abs(y[i]), abs(y_new[i]))
        s += (err[i] / scale) ** 2
    return np.sqrt(s / err.size)


@njit(error_model="numpy")
def step_factor(err, error_order, safety, min_factor, max_factor):
    """Elementary controller: h_new / h = safety * err^(-1/(q+1)), clipped.

    q is the order of the error estimator; a non-finite err gives ``min_factor``.
    """
    if err == 0.0:
        return max_factor
    if not np.isfinite(err):
        return min_factor
    return min(max_factor, max(min_factor, safety * err ** (-1.0 / (error_order + 1))))


@njit(error_model="numpy")
def _scaled_rms(x, y0, atol, rtol):
    s = 0.0
    for i in range(x.size):
        s += (x[i] / (atol[i] + rtol * abs(y0[i]))) ** 2
    return np.sqrt(s / x.size)


@njit(error_model="numpy")
def select_initial_step(rhs, mode, t0, y0, p, f0, t_end, hmax, error_order, rtol, atol, y1, f1):
    """Hairer's initial step ("Solving ODEs I", Sec. II.4; scipy's select_initial_step).

    One trial Euler step of size h0 ~ 0.01 ||y0|| / ||f0|| estimates ||f'||; the
    step is then chosen so that the leading error term h^(q+1) max(||f0||, ||f'||)
    is about 0.01. Makes exactly one rhs call; y1 and f1 are work arrays.
    """
    interval = t_end - t0
    d0 = _scaled_rms(y0, y0, atol, rtol)
    d1 = _scaled_rms(f0, y0, atol, rtol)
    if d0 < H0_TINY_NORM or d1 < H0_TINY_NORM:
        h0 = H0_FALLBACK
    else:
        h0 = H0_FRACTION * d0 / d1
    h0 = min(h0, interval)
    for i in range(y0.size):
        y1[i] = y0[i] + h0 * f0[i]
    rhs(mode, t0 + h0, y1, p, f1)
    for i in range(y0.size):
        f1[i] = f1[i] - f0[i]
    d2 = _scaled_rms(f1, y0, atol, rtol) / h0
    if d1 <= H0_TINY_DERIV and d2 <= H0_TINY_DERIV:
        h1 = max(H0_FALLBACK, h0 * 1e-3)
    else:
        h1 = (H0_FRACTION / max(d1, d2)) ** (1.0 / (error_order + 1))
    return min(H0_GROWTH * h0, h1, interval, hmax)


@njit(error_model="numpy")
def proportional_tolerance(rtol, order, corner, floor):
    """The fraction of the tolerance a step's error is held to, so that the global error of a
    method of this order that is advanced without local extrapolation stays about proportional
    to rtol (tolerance proportionality): (rtol / corner)^(1/order) below ``corner``, else 1;
    never below floor / rtol (a step's relative error is not held below ``floor``).

    Held to tau per step, such a method takes ~tau^(-1/(order+1)) steps and its global error
    grows like tau^(order/(order+1)): relative to rtol, like rtol^(-1/(order+1)). With tau =
    rtol (rtol / corner)^(1/order) it is about what it is at rtol = corner, at every rtol.
    """
    return min(1.0, max((rtol / corner) ** (1.0 / order), floor / rtol))


OBSERVED_SAFETY = 0.8  # after a repeated rejection, aim at err = 0.8 ...
OBSERVED_MIN_FACTOR = 0.05  # ... cutting the step by at most 20x
PREDICTIVE_SAFETY = 0.9
PREDICTIVE_MIN_ERR = 1e-2  # RADAU5's floor on the previous step's error


@njit(error_model="numpy")
def observed_order_factor(err, order):
    """Step factor after a second rejection at the same t, for err ~ h^order as the two tries
    showed (order taken as at least 1)."""
    return max(OBSERVED_MIN_FACTOR, OBSERVED_SAFETY * err ** (-1.0 / max(order, 1.0)))


@njit(error_model="numpy")
def predictive_factor(h, err, h_prev, err_prev, error_order):
    """Gustafsson's predictive step factor after an accepted step h with error err, the one
    before being h_prev with err_prev: safety (h / h_prev) (err_prev / err^2)^(1/(q+1))."""
    return PREDICTIVE_SAFETY * (h / h_prev) * (err_prev / (err * err)) ** (1.0 / (error_order + 1))


SPECTRAL_SQUARINGS = 5  # spectral_radius: ||J^32||^(1/32)


@njit(error_model="numpy")
def spectral_radius(J, A, B):
    """An upper bound of the spectral radius of J: ||J^k||_inf^(1/k), k = 2^SPECTRAL_SQUARINGS
    (Gelfand's formula; within a factor cond(V)^(1/k) of it for diagonalisable J = V D V^-1: far
    closer than ||J|| itself where the states have mixed units). A and B: n x n scratch."""
    copy_rows(A, J)
    log_rho = 0.0
    for k in range(SPECTRAL_SQUARINGS + 1):
        norm = 0.0
        for i in range(A.shape[0]):  # rows summed by hand: np.sum would tie the cached kernels to numba's
            row = 0.0                # array-math module, whose import pulls in scipy.linalg (a warm start)
            for j in range(A.shape[1]):
                row += abs(A[i, j])
            norm = max(norm, row)
        if norm == 0.0 or not np.isfinite(norm):
            return norm
        log_rho += np.log(norm) / 2.0 ** k
        if k == SPECTRAL_SQUARINGS:
            break
        n = A.shape[0]
        for i in range(n):  # B = (A / norm)^2, A = B
            for j in range(n):
                acc = 0.0
                for m in range(n):
                    acc += A[i, m] * A[m, j]
                B[i, j] = acc / (norm * norm)
        copy_rows(A, B)
    return np.exp(log_rho)
