"""Integrators, dense output and event location of tswm_runtime on closed-form ODEs.

The test models are compiled with the contract's signatures (as generated modules
are) and passed to the one cached ``integrate_segment``.
"""
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st
# numba's type of a first-class function value (attempt_function) is registered by this module: with
# every kernel loaded from the cache nothing else imports it, and integrate_segment got a pyobject
import numba.experimental.function_type  # noqa: F401
from numba import njit
from scipy.integrate import RK45, solve_ivp

from tswm_runtime.integration import events as ev
from tswm_runtime.integration import rosenbrock as ros
from tswm_runtime.integration import segment as seg
from tswm_runtime.integration.single import integrate_segment
from tswm_runtime.jit.signatures import GUARDS_SIG, JAC_SIG, RHS_SIG
from tswm_runtime.jit.structures import EventSettings, Tolerances

METHODS = [seg.DOPRI5, seg.ROSENBROCK23]
METHOD_IDS = ["dopri5", "rosenbrock23"]
# Global relative error expected at rtol = 1e-9: ode23s is of order 2 without local
# extrapolation, so its global error is about (number of steps) x rtol.
ACCURACY = {seg.DOPRI5: 1e-7, seg.ROSENBROCK23: 1e-5}


# --- models -------------------------------------------------------------------------

@njit(RHS_SIG, cache=True)
def osc_rhs(mode, t, y, p, dy):
    dy[0] = y[1]
    dy[1] = -y[0]


@njit(JAC_SIG, cache=True)
def osc_jac(mode, t, y, p, J, dfdt):
    J[0, 0], J[0, 1], J[1, 0], J[1, 1] = 0.0, 1.0, -1.0, 0.0
    dfdt[:] = 0.0


@njit(GUARDS_SIG, cache=True)
def osc_guards(mode, t, y, p, g):
    g[0] = y[0]  # cos t: falls at pi/2, rises at 3 pi/2


@njit(RHS_SIG, cache=True)
def decay_rhs(mode, t, y, p, dy):
    dy[0] = -p[0] * y[0]


@njit(JAC_SIG, cache=True)
def decay_jac(mode, t, y, p, J, dfdt):
    J[0, 0] = -p[0]
    dfdt[0] = 0.0


@njit(RHS_SIG, cache=True)
def square_rhs(mode, t, y, p, dy):
    dy[0] = t * t


@njit(JAC_SIG, cache=True)
def square_jac(mode, t, y, p, J, dfdt):
    J[0, 0] = 0.0
    dfdt[0] = 2.0 * t


@njit(RHS_SIG, cache=True)
def stiff_rhs(mode, t, y, p, dy):
    # Eigenvalues -1 (y0 + y1) and -1000 (y0 - y1); y2 follows cos t at rate 1000.
    dy[0] = -500.5 * y[0] + 499.5 * y[1]
    dy[1] = 499.5 * y[0] - 500.5 * y[1]
    dy[2] = -1000.0 * (y[2] - math.cos(t)) - math.sin(t)


@njit(JAC_SIG, cache=True)
def stiff_jac(mode, t, y, p, J, dfdt):
    J[:, :] = 0.0
    J[0, 0], J[0, 1], J[1, 0], J[1, 1] = -500.5, 499.5, 499.5, -500.5
    J[2, 2] = -1000.0
    dfdt[0], dfdt[1] = 0.0, 0.0
    dfdt[2] = -1000.0 * math.sin(t) - math.cos(t)


@njit(JAC_SIG, cache=True)
def stiff_jac_no_dfdt(mode, t, y, p, J, dfdt):
    stiff_jac(mode, t, y, p, J, dfdt)
    dfdt[:] = 0.0


@njit(RHS_SIG, cache=True)
def vdp_rhs(mode, t, y, p, dy):
    dy[0] = y[1]
    dy[1] = p[0] * (1.0 - y[0] * y[0]) * y[1] - y[0]


@njit(JAC_SIG, cache=True)
def vdp_jac(mode, t, y, p, J, dfdt):
    J[0, 0], J[0, 1] = 0.0, 1.0
    J[1, 0] = -2.0 * p[0] * y[0] * y[1] - 1.0
    J[1, 1] = p[0] * (1.0 - y[0] * y[0])
    dfdt[:] = 0.0


