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

The dense output is 4th order, and its error can be much larger than the step's estimate
(which measures the 4th-order embedded solution and can nearly vanish for the trajectory at
hand: 22 rtol on the paper gear near v1 = 7 m/s at rtol 1e-8, where the step ends were within
1 rtol). ``dense_error`` therefore also estimates the interpolant's error from its defect
p' - f(t, p) at two interior points, and the step is judged by the larger of the two error
norms (where the step's is the larger, the controller is scipy's RK45's).

Step-size control, shared with the Rosenbrock method, is in ``control``; the
constants below are this method's (scipy's ``_ivp/rk.py``).
"""
import numpy as np
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit

# Step-size control (values of scipy's _ivp/rk.py).
SAFETY = 0.9  # Multiply steps computed from the asymptotic error behaviour by this.
MIN_FACTOR = 0.2  # Smallest allowed step decrease after a rejected step.
MAX_FACTOR = 10.0  # Largest allowed step increase after an accepted step.
ERROR_ORDER = 4  # The controlled error behaves like h^(ERROR_ORDER + 1).
N_STAGES = 6  # Stages before the FSAL stage; K has N_STAGES + 1 rows.
# Where the stability region meets the negative real axis, about (Hairer & Wanner's dopri5.f
# stiffness test): a step with h rho > 3.25 is limited by stability, not by accuracy.
STABILITY_LIMIT = 3.25

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


@njit(error_model="numpy")
def stages(rhs, mode, t, y, p, h, K, y_new, y6):
    """One DOPRI5 step without its FSAL stage: y_new = y + h sum_s B_s K_s.

    On entry K[0] = f(t, y); fills K[1..5] (5 rhs calls), y_new, and y6, the state of the
    sixth stage (for ``stiffness``). The caller evaluates K[6] = f(t + h, y_new) when it
    needs the error estimate.
    """
    n = y.size
    for s in range(1, N_STAGES):
        for i in range(n):
            acc = 0.0
            for j in range(s):
                acc += A[s, j] * K[j, i]
            y_new[i] = y[i] + h * acc
        rhs(mode, t + C[s] * h, y_new, p, K[s])
    copy_into(y6, y_new)
    for i in range(n):
        acc = 0.0
        for j in range(N_STAGES):
            acc += B[j] * K[j, i]
        y_new[i] = y[i] + h * acc


@njit(error_model="numpy")
def stiffness(h, K, y_new, y6):
    """h rho, rho = |K[6] - K[5]| / |y_new - y6| (Euclidean): the sixth and seventh stages are
    both at t + h, so rho estimates the largest |eigenvalue| of the Jacobian along the step
    (Hairer & Wanner, "Solving ODEs II", Sec. IV.2; dopri5.f). 0 when the two states agree."""
    num, den = 0.0, 0.0
    for i in range(y6.size):
        num += (K[N_STAGES, i] - K[N_STAGES - 1, i]) ** 2
        den += (y_new[i] - y6[i]) ** 2
    return h * np.sqrt(num / den) if den > 0.0 else 0.0


@njit(error_model="numpy")
def error_estimate(h, K, err):
    """err = h K^T E: 5th- minus 4th-order solution; needs K[6] = f(t + h, y_new)."""
    for i in range(err.size):
        acc = 0.0
        for s in range(N_STAGES + 1):
            acc += E[s] * K[s, i]
        err[i] = h * acc


@njit(error_model="numpy")
def dense_coeffs(K, Q):
    """Q = K^T P: coefficients of theta^1..theta^4 of the continuous extension."""
    for i in range(Q.shape[0]):
        for j in range(4):
            acc = 0.0
            for s in range(N_STAGES + 1):
                acc += K[s, i] * P[s, j]
            Q[i, j] = acc


DEFECT_THETAS = (1.0 / 3.0, 2.0 / 3.0)  # where the dense output's defect is sampled
# The interpolant's error is about DEFECT_WEIGHT h max |defect| (e' = h (defect + J e), e(0) = 0):
# 1.4 to 1.9 times the true largest error with 0.5 on the harmonic oscillator and the paper gear
# (steps of 1e-3 to 4e-3 s, where the step's estimate was up to 9 times too small for it).
DEFECT_WEIGHT = 0.35


@njit(error_model="numpy")
def dense_error(rhs, mode, t, y, p, h, K, Q, est):
    """est = the estimated error of the dense output Q, per component.

    At theta in DEFECT_THETAS: defect = p'(theta) - f(t + theta h, p(theta)) of the interpolant
    p (it vanishes at both ends); est = DEFECT_WEIGHT h max |defect|. After ``dense_coeffs``:
    uses K[1] and K[2] as scratch; 2 rhs calls.
    """
    y_theta, f_theta = K[1], K[2]
    est[:] = 0.0
    for theta in DEFECT_THETAS:
        for i in range(y.size):
            poly = Q[i, 3]
            for j in range(2, -1, -1):
                poly = poly * theta + Q[i, j]
            y_theta[i] = y[i] + h * theta * poly
        rhs(mode, t + theta * h, y_theta, p, f_theta)
        for i in range(y.size):
            slope = Q[i, 0] + theta * (2.0 * Q[i, 1] + theta * (3.0 * Q[i, 2] + theta * 4.0 * Q[i, 3]))
            est[i] = max(est[i], DEFECT_WEIGHT * h * abs(slope - f_theta[i]))
