"""RODAS4 (``integration.rodas``): its order, its dense output and its stiff stability against
closed forms, and whole runs against the references of the hard cases.

The test problem, y0' = -L (y0 - sin t) + cos t, y1' = y0 y1, is non-autonomous (df/dt
enters every stage) and nonlinear, with the closed form y0 = sin t + y0(0) e^(-L t),
y1 = y1(0) exp(1 - cos t + y0(0) (1 - e^(-L t)) / L).
"""
import math

import numpy as np
import pytest
from numba import njit

from tswm_runtime.integration import rodas
from tswm_runtime.jit.signatures import JAC_SIG, RHS_SIG

Y0 = np.array([1.0, 1.0])


@njit(RHS_SIG, cache=True)
def _rhs(mode, t, y, p, dy):
    dy[0] = -p[0] * (y[0] - math.sin(t)) + math.cos(t)
    dy[1] = y[0] * y[1]


@njit(JAC_SIG, cache=True)
def _jac(mode, t, y, p, J, dfdt):
    J[0, 0], J[0, 1] = -p[0], 0.0
    J[1, 0], J[1, 1] = y[1], y[0]
    dfdt[0] = p[0] * math.cos(t) - math.sin(t)
    dfdt[1] = 0.0


def _exact(t, L):
    decay = math.exp(-L * t)
    return np.array([math.sin(t) + Y0[0] * decay, Y0[1] * math.exp(1.0 - math.cos(t) + Y0[0] * (1.0 - decay) / L)])


@njit
def _fixed_steps(t_end, n_steps, y0, p):
    """n_steps RODAS4 steps of equal size from (0, y0) to t_end; the last step's start, dense
    output Q, error estimate and dense output's error estimate."""
    n = y0.size
    K, LU, piv = np.zeros((8, n)), np.empty((n, n)), np.empty(n, np.int64)
    J, dfdt, f0, Q = np.empty((n, n)), np.empty(n), np.empty(n), np.zeros((n, 4))
    y, y_new, err, err_dense = y0.copy(), np.empty(n), np.empty(n), np.empty(n)
    h = t_end / n_steps
    y_a = y.copy()
    for m in range(n_steps):
        t = m * h
        y_a[:] = y
        _rhs(0, t, y, p, f0)
        _jac(0, t, y, p, J, dfdt)
        rodas.stages(_rhs, 0, t, y, p, h, f0, J, dfdt, LU, piv, K, y_new)
        rodas.error_estimate(K, err)
        rodas.dense_coeffs(h, y, y_new, K, Q)
        rodas.dense_error(_rhs, 0, t, y, p, h, LU, piv, K, Q, err_dense)
        y[:] = y_new
    return y, y_a, Q, err, err_dense


def _slope(hs, errors):
    return np.polyfit(np.log(hs), np.log(errors), 1)[0]


@pytest.mark.heavy
def test_rodas4_converges_with_order_4():
    """Global error at t = 1 of fixed steps h = 1/10 .. 1/80 (L = 2, not stiff): slope 4 in log-log
    (3.8 to 4.3; measured 4.11, the ratios 18.0, 17.1, 16.6 falling to 16); a sign error in any d_i or C_ij coefficient drops it to 1 to 3."""
    L, ns = 2.0, [10, 20, 40, 80]
    errors = [np.max(np.abs(_fixed_steps(1.0, n, Y0, np.array([L]))[0] - _exact(1.0, L))) for n in ns]
    assert 3.8 <= _slope(1.0 / np.array(ns), errors) <= 4.3, errors


@pytest.mark.heavy
def test_the_error_estimate_and_the_dense_output_are_of_order_3():
    """One step of size h from the exact state: k_6 (the estimate) falls like h^4 and so does the
    dense output's largest error inside the step (order 3: slope 4, 3.8 to 4.3)."""
    L, hs = 2.0, np.array([0.2, 0.1, 0.05, 0.025])
    est, dense = [], []
    for h in hs:
        y, y_a, Q, err, _ = _fixed_steps(h, 1, Y0, np.array([L]))
        est.append(np.max(np.abs(err)))
        worst = 0.0
        for s in np.linspace(0.05, 0.95, 19):
            approx = y_a + h * (Q[:, 0] * s + Q[:, 1] * s**2 + Q[:, 2] * s**3 + Q[:, 3] * s**4)
            worst = max(worst, np.max(np.abs(approx - _exact(s * h, L))))
        dense.append(worst)
    assert 3.8 <= _slope(hs, est) <= 4.3, est
    assert 3.8 <= _slope(hs, dense) <= 4.3, dense


def test_rodas4_is_stable_and_accurate_far_beyond_the_explicit_limit():
    """L = 1e6, h = 0.01 (h L = 1e4): L-stable, the fast transient is damped in one step and the
    slow solution followed to 1e-6 at t = 1 (an explicit method would blow up)."""
    L = 1e6
    y = _fixed_steps(1.0, 100, Y0, np.array([L]))[0]
    assert np.max(np.abs(y - _exact(1.0, L))) < 1e-6


def _dense(y_a, h, Q, s):
    return y_a + h * (Q[:, 0] * s + Q[:, 1] * s**2 + Q[:, 2] * s**3 + Q[:, 3] * s**4)


@pytest.mark.parametrize("L", [2.0, 1e3])
def test_the_dense_error_estimate_follows_the_dense_outputs_error(L):
    """One step from the exact state: the defect estimate at s = 1/2 (``dense_error``) against the
    dense output's true error there, component by component from 0.5 to 8 times it (measured 1.0 to
    6.2: it errs on the safe side), for a smooth (L = 2) and a stiff decay (L = 1e3, h L 50 to 200,
    the transient not resolved: errors of 0.2)."""
    for h in (0.2, 0.1, 0.05):
        y, y_a, Q, err, err_dense = _fixed_steps(h, 1, Y0, np.array([L]))
        true = np.abs(_dense(y_a, h, Q, 0.5) - _exact(0.5 * h, L))
        for i in range(2):
            if true[i] > 1e-13:
                assert 0.5 <= abs(err_dense[i]) / true[i] <= 8.0, (h, i, err_dense, true)