@njit(RHS_SIG, cache=True)
def blowup_rhs(mode, t, y, p, dy):
    dy[0] = y[0] * y[0]


@njit(JAC_SIG, cache=True)
def blowup_jac(mode, t, y, p, J, dfdt):
    J[0, 0] = 2.0 * y[0]
    dfdt[0] = 0.0


@njit(RHS_SIG, cache=True)
def unit_rhs(mode, t, y, p, dy):
    dy[0] = 1.0  # y = y0 + t - t0, exact for both methods and their dense output


@njit(JAC_SIG, cache=True)
def unit_jac(mode, t, y, p, J, dfdt):
    J[0, 0] = 0.0
    dfdt[0] = 0.0


# Guard sets of the unit-speed model, selected by mode.
TWO_ROOTS, GRAZING, CLOCK, ZERO_AT_START, COSINE = 0, 1, 2, 3, 4


@njit(GUARDS_SIG, cache=True)
def unit_guards(mode, t, y, p, g):
    if mode == TWO_ROOTS:
        g[0] = (y[0] - p[0]) * (y[0] - p[1])
    elif mode == GRAZING:
        g[0] = (y[0] - p[0]) ** 2
    elif mode == CLOCK:
        g[0] = t - p[0]
    elif mode == ZERO_AT_START:
        g[0] = y[0]
    else:
        g[0] = math.cos(y[0])


OSC = SimpleNamespace(rhs=osc_rhs, jac=osc_jac, guards=osc_guards)
DECAY = SimpleNamespace(rhs=decay_rhs, jac=decay_jac, guards=osc_guards)
SQUARE = SimpleNamespace(rhs=square_rhs, jac=square_jac, guards=osc_guards)
STIFF = SimpleNamespace(rhs=stiff_rhs, jac=stiff_jac, guards=osc_guards)
VDP = SimpleNamespace(rhs=vdp_rhs, jac=vdp_jac, guards=osc_guards)
BLOWUP = SimpleNamespace(rhs=blowup_rhs, jac=blowup_jac, guards=osc_guards)
UNIT = SimpleNamespace(rhs=unit_rhs, jac=unit_jac, guards=unit_guards)


def run(method, model, y0, t_end, t0=0.0, rtol=1e-8, atol=None, h0=0.0, hmin=0.0,
        hmax=np.inf, max_steps=10**6, directions=(), gtol=0.0, ttol=0.0, t_out=(), mode=0,
        p=(0.0,)):
    """integrate_segment with defaults; returns its results as a namespace."""
    y0 = np.array(y0, dtype=np.float64)
    atol = np.full(y0.size, rtol if atol is None else atol)
    t_out = np.array(t_out, dtype=np.float64)
    y_out = np.full((t_out.size, y0.size), np.nan)
    y = np.empty_like(y0)
    counters = np.zeros(seg.N_COUNTERS, np.int64)
    status, t, k, n_out, h = integrate_segment(
        method, seg.attempt_function(method), model.rhs, model.jac, model.guards, mode, np.array(p, dtype=np.float64),
        t0, y0, t_end, Tolerances(rtol, atol, hmin, hmax), max_steps, h0,
        EventSettings(np.array(directions, dtype=np.int64), gtol, ttol, False, -1, False), t_out, 0, y_out, y, counters)
    return SimpleNamespace(status=status, t=t, k=k, n_out=n_out, h=h, y=y, y_out=y_out,
                           steps=counters[seg.N_STEPS], rejected=counters[seg.N_REJECTED],
                           nrhs=counters[seg.N_RHS], njac=counters[seg.N_JAC])


def osc_exact(t):
    return np.array([np.cos(t), -np.sin(t)])


def slope(x, y):
    return np.polyfit(np.log(x), np.log(y), 1)[0]


