"""Method "auto": DOPRI5 switching to ROSENBROCK23 where its steps are limited by stability.

The stiffness estimates against closed forms (a linear decay, numpy's eigenvalues), and whole
runs of the slow-load scene (a load that keeps changing: nothing is held) against the DOP853
reference of the benchmark (``bench.cases.reference``: hand formulas, rtol 1e-13).
"""
import numpy as np
import pytest
from numba import njit

from tswm_runtime.bench.cases import CASES, reference
from tswm_runtime.integration import control, dopri5
from tswm_runtime.jit.signatures import RHS_SIG
from tswm_runtime.simulation.simulate import simulate


@njit(RHS_SIG, cache=True)
def _decay(mode, t, y, p, dy):
    dy[0] = -p[0] * y[0]
    dy[1] = -0.5 * p[0] * y[1]


@njit
def _stiffness_after_a_step(h, y, p, K, y_new, y6):
    """dopri5.stiffness after one DOPRI5 step of _decay (kernel helpers run inside compiled code only)."""
    _decay(0, 0.0, y, p, K[0])
    dopri5.stages(_decay, 0, 0.0, y, p, h, K, y_new, y6)
    _decay(0, h, y_new, p, K[dopri5.N_STAGES])
    return dopri5.stiffness(h, K, y_new, y6)


@njit
def _spectral_radius(J, A, B):
    return control.spectral_radius(J, A, B)


@pytest.mark.parametrize("h", [1e-4, 1e-3, 1e-2])
def test_dopri5_stiffness_is_h_times_the_largest_rate_on_a_linear_decay(h):
    """y' = diag(-L, -L/2) y: the sixth and seventh stages both sit at t + h, so their
    difference is J (y_new - y6) and h rho lies between h L/2 and h L (h L where the fast
    component dominates the stage difference, as it does here from y0 = (1, 0))."""
    L = 1000.0
    K, y_new, y6 = np.zeros((dopri5.N_STAGES + 1, 2)), np.empty(2), np.empty(2)
    y, p = np.array([1.0, 0.0]), np.array([L])
    assert _stiffness_after_a_step(h, y, p, K, y_new, y6) == pytest.approx(h * L, rel=1e-9)


def test_the_spectral_radius_bound_is_above_and_close_to_numpys():
    """||J^32||^(1/32) bounds the spectral radius from above, within 30 % on random 4 x 4 matrices
    and a spring-mass pair in mixed units (k/m = 1e8: ||J|| = 1e8, rho = 1e4)."""
    rng = np.random.default_rng(7)
    spring = np.array([[0.0, 1.0], [-1e8, -20.0]])
    for J in [spring, *(rng.normal(size=(4, 4)) * 10.0 ** rng.uniform(-3, 6) for _ in range(50))]:
        rho = max(abs(np.linalg.eigvals(J)))
        bound = _spectral_radius(J, np.empty_like(J), np.empty_like(J))
        assert rho * (1 - 1e-12) <= bound <= 1.3 * rho, (J, rho, bound)


@pytest.mark.parametrize("t_end, rtol", [(10.0, 1e-6), (100.0, 1e-6), (100.0, 1e-9)])
def test_auto_switches_on_the_slow_load_and_stays_accurate(t_end, rtol):
    """After the run-up the gear follows the slowly changing load: DOPRI5 steps at its stability
    limit there (6538 steps to 100 s), auto hands over to RODAS4 and takes a fraction of the
    steps; x1(T) and v1(T) within 10 rtol of the reference, as the fixed methods'. At rtol 1e-9
    DOPRI5 holds h|J| at 2.8 to 3.23, below dopri5.f's 3.25: with that bound auto took 5352 of
    DOPRI5's 7027 steps to 100 s (818 with segment.STIFF_H_RHO)."""
    ref = reference(CASES[f"slow load T={t_end:g}"])
    runs = {m: simulate("slow-load", method=m, t_end=t_end, rtol=rtol, atol=rtol * 1e-3)
            for m in ("dopri5", "auto")}
    for method, r in runs.items():
        assert r.status == "finished", r.message
        assert abs(r.final_state["x1"] - ref.x_end) <= 10 * rtol * abs(ref.x_end), method
        assert abs(r.final_state["v1"] - ref.v_end) <= 10 * rtol * abs(ref.v_end), method
    auto, explicit = runs["auto"], runs["dopri5"]
    assert auto.n_switches >= 1 and auto.njev > 0
    assert auto.n_steps < explicit.n_steps / 3
    assert explicit.n_switches == 0
    # no flip-flopping: at most a return and a new switch per load breakpoint (each starts a
    # fast transient DOPRI5 resolves best), and the first switch
    assert auto.n_switches <= 1 + 2 * len(auto.events)


def test_auto_is_dopri5_where_nothing_is_stiff():
    """paper-runup: the run-up and the held tail never limit DOPRI5 by stability: auto takes
    exactly DOPRI5's steps."""
    auto, explicit = (simulate("paper-runup", method=m) for m in ("auto", "dopri5"))
    assert auto.n_switches == 0
    assert (auto.n_steps, auto.nfev, auto.final_state) == (explicit.n_steps, explicit.nfev, explicit.final_state)


def test_the_sweep_table_counts_autos_switches():
    """The sweep's n_switches column is the run's Result.n_switches, case by case (slow-load,
    T = 10 s, m2 = 150 and 250 kg: auto switches; dopri5 never does)."""
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.sweeps.sweep import grid_cases, parse_grid, sweep

    module = load_module("slow-load")
    P = grid_cases(module, parse_grid(["m2=150:250:2"], module))
    for method in ("auto", "dopri5"):
        table = sweep(module, P, {"method": method, "t_end": 10.0}).table
        runs = [simulate("slow-load", {"m2": m2}, method=method, t_end=10.0) for m2 in P[:, 0]]
        assert list(table["n_switches"]) == [r.n_switches for r in runs], method
        assert (table["n_switches"] >= 1).all() == (method == "auto")
