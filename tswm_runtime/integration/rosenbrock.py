"""Shampine-Reichelt modified Rosenbrock triple ROS2(3) (MATLAB's ode23s), nopython.

Source of the formula and all coefficients: L. F. Shampine, M. W. Reichelt, "The
MATLAB ODE Suite", SIAM J. Sci. Comput. 18(1) (1997) 1-22, Sec. 3, and its
implementation ode23s.m / ntrp23s.m. With W = I - h d J, J = df/dy(t, y),
T = df/dt(t, y), d = 1/(2 + sqrt 2), e32 = 6 + sqrt 2:

    k1 = W^-1 (f(t, y) + h d T)
    F1 = f(t + h/2, y + h/2 k1)
    k2 = W^-1 (F1 - k1) + k1
    y_new = y + h k2                                        (order 2, L-stable)
    F2 = f(t + h, y_new)                                    (FSAL: reused next step)
    k3 = W^-1 (F2 - e32 (k2 - F1) - 2 (k1 - f(t, y)) + h d T)
    err = h/6 (k1 - 2 k2 + k3)                              (3rd-order estimate)

Why this method: the paper being reproduced integrated with ode23s; the formula
is L-stable, needs one Jacobian and one LU per step, re-uses its last stage (FSAL)
and comes with a free interpolant. It is a W-method: the solution keeps order 2
with an inexact J (tested), only the error estimate and stiff stability suffer. RODAS4 (order 4) would be cheaper at tight
tolerances but is not what the paper's numbers were computed with. The steps are
advanced with the 2nd-order solution (no local extrapolation), so the controller
treats the error as O(h^3). Dense output (same paper, ntrp23s.m):

    y(t + s h) = y + h (s (1 - s) k1 + s (s - 2 d) k2) / (1 - 2 d)

Step-size control uses ode23s's constants (safety 0.8, decrease at most 0.5x,
increase at most 5x) with the elementary controller shared with DOPRI5. The n x n
systems (n <= 4) are solved with the small LU with partial pivoting below.
"""
import numpy as np
from tswm_runtime.jit.cache_guard import njit

D = 1.0 / (2.0 + np.sqrt(2.0))  # Diagonal coefficient gamma of the W-method.
E32 = 6.0 + np.sqrt(2.0)  # Coefficient of (k2 - F1) in the error stage.

# Step-size control (values of MATLAB's ode23s).
SAFETY = 0.8  # ode23s: h_new = h / (1.25 (err/rtol)^(1/3)).
MIN_FACTOR = 0.5  # Smallest allowed step decrease after a rejected step.
MAX_FACTOR = 5.0  # Largest allowed step increase after an accepted step.
ERROR_ORDER = 2  # The controlled error behaves like h^(ERROR_ORDER + 1).
# Below this rtol a step's error is held to rtol (rtol / PROPORTIONAL_RTOL)^(1/2)
# (control.proportional_tolerance): the 2nd-order solution's global error, ~0.2-0.4 rtol^(2/3)
# on the paper gear when each step is held to rtol (up to 382 rtol at rtol 1e-9), stays within
# about 4 rtol at every rtol (tools/sample_accuracy.py), for about rtol^(-1/6) / 3 times the steps.
PROPORTIONAL_RTOL = 1e-3
# ... but never below 1e-12 (reached at rtol 1e-9): the steps grow like (step tolerance)^(-1/3),
# 70,000 on the load-schedule scene at rtol 1e-9, and would pass the default max_steps (100,000)
# at rtol 1e-10. Below rtol 1e-9 the rows' error therefore grows like 1e-8 / rtol (in units of rtol).
STEP_RTOL_FLOOR = 1e-12


@njit(error_model="numpy")
def lu_factor(A, piv):
    """In-place LU factorisation with partial pivoting (Doolittle, row swaps in piv).

    Returns False if a pivot is exactly zero (singular matrix); A is then garbage.
    """
    n = A.shape[0]
    for c in range(n):
        r = c
        for i in range(c + 1, n):
            if abs(A[i, c]) > abs(A[r, c]):
                r = i
        piv[c] = r
        if A[r, c] == 0.0:
            return False
        if r != c:
            for j in range(n):
                A[c, j], A[r, j] = A[r, j], A[c, j]
        for i in range(c + 1, n):
            A[i, c] /= A[c, c]
            for j in range(c + 1, n):
                A[i, j] -= A[i, c] * A[c, j]
    return True


@njit(error_model="numpy")
def lu_solve(LU, piv, b):
    """Solve A x = b in place (b becomes x) from ``lu_factor``'s output."""
    n = b.size
    for c in range(n):
        r = piv[c]
        if r != c:
            b[c], b[r] = b[r], b[c]
    for i in range(n):
        for j in range(i):
            b[i] -= LU[i, j] * b[j]
    for i in range(n - 1, -1, -1):
        for j in range(i + 1, n):
            b[i] -= LU[i, j] * b[j]
        b[i] /= LU[i, i]


@njit(error_model="numpy")
def stages(rhs, mode, t, y, p, h, f0, J, dfdt, LU, piv, K, y_new):
    """One ode23s step without its error stage: y_new = y + h k2 (1 rhs call).

    J, dfdt: Jacobian and df/dt at (t, y). Leaves LU = W(h), K[0] = k1, K[1] = k2,
    K[2] = F1 for ``error_estimate`` and ``dense_coeffs``. A singular W yields a
    NaN y_new, which the caller's error test rejects (the step is then reduced).
    """
    n = y.size
    for i in range(n):
        for j in range(n):
            LU[i, j] = -h * D * J[i, j]
        LU[i, i] += 1.0
    if not lu_factor(LU, piv):
        y_new[:] = np.nan
        return
    k1, k2, f1 = K[0], K[1], K[2]
    for i in range(n):
        k1[i] = f0[i] + h * D * dfdt[i]
    lu_solve(LU, piv, k1)
    for i in range(n):
        y_new[i] = y[i] + 0.5 * h * k1[i]
    rhs(mode, t + 0.5 * h, y_new, p, f1)
    for i in range(n):
        k2[i] = f1[i] - k1[i]
    lu_solve(LU, piv, k2)
    for i in range(n):
        k2[i] += k1[i]
        y_new[i] = y[i] + h * k2[i]


@njit(error_model="numpy")
def error_estimate(h, f0, f_new, dfdt, LU, piv, K, err):
    """err = h/6 (k1 - 2 k2 + k3) after ``stages`` with the same h; f_new = F2."""
    k1, k2, f1, k3 = K[0], K[1], K[2], K[3]
    for i in range(err.size):
        k3[i] = f_new[i] - E32 * (k2[i] - f1[i]) - 2.0 * (k1[i] - f0[i]) + h * D * dfdt[i]
    lu_solve(LU, piv, k3)
    for i in range(err.size):
        err[i] = h / 6.0 * (k1[i] - 2.0 * k2[i] + k3[i])


@njit(error_model="numpy")
def dense_coeffs(K, Q):
    """Coefficients of s^1, s^2 of the ntrp23s interpolant; s^3, s^4 terms are zero."""
    k1, k2 = K[0], K[1]
    for i in range(Q.shape[0]):
        Q[i, 0] = (k1[i] - 2.0 * D * k2[i]) / (1.0 - 2.0 * D)
        Q[i, 1] = (k2[i] - k1[i]) / (1.0 - 2.0 * D)
        Q[i, 2] = 0.0
        Q[i, 3] = 0.0