# --- closed-form solutions ------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_exponential_decay(method):
    r = run(method, DECAY, [2.0], 5.0, rtol=1e-9, atol=1e-12, p=(1.5,))
    assert r.status == seg.REACHED_END and r.t == 5.0
    assert r.y[0] == pytest.approx(2.0 * math.exp(-7.5), rel=ACCURACY[method])


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_harmonic_oscillator(method):
    r = run(method, OSC, [1.0, 0.0], 10.0, rtol=1e-9, atol=1e-12)
    assert r.status == seg.REACHED_END
    np.testing.assert_allclose(r.y, osc_exact(10.0), atol=10 * ACCURACY[method])


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_nonautonomous_square(method):
    r = run(method, SQUARE, [1.0], 2.0, rtol=1e-9, atol=1e-12)
    assert r.y[0] == pytest.approx(1.0 + 8.0 / 3.0, rel=ACCURACY[method])


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_stiff_linear(method):
    y0 = [2.0, 0.0, 2.0]
    r = run(method, STIFF, y0, 5.0, rtol=1e-7, atol=1e-10)
    fast, slow = math.exp(-1000 * 5.0), math.exp(-5.0)
    exact = [slow + fast, slow - fast, math.cos(5.0) + fast]
    assert r.status == seg.REACHED_END
    np.testing.assert_allclose(r.y, exact, rtol=1e-5, atol=1e-8)


def test_stiff_solver_takes_far_fewer_steps():
    y0 = [2.0, 0.0, 2.0]
    stiff = run(seg.ROSENBROCK23, STIFF, y0, 20.0, rtol=1e-3, atol=1e-6)
    explicit = run(seg.DOPRI5, STIFF, y0, 20.0, rtol=1e-3, atol=1e-6)
    assert stiff.steps * 10 < explicit.steps
    assert stiff.njac == stiff.steps and explicit.njac == 0


def test_rosenbrock_uses_dfdt():
    """y2' = -1000 (y2 - cos t) - sin t: without the df/dt term ode23s is inconsistent
    at O(h) in the stiff component, and its error estimator forces tiny steps."""
    def solve(jac):
        model = SimpleNamespace(rhs=stiff_rhs, jac=jac, guards=osc_guards)
        return run(seg.ROSENBROCK23, model, [2.0, 0.0, 1.0], 3.0, rtol=1e-6, atol=1e-9)

    exact, lacking = solve(stiff_jac), solve(stiff_jac_no_dfdt)
    assert abs(exact.y[2] - math.cos(3.0)) < 1e-6
    assert 5 * exact.steps < lacking.steps


def test_van_der_pol_stiff_against_radau():
    mu, t_end = 1000.0, 3000.0
    t_out = np.linspace(0.0, t_end, 16)

    def f(t, y):
        return [y[1], mu * (1 - y[0] ** 2) * y[1] - y[0]]

    def jac(t, y):
        return [[0.0, 1.0], [-2 * mu * y[0] * y[1] - 1.0, mu * (1 - y[0] ** 2)]]

    ref = solve_ivp(f, (0.0, t_end), [2.0, 0.0], method="Radau", rtol=1e-10, atol=1e-10,
                    jac=jac, t_eval=t_out)
    r = run(seg.ROSENBROCK23, VDP, [2.0, 0.0], t_end, rtol=1e-7, atol=1e-9, t_out=t_out,
            p=(mu,))
    assert r.status == seg.REACHED_END and r.n_out == t_out.size
    np.testing.assert_allclose(r.y_out[:, 0], ref.y[0], atol=1e-4)
    np.testing.assert_allclose(r.y, ref.y[:, -1], rtol=1e-4, atol=1e-6)


# --- order of convergence and agreement with scipy ------------------------------------

@pytest.mark.parametrize("method, rtols, order", [
    (seg.DOPRI5, [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10], 5),
    (seg.ROSENBROCK23, [1e-4, 1e-5, 1e-6, 1e-7, 1e-8], 2),
], ids=METHOD_IDS)
def test_global_error_falls_at_method_order(method, rtols, order):
    """Error at t = 10 against the number of steps: slope -order on a log-log fit."""
    steps, errors = [], []
    for rtol in rtols:
        r = run(method, OSC, [1.0, 0.0], 10.0, rtol=rtol, atol=rtol)
        steps.append(r.steps)
        errors.append(np.max(np.abs(r.y - osc_exact(10.0))))
    assert errors == sorted(errors, reverse=True)
    assert -slope(steps, errors) == pytest.approx(order, abs=0.5)


