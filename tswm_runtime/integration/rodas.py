"""Hairer-Wanner RODAS4: a stiffly accurate, L-stable Rosenbrock method of order 4(3), nopython.

Source of the formula and all coefficients: E. Hairer, G. Wanner, "Solving Ordinary
Differential Equations II", 2nd ed., Springer 1996, Sec. IV.7 (Table 7.2 and the code
rodas.f, METH = 1), as transcribed in OrdinaryDiffEq.jl
(SciML/OrdinaryDiffEq.jl, lib/OrdinaryDiffEqRosenbrock/src/rosenbrock_tableaus.jl,
``Rodas4Tableau``, with the dense-output coefficients h21..h35 of rodas.f). In rodas.f's
transformed variables, with W = I / (h gamma) - J, J = df/dy(t, y), T = df/dt(t, y):

    W k_i = f(t + c_i h, y + sum_j a_ij k_j) + h d_i T + sum_j (C_ij / h) k_j   (i = 1..6)
    y_new = y + sum_j a_6j k_j + k_6                                    (order 4, L-stable)
    err = k_6                                          (the embedded order-3 solution's error)

Stages 5 and 6 sit at t + h and the solution is the sixth stage's point plus k_6 (stiffly
accurate): one Jacobian, one LU of the n x n W and six rhs calls per step. The steps are
advanced with the 4th-order solution (local extrapolation, as rodas.f), so a step's error
estimate is O(h^4) and the controller treats it as ERROR_ORDER 3. Dense output (rodas.f's
CONTRO, order 3), with K1 = sum_j h2j k_j and K2 = sum_j h3j k_j:

    y(t + s h) = y + s (y_new - y) + s (1 - s) (K1 + s K2)

That interpolant's error is not controlled by k_6: at rtol 1e-3 its rows were up to 27 rtol off
(tools/sample_accuracy.py). ``dense_error`` estimates it from the defect at s = 1/2 (one rhs call),
and the step is judged by the larger of the two estimates, as ``dopri5`` judges its dense output.

The step-size constants are rodas.f's defaults (safety 0.9, h_new / h within [0.2, 6]).
The LU with partial pivoting is ``rosenbrock``'s.
"""
import numpy as np

from tswm_runtime.integration.rosenbrock import lu_factor, lu_solve
from tswm_runtime.jit.cache_guard import njit

N_STAGES = 6
GAMMA = 0.25
# A[i, j] = a_(i+1)(j+1): the stage points (rows 5 and 6: the last two stages both at t + h).
A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1.544, 0.0, 0.0, 0.0, 0.0],
    [0.9466785280815826, 0.2557011698983284, 0.0, 0.0, 0.0],
    [3.314825187068521, 2.896124015972201, 0.9986419139977817, 0.0, 0.0],
    [1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950, 0.0],
    [1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950, 1.0],
])
# C[i, j] = C_(i+1)(j+1): the earlier stages' share in each stage's right-hand side.
C = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [-5.668800000000000, 0.0, 0.0, 0.0, 0.0],
    [-2.430093356833875, -0.2063599157091915, 0.0, 0.0, 0.0],
    [-0.1073529058151375, -9.594562251023355, -20.47028614809616, 0.0, 0.0],
    [7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160, 0.0],
    [8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054],
])
NODES = np.array([0.0, 0.386, 0.21, 0.63, 1.0, 1.0])  # c_i: the stage times t + c_i h
D = np.array([0.25, -0.1043, 0.1035, -0.03620000000000023, 0.0, 0.0])  # d_i: the df/dt terms
# H[r, j]: the dense output's K1 (r = 0) and K2 (r = 1) from k_1..k_5.
H = np.array([
    [10.12623508344586, -7.487995877610167, -34.80091861555747, -7.992771707568823, 1.025137723295662],
    [-0.6762803392801253, 6.087714651680015, 16.43084320892478, 24.76722511418386, -6.594389125716872],
])

