"""Dormand-Prince 5(4) explicit Runge-Kutta method, nopython building blocks.

Tableau: J. R. Dormand, P. J. Prince, "A family of embedded Runge-Kutta formulae",
J. Comput. Appl. Math. 6 (1980) 19-26; seven stages with FSAL (the last stage is
f(t + h, y_new) and serves as the first stage of the next step). The step is
advanced with the 5th-order formula (local extrapolation) and the error estimate
is that of the embedded 4th-order formula, so the controller treats the error as
O(h^5) ("error estimator order" 4), exactly as scipy's ``RK45``.

Dense output: the 4th-order continuous extension of Hairer, Norsett & Wanner,
"Solving ODEs I", Sec. II.6, in the form of scipy's ``RK45.P`` matrix (L. F.
Shampine, "Some practical Runge-Kutta formulas", Math. Comp. 46 (1986) 135-150,
optimum c6): y(t + theta h) = y + h * sum_j Q[:, j] theta^(j+1) with Q = K^T P.

Step-size control is the elementary controller of scipy's ``_ivp/rk.py`` with its
constants (``step_factor``); the initial step is Hairer's algorithm
(``select_initial_step``, "Solving ODEs I", Sec. II.4, as scipy's
``select_initial_step``). These two and ``error_norm`` are shared with the
Rosenbrock method.
"""
import numpy as np
from numba import njit

# Step-size control (values of scipy's _ivp/rk.py).
SAFETY = 0.9  # Multiply steps computed from the asymptotic error behaviour by this.
MIN_FACTOR = 0.2  # Smallest allowed step decrease after a rejected step.
MAX_FACTOR = 10.0  # Largest allowed step increase after an accepted step.
ERROR_ORDER = 4  # The controlled error behaves like h^(ERROR_ORDER + 1).
N_STAGES = 6  # Stages before the FSAL stage; K has N_STAGES + 1 rows.

# Hairer's initial step selection (Sec. II.4): thresholds of scipy's common.py.
H0_TINY_NORM = 1e-5  # ||y0|| or ||f0|| (scaled) below this: start from H0_FALLBACK.
H0_FALLBACK = 1e-6  # First trial step when the scaled norms carry no information.
H0_TINY_DERIV = 1e-15  # ||f0|| and ||f'|| both below this: h = max(1e-6, 1e-3 h0).
H0_FRACTION = 0.01  # Target: first step changes y by ~1% of its scale.
H0_GROWTH = 100.0  # The initial step is at most 100 times the trial step.

C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0])
A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
])
B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
# E = (5th-order weights) - (4th-order weights), with the FSAL stage as 7th column.
E = np.array([-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40])
P = np.array([
    [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
    [0.0, 0.0, 0.0, 0.0],
    [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
    [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
    [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
    [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
    [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
])


@njit(cache=True, error_model="numpy")
def error_norm(err, y, y_new, atol, rtol):
    """RMS norm of err_i / (atol_i + rtol * max(|y_i|, |y_new_i|)) (scipy's convention)."""
    s = 0.0
    for i in range(err.size):
        scale = atol[i] + rtol * max(abs(y[i]), abs(y_new[i]))
        s += (err[i] / scale) ** 2
    return np.sqrt(s / err.size)


@njit(cache=True, error_model="numpy")
def step_factor(err, error_order, safety, min_factor, max_factor):
    """Elementary controller: h_new / h = safety * err^(-1/(q+1)), clipped.

    q is the order of the error estimator; a non-finite err gives ``min_factor``.
    """
    if err == 0.0:
        return max_factor
    if not np.isfinite(err):
        return min_factor
    return min(max_factor, max(min_factor, safety * err ** (-1.0 / (error_order + 1))))


@njit(cache=True, error_model="numpy")
def _scaled_rms(x, y0, atol, rtol):
    s = 0.0
    for i in range(x.size):
        s += (x[i] / (atol[i] + rtol * abs(y0[i]))) ** 2
    return np.sqrt(s / x.size)


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def stages(rhs, mode, t, y, p, h, K, y_new):
    """One DOPRI5 step without its FSAL stage: y_new = y + h sum_s B_s K_s.

    On entry K[0] = f(t, y); fills K[1..5] (5 rhs calls) and y_new. The caller
    evaluates K[6] = f(t + h, y_new) when it needs the error estimate.
    """
    n = y.size
    for s in range(1, N_STAGES):
        for i in range(n):
            acc = 0.0
            for j in range(s):
                acc += A[s, j] * K[j, i]
            y_new[i] = y[i] + h * acc
        rhs(mode, t + C[s] * h, y_new, p, K[s])
    for i in range(n):
        acc = 0.0
        for j in range(N_STAGES):
            acc += B[j] * K[j, i]
        y_new[i] = y[i] + h * acc


@njit(cache=True, error_model="numpy")
def error_estimate(h, K, err):
    """err = h K^T E: 5th- minus 4th-order solution; needs K[6] = f(t + h, y_new)."""
    for i in range(err.size):
        acc = 0.0
        for s in range(N_STAGES + 1):
            acc += E[s] * K[s, i]
        err[i] = h * acc


@njit(cache=True, error_model="numpy")
def dense_coeffs(K, Q):
    """Q = K^T P: coefficients of theta^1..theta^4 of the continuous extension."""
    for i in range(Q.shape[0]):
        for j in range(4):
            acc = 0.0
            for s in range(N_STAGES + 1):
                acc += K[s, i] * P[s, j]
            Q[i, j] = acc