@njit(JAC_SIG, cache=True)
def osc_jac_wrong(mode, t, y, p, J, dfdt):
    J[0, 0], J[0, 1], J[1, 0], J[1, 1] = 0.1, 0.5, -0.3, 0.0
    dfdt[:] = 0.0


@pytest.mark.parametrize("jac", [osc_jac, osc_jac_wrong], ids=["exact", "wrong"])
def test_rosenbrock_fixed_step_order_with_any_jacobian(jac):
    """ode23s is a W-method: order 2 even with a wrong Jacobian (generated models zero
    non-finite Jacobian entries and rely on this)."""
    model = SimpleNamespace(rhs=osc_rhs, jac=jac, guards=osc_guards)
    hs = [0.1, 0.05, 0.025, 0.0125]
    errors = [np.max(np.abs(run(seg.ROSENBROCK23, model, [1.0, 0.0], 10.0, rtol=1e3, atol=1e3,
                                h0=h, hmax=h).y - osc_exact(10.0))) for h in hs]
    assert slope(hs, errors) == pytest.approx(2.0, abs=0.1)


@pytest.mark.parametrize("method, order", [(seg.DOPRI5, 4), (seg.ROSENBROCK23, 2)],
                         ids=METHOD_IDS)
def test_dense_output_order(method, order):
    """One step of size h, sampled at h/3 and 3h/4: local error O(h^(order + 1))."""
    hs = np.array([0.4, 0.2, 0.1, 0.05])
    errors = []
    for h in hs:
        t_out = [h / 3, 0.75 * h]
        r = run(method, OSC, [1.0, 0.0], h, rtol=1.0, atol=1.0, h0=h, t_out=t_out)
        assert r.steps == 1 and r.n_out == 2
        errors.append(max(np.max(np.abs(r.y_out[i] - osc_exact(t))) for i, t in
                          enumerate(t_out)))
    assert slope(hs, errors) == pytest.approx(order + 1, abs=0.3)


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_dense_output_along_a_run(method):
    t_out = np.linspace(0.0, 10.0, 101)
    r = run(method, OSC, [1.0, 0.0], 10.0, rtol=1e-8, atol=1e-10, t_out=t_out)
    assert r.n_out == 101
    np.testing.assert_array_equal(r.y_out[0], [1.0, 0.0])
    np.testing.assert_array_equal(r.y_out[-1], r.y)
    node_error = np.max(np.abs(r.y - osc_exact(10.0)))
    dense_error = np.max(np.abs(r.y_out - osc_exact(t_out).T))
    assert dense_error < 20 * max(node_error, 1e-8)


@pytest.mark.parametrize("first_step", [None, 0.05])
def test_dopri5_steps_like_scipy_rk45(first_step):
    """Same tableau, norm and controller: the first accepted steps agree with RK45."""
    rtol, atol = 1e-6, 1e-9
    ref = RK45(lambda t, y: np.array([y[1], -y[0]]), 0.0, np.array([1.0, 0.0]), 100.0,
               rtol=rtol, atol=atol, first_step=first_step)
    for k in range(1, 7):
        ref.step()
        r = run(seg.DOPRI5, OSC, [1.0, 0.0], 100.0, rtol=rtol, atol=atol,
                h0=first_step or 0.0, max_steps=k)
        assert r.status == seg.MAX_STEPS and r.steps == k and r.rejected == 0
        # Equal up to rounding, amplified by the cancellation in the error estimate (and by
        # LLVM's fused multiply-adds where the CPU has them: 4e-11 in t seen on one machine).
        assert r.t == pytest.approx(ref.t, rel=1e-9)
        np.testing.assert_allclose(r.y, ref.y, rtol=1e-9, atol=1e-10)