# Step-size control: rodas.f's defaults (SAFE = 0.9; 0.2 <= h_new / h <= 6).
SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 6.0
ERROR_ORDER = 3  # The controlled error (k_6) behaves like h^(ERROR_ORDER + 1).


@njit(error_model="numpy")
def stages(rhs, mode, t, y, p, h, f0, J, dfdt, LU, piv, K, y_new):
    """One RODAS4 step from (t, y), f0 = f(t, y): y_new (N_STAGES - 1 rhs calls).

    J, dfdt: Jacobian and df/dt at (t, y). Leaves k_1..k_6 in K[0:6] (K[6] is scratch) for
    ``error_estimate`` and ``dense_coeffs``. A singular W yields a NaN y_new, which the caller's
    error test rejects (the step is then reduced).
    """
    n = y.size
    fac = 1.0 / (h * GAMMA)
    for i in range(n):
        for j in range(n):
            LU[i, j] = -J[i, j]
        LU[i, i] += fac
    if not lu_factor(LU, piv):
        y_new[:] = np.nan
        return
    f = K[N_STAGES]
    for s in range(N_STAGES):
        if s == 0:
            for i in range(n):
                f[i] = f0[i]
        else:
            for i in range(n):
                acc = y[i]
                for j in range(s):
                    acc += A[s, j] * K[j, i]
                y_new[i] = acc
            rhs(mode, t + NODES[s] * h, y_new, p, f)
        k = K[s]
        for i in range(n):
            acc = f[i] + h * D[s] * dfdt[i]
            for j in range(s):
                acc += C[s, j] / h * K[j, i]
            k[i] = acc
        lu_solve(LU, piv, k)
    for i in range(n):
        y_new[i] += K[N_STAGES - 1, i]


@njit(error_model="numpy")
def error_estimate(K, err):
    """err = k_6, the difference of the order-4 and the embedded order-3 solution."""
    for i in range(err.size):
        err[i] = K[N_STAGES - 1, i]


@njit(error_model="numpy")
def dense_error(rhs, mode, t, y, p, h, LU, piv, K, Q, err):
    """err = the dense output's error at s = 1/2, estimated from its defect there,
    d = P'(1/2) - f(t + h/2, P(1/2)): (h/2) (I - h gamma J)^-1 d, that is h/2 d where the solution is
    smooth, damped like the stages where it is stiff (W = I/(h gamma) - J is LU's; 1 rhs call).
    Call after ``dense_coeffs``; K[6], K[7] are scratch."""
    y_m, f_m = K[N_STAGES], K[N_STAGES + 1]
    for i in range(err.size):
        y_m[i] = y[i] + h * (0.5 * Q[i, 0] + 0.25 * Q[i, 1] + 0.125 * Q[i, 2] + 0.0625 * Q[i, 3])
    rhs(mode, t + 0.5 * h, y_m, p, f_m)
    for i in range(err.size):
        err[i] = Q[i, 0] + Q[i, 1] + 0.75 * Q[i, 2] + 0.5 * Q[i, 3] - f_m[i]
    lu_solve(LU, piv, err)  # (I / (h gamma) - J)^-1 d = h gamma (I - h gamma J)^-1 d
    for i in range(err.size):
        err[i] *= 0.5 / GAMMA


@njit(error_model="numpy")
def dense_coeffs(h, y, y_new, K, Q):
    """Coefficients of s^1..s^3 (divided by h) of the dense output y + h sum_j Q[:, j] s^(j+1);
    the s^4 term is zero."""
    for i in range(Q.shape[0]):
        k1 = 0.0
        k2 = 0.0
        for j in range(N_STAGES - 1):
            k1 += H[0, j] * K[j, i]
            k2 += H[1, j] * K[j, i]
        Q[i, 0] = (y_new[i] - y[i] + k1) / h
        Q[i, 1] = (k2 - k1) / h
        Q[i, 2] = -k2 / h
        Q[i, 3] = 0.0