# --- events ---------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_event_root_to_relative_precision(method):
    """g = cos(y), y = t exactly: the root is pi/2 to a few eps."""
    r = run(method, UNIT, [0.0], 5.0, directions=[0], mode=COSINE)
    assert r.status == seg.EVENT and r.k == 0
    assert abs(r.t - math.pi / 2) <= 8 * np.finfo(float).eps * math.pi / 2
    assert r.t >= math.pi / 2 - 2e-16 and r.y[0] == pytest.approx(r.t, rel=1e-15)


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_event_time_tolerance_is_relative_and_never_early(method):
    r = run(method, UNIT, [0.0], 5.0, directions=[-1], ttol=1e-6, mode=COSINE)
    assert math.pi / 2 <= r.t <= math.pi / 2 + 1e-6 * r.t and math.cos(r.y[0]) <= 0.0


def test_event_on_oscillator_against_closed_form():
    r = run(seg.DOPRI5, OSC, [1.0, 0.0], 5.0, rtol=1e-13, atol=1e-14, directions=[0])
    assert r.status == seg.EVENT
    assert r.t == pytest.approx(math.pi / 2, rel=1e-12)
    assert r.y[0] <= 0.0  # on the far side of (or on) the surface


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
@pytest.mark.parametrize("direction, root", [(0, 0.5), (-1, 0.5), (1, 1.5)])
def test_direction_filter(method, direction, root):
    r = run(method, OSC, [1.0, 0.0], 5.0, rtol=1e-10, atol=1e-12, directions=[direction])
    assert r.status == seg.EVENT and r.t == pytest.approx(root * math.pi, rel=1e-7)
    far_side = -1.0 if root == 0.5 else 1.0
    assert r.y[0] * far_side >= 0.0


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_two_crossings_in_one_step_found_in_order(method):
    """g = (y - 4.9)(y - 5.1) is positive at both ends of the single step [0, 10]."""
    roots = (4.9, 5.1)
    first = run(method, UNIT, [0.0], 10.0, h0=10.0, directions=[0], mode=TWO_ROOTS, p=roots)
    assert first.steps == 1 and first.status == seg.EVENT
    assert first.t == pytest.approx(4.9, rel=1e-14)
    second = run(method, UNIT, first.y, 10.0, t0=first.t, h0=first.h, directions=[0],
                 mode=TWO_ROOTS, p=roots)
    assert second.status == seg.EVENT and second.t == pytest.approx(5.1, rel=1e-14)
    rising = run(method, UNIT, [0.0], 10.0, h0=10.0, directions=[1], mode=TWO_ROOTS, p=roots)
    assert rising.t == pytest.approx(5.1, rel=1e-14)


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
@pytest.mark.parametrize("h0", [0.0, 4.0])  # 4.0: a guard sample lands on the touch point
def test_grazing_is_not_an_event(method, h0):
    r = run(method, UNIT, [0.0], 4.0, h0=h0, directions=[0], mode=GRAZING, p=(1.0,))
    assert r.status == seg.REACHED_END and r.k == -1


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
@pytest.mark.parametrize("direction, status", [(0, seg.EVENT), (1, seg.EVENT),
                                               (-1, seg.REACHED_END)])
def test_event_exactly_at_end_time(method, direction, status):
    r = run(method, UNIT, [0.0], 2.0, directions=[direction], mode=CLOCK, p=(2.0,))
    assert r.status == status and r.t == 2.0


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_guard_zero_at_start_is_not_triggered(method):
    r = run(method, UNIT, [0.0], 3.0, directions=[0], mode=ZERO_AT_START)
    assert r.status == seg.REACHED_END


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
@pytest.mark.parametrize("rtol", [1e-6, 1e-9, 1e-12])
def test_restart_at_event_does_not_repeat_it(method, rtol):
    kw = dict(rtol=rtol, atol=rtol, directions=[0])
    first = run(method, OSC, [1.0, 0.0], 10.0, **kw)
    assert first.status == seg.EVENT and first.y[0] <= 0.0
    second = run(method, OSC, first.y, 10.0, t0=first.t, h0=first.h, **kw)
    assert second.status == seg.EVENT
    assert second.t == pytest.approx(1.5 * math.pi, rel=1e-4)
    assert second.y[0] >= 0.0


@pytest.mark.parametrize("gtol, status", [(0.0, seg.EVENT), (1e-10, seg.REACHED_END)])
def test_gtol_disarms_a_guard_near_zero_at_start(gtol, status):
    """g = y starts at -1e-12 and rises: a crossing at t = 1e-12 unless within gtol."""
    r = run(seg.DOPRI5, UNIT, [-1e-12], 3.0, directions=[0], gtol=gtol, mode=ZERO_AT_START)
    assert r.status == status


def test_output_samples_stop_at_event_and_continue():
    t_out = np.linspace(0.0, 6.0, 13)
    y_out = np.full((13, 2), np.nan)
    y, counters = np.empty(2), np.zeros(seg.N_COUNTERS, np.int64)
    t, i_out = 0.0, 0
    kw = dict(tol=Tolerances(1e-10, np.full(2, 1e-12), 0.0, np.inf), max_steps=10**5,
              ev=EventSettings(np.zeros(1, np.int64), 0.0, 0.0, False, -1, False), t_out=t_out, y_out=y_out,
              y_stop=y, counters=counters)
    events = []
    status, h = seg.EVENT, 0.0
    while status == seg.EVENT:
        status, t, k, n_out, h = integrate_segment(
            method=seg.DOPRI5, attempt=seg.attempt_function(seg.DOPRI5), rhs=osc_rhs, jac=seg.no_jacobian, guards=osc_guards, mode=0,
            p=np.zeros(1), t0=t, y0=y.copy() if events else np.array([1.0, 0.0]), t_end=6.0,
            h0=h, i_out=i_out, **kw)
        assert n_out == np.searchsorted(t_out, t, side="right") - i_out
        i_out += n_out
        events.append(t)
    assert status == seg.REACHED_END and i_out == 13
    np.testing.assert_allclose(events, [0.5 * math.pi, 1.5 * math.pi, 6.0], rtol=1e-9)
    np.testing.assert_allclose(y_out, osc_exact(t_out).T, atol=1e-8)


@njit
def _illinois_cube_root_of_2():
    """(bracket state, tolerance, iterations) of the Illinois iteration on t^3 - 2 over [0, 2],
    in compiled code (events' helpers have no CPython wrapper)."""
    state = ev.bracket_start(0.0, -2.0, 2.0, 6.0)
    tol = ev.time_tolerance(2.0, 0.0)
    for iterations in range(100):
        if ev.bracket_done(state, tol):
            break
        c = ev.bracket_next(state, tol)
        state = ev.bracket_update(state, c, c ** 3 - 2.0)
    return state, tol, iterations


def test_illinois_returns_far_side_end():
    """f(t) = t^3 - 2 on [0, 2]: ends at b on the positive side (or an exact zero) within
    tol of the root."""
    state, tol, iterations = _illinois_cube_root_of_2()
    root = 2.0 ** (1 / 3)
    assert iterations < 20
    assert state[3] >= 0.0 and abs(state[2] - root) <= tol


@njit(GUARDS_SIG, cache=True)
def counted_guards(mode, t, y, p, g):
    """cos t + p[0] on the oscillator; counts its calls in p[1]."""
    p[1] += 1.0
    g[0] = y[0] + p[0]


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_steps_no_guard_can_cross_are_not_sampled_inside(method):
    """cos t + 2 stays >= 1: after the start (value and rate) every accepted step costs two guard
    calls, its end and its rate, not the three interior samples besides. (That a step with a
    double crossing inside is still sampled: test_two_crossings_in_one_step_found_in_order.)"""
    p = np.array([2.0, 0.0])
    y, counters = np.empty(2), np.zeros(seg.N_COUNTERS, np.int64)
    status, *_ = integrate_segment(
        method, seg.attempt_function(method), osc_rhs, osc_jac, counted_guards, 0, p, 0.0, np.array([1.0, 0.0]),
        2 * math.pi, Tolerances(1e-8, np.full(2, 1e-8), 0.0, np.inf), 10**6, 0.0,
        EventSettings(np.zeros(1, np.int64), 0.0, 0.0, False, -1, False), np.empty(0), 0, np.empty((0, 2)), y,
        counters)
    assert status == seg.REACHED_END and counters[seg.N_STEPS] > 10
    assert p[1] == 2 + 2 * counters[seg.N_STEPS]


@njit
def _clear_of_zero(g_a, g_b, rate_a, rate_b, h, sign):
    return ev.clear_of_zero(np.array([g_a]), np.array([g_b]), np.array([rate_a]), np.array([rate_b]), h,
                            np.array([sign]), 0.0)


_VALUES = st.floats(-1e3, 1e3, allow_nan=False, allow_subnormal=False)


@settings(max_examples=400, deadline=None)
@example(g_a=-6.439606410161251e-256, g_b=-6.439606410161251e-256, rate_a=0.0,   # B*B underflowed to 0
         rate_b=-6.439606410161251e-256, h=4.0, sign=-1)
@example(g_a=1e200, g_b=1e200, rate_a=0.0, rate_b=1e200, h=4.0, sign=1)   # B*B overflowed to inf
@given(g_a=_VALUES, g_b=_VALUES, rate_a=_VALUES, rate_b=_VALUES, h=st.floats(1e-6, 10.0), sign=st.sampled_from([-1, 1]))
def test_a_step_left_unsampled_keeps_its_cubic_away_from_zero(g_a, g_b, rate_a, rate_b, h, sign):
    """Where clear_of_zero leaves a step unsampled, the cubic Hermite interpolant of the guard's
    end values and rates (the guard itself, if it is a cubic in t) keeps the guard's sign on the
    whole step, by at least half its smaller end distance: its extrema found independently
    (numpy's roots of its derivative). Subnormal values are left out: numpy's polynomial
    arithmetic loses their digits."""
    if not _clear_of_zero(g_a, g_b, rate_a, rate_b, h, sign):
        return
    # H(theta) = g_a h00 + h rate_a h10 + g_b h01 + h rate_b h11, as a polynomial in theta
    cubic = (np.polynomial.Polynomial([1, 0, -3, 2]) * g_a + np.polynomial.Polynomial([0, 1, -2, 1]) * h * rate_a
             + np.polynomial.Polynomial([0, 0, 3, -2]) * g_b + np.polynomial.Polynomial([0, 0, -1, 1]) * h * rate_b)
    critical = [r.real for r in cubic.deriv().roots() if abs(r.imag) < 1e-12 and 0.0 <= r.real <= 1.0]
    lowest = min(sign * cubic(theta) for theta in [0.0, 1.0] + critical)
    distance = min(sign * g_a, sign * g_b)
    assert lowest >= (1.0 - ev.CLEAR_MARGIN) * distance - 1e-9 * (abs(g_a) + abs(g_b) + h * (abs(rate_a) + abs(rate_b)))


@njit
def _dip_bound(sign, slope_a, slope_b):
    return ev._dip_bound(sign, slope_a, slope_b)


@settings(max_examples=400, deadline=None)
@given(g_a=_VALUES, g_b=_VALUES, slope_a=_VALUES, slope_b=_VALUES, sign=st.sampled_from([-1, 1]))
def test_the_cheap_dip_bound_holds_the_cubic(g_a, g_b, slope_a, slope_b, sign):
    """clear_of_zero's first test: ``_dip_bound`` is never below how far sign H dips under its smaller end
    value on [0, 1] (H the cubic Hermite interpolant of the end values and slopes per unit theta),
    checked on a fine grid of theta independently of the bound's derivation."""
    theta = np.linspace(0.0, 1.0, 3001)
    H = (g_a * (1 - 3 * theta**2 + 2 * theta**3) + slope_a * theta * (1 - theta)**2
         + g_b * (3 * theta**2 - 2 * theta**3) - slope_b * theta**2 * (1 - theta))
    dip = min(sign * g_a, sign * g_b) - np.min(sign * H)
    assert dip <= _dip_bound(sign, slope_a, slope_b) + 1e-12 * (abs(g_a) + abs(g_b) + abs(slope_a) + abs(slope_b))


def test_the_cheap_dip_bound_is_reached_and_passes_nan_on():
    """The bound is sharp (a single slope toward zero dips by 4/27 of it, at theta = 1/3 or 2/3), zero
    for slopes that point away from zero, and NaN for a NaN slope (clear_of_zero then takes the
    full test)."""
    assert _dip_bound(1, -1.0, 0.0) == pytest.approx(4.0 / 27.0, rel=1e-15)
    assert _dip_bound(-1, 0.0, -2.0) == pytest.approx(8.0 / 27.0, rel=1e-15)
    assert _dip_bound(1, 3.0, -5.0) == 0.0
    assert math.isnan(_dip_bound(1, math.nan, 0.0)) and math.isnan(_dip_bound(-1, 0.0, math.nan))


@njit
def _lu_solve(A, b):
    """(factorised, x with A x = b) by rosenbrock's LU, in compiled code (no CPython wrapper)."""
    LU, piv, x = A.copy(), np.zeros(A.shape[0], np.int64), b.copy()
    ok = ros.lu_factor(LU, piv)
    if ok:
        ros.lu_solve(LU, piv, x)
    return ok, x


def test_small_lu_with_partial_pivoting():
    rng = np.random.default_rng(1)
    matrices = [np.array([[0.0, 1.0], [1.0, 0.0]])] + [rng.normal(size=(n, n))
                                                       for n in (1, 2, 3, 4) for _ in range(5)]
    for A in matrices:
        b = rng.normal(size=A.shape[0])
        ok, x = _lu_solve(A, b)
        assert ok
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)
    assert not _lu_solve(np.ones((3, 3)), np.ones(3))[0]


# --- failure statuses -----------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
def test_max_steps(method):
    r = run(method, OSC, [1.0, 0.0], 1e6, max_steps=50)
    assert r.status == seg.MAX_STEPS and r.steps + r.rejected == 50 and r.t < 1e6
    np.testing.assert_allclose(r.y, osc_exact(r.t), atol=1e-5)


@pytest.mark.parametrize("method", METHODS, ids=METHOD_IDS)
@pytest.mark.parametrize("hmin", [0.0, 1e-6])
def test_step_size_underflow_at_blowup(method, hmin):
    """y' = y^2, y(0) = 1 blows up at t = 1: the step size collapses and the run stops."""
    r = run(method, BLOWUP, [1.0], 2.0, rtol=1e-6, atol=1e-6, hmin=hmin)
    assert r.status in (seg.STEP_TOO_SMALL, seg.NOT_FINITE)
    assert r.t < 1.0 + 1e-4 and np.isfinite(r.y).all()
    if hmin > 0:
        assert r.status == seg.STEP_TOO_SMALL and r.h < hmin


def test_non_finite_initial_state():
    r = run(seg.DOPRI5, OSC, [np.nan, 0.0], 1.0)
    assert r.status == seg.NOT_FINITE and r.steps == 0


def test_invalid_input():
    y0 = np.zeros(2)
    status = integrate_segment(  # atol has 3 entries for 2 states
        seg.DOPRI5, seg.attempt_function(seg.DOPRI5), osc_rhs, seg.no_jacobian, osc_guards, 0, np.zeros(1), 0.0, y0, 1.0,
        Tolerances(1e-6, np.zeros(3), 0.0, np.inf), 100, 0.0, EventSettings(np.zeros(0, np.int64), 0.0, 0.0, False, -1, False),
        np.zeros(0), 0, np.zeros((0, 2)), np.zeros(2), np.zeros(4, np.int64))[0]
    assert status == seg.INVALID_INPUT


def test_an_unknown_method_is_refused_by_name():
    with pytest.raises(ValueError, match=r"method 7: expected 0 \(dopri5\), 1 \(rosenbrock23\) or 3 \(rodas4\)"):
        seg.attempt_function(7)


def test_dopri5_accepts_placeholder_jacobian():
    model = SimpleNamespace(rhs=osc_rhs, jac=seg.no_jacobian, guards=osc_guards)
    r = run(seg.DOPRI5, model, [1.0, 0.0], 1.0)
    assert r.status == seg.REACHED_END and r.njac == 0
