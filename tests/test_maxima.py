"""The maxima of S1 and S2 cover the whole run: every segment, held equilibrium tails, event
instants; a maximum is never below an output row, and the load factors are those of the maxima."""
import numpy as np
import pytest

from tswm_runtime.model.contract import load_module
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.sweeps.sweep import grid_cases, parse_grid, sweep

SHIPPED = ("asymmetric", "backlash", "load-schedule", "lost-motion", "mesh", "one-sided", "paper",
           "paper-literal", "paper-lostmotion", "paper-runup", "seating", "slow-load", "stiff-drive", "valve-travel")


@pytest.mark.parametrize("method", ["dopri5", "rosenbrock23"])
@pytest.mark.parametrize("scene", SHIPPED)
def test_maxima_are_never_below_an_output_row(scene, method):
    r = simulate(scene, method=method, points=2001)
    for name, peak in (("S1", r.S1_max), ("S2", r.S2_max)):
        rows = np.abs(getattr(r, name))
        assert abs(peak) >= rows.max() * (1.0 - 1e-14), f"{name}: max {peak} below the row {rows.max()}"
    module = load_module(scene)
    if module.HAS_LOAD_FACTORS:
        p = np.array([r.params[k] for k in module.PARAM_NAMES] + [0.0] * len(getattr(module, "LATCH_NAMES", ())))
        assert (r.KD1, r.KD2) == module.load_factors(r.S1_max, r.S2_max, p)


@pytest.mark.parametrize("method", ["dopri5", "rosenbrock23"])
def test_a_held_tail_holds_the_true_peak(method):
    """paper-runup: the load steps to F2_after and the worm settles to a steady speed, held
    (integration.steady). There a1 = a2 = 0, so body 2's balance gives S2 = -F2_after exactly,
    and |S2| rises towards it from below: the peak is the held tail's, 15000 N."""
    r = simulate("paper-runup", method=method, points=2001)
    assert abs(r.S2_max) == pytest.approx(abs(r.params["F2_after"]), rel=1e-10)


def test_a_stop_at_an_event_reports_the_finite_peaks_before_it():
    """paper-runup with m2 = 8000 kg and F2_after = +60000 N: at the load step the state needs
    flank b, whose D is negative there; the run stops (inconsistent) at t_step. The forces up to
    it were finite: the maxima are the largest |S| reached before the stop, not +-inf."""
    r = simulate("paper-runup", {"m2": 8000.0, "F2_after": 60000.0, "t_step": 0.04}, points=20001)
    assert r.status == "inconsistent" and r.t_stop == pytest.approx(0.04)
    assert "finite peaks" in r.message
    for name, peak in (("S1", r.S1_max), ("S2", r.S2_max)):
        rows = np.abs(getattr(r, name))
        assert np.isfinite(peak) and abs(peak) >= rows.max() * (1.0 - 1e-14)
        assert abs(peak) == pytest.approx(rows.max(), rel=1e-6)


def test_a_painleve_end_keeps_its_unbounded_maxima():
    """m2 = 5000 kg, F2_after = +60000 N at 0.04 s: D falls to 0 in finite time on flank b (the
    reference's square-root approach, tests/hard_cases/test_quadrature.py): the forces grow
    without bound, so the maxima are +-inf and the message says so."""
    r = simulate("paper-runup", {"m2": 5000.0, "F2_after": 60000.0, "t_step": 0.04})
    assert r.status == "inconsistent" and r.events[-1].guard == "D"
    assert np.isinf(r.S1_max) and np.isinf(r.S2_max) and "grow without bound" in r.message


def test_the_sweep_batch_maxima_cover_the_rows_and_the_held_tail():
    """hybrid/batch.py reports S1m, S2m per case: never below a row of the same case run with
    dense rows, and over paper-runup's held tails |S2m| = |F2_after| (a1 = 0 there)."""
    module = load_module("paper-runup")
    P = grid_cases(module, parse_grid(["m2=100:300:2", "F2_after=-15000:-5000:2"], module))
    table = sweep("paper-runup", P, {}, chunk_size=4).table
    for row in table.to_dict("records"):
        r = simulate("paper-runup", {"m2": row["m2"], "F2_after": row["F2_after"]}, points=2001)
        assert abs(row["S1m"]) >= np.abs(r.S1).max() * (1.0 - 1e-14)
        assert abs(row["S2m"]) >= np.abs(r.S2).max() * (1.0 - 1e-14)
        assert abs(row["S2m"]) == pytest.approx(abs(row["F2_after"]), rel=1e-10)



@pytest.mark.parametrize("t_end", [0.05, 0.0790, 0.0796, 0.0797, 0.0798, 0.0799, 0.0801, 0.2])
def test_a_maximum_at_the_end_or_inside_a_step_is_the_reference_s(t_end):
    """m2 = 200 kg, no load: |S1| and |S2| rise to smooth peaks at 79.60 and 79.84 ms and fall. A
    run that ends before a peak has that maximum at t_end, where |S| still rises (taken from the
    end's state, no search: ``segment._rising_to_end``); one that ends after it has it inside a
    step, in the last one or earlier. Both against the quadrature reference of the same interval."""
    from tswm_runtime.reference import quadrature as q
    ref = q.solve(q.paper_wedge(200.0), [(0.0, 0.0)], 0.0, t_end).S_extrema()
    r = simulate("paper-runup", {"m2": 200.0, "F2_after": 0.0}, t_end=t_end, rtol=1e-10, atol=1e-13)
    for name, peak in (("S1", r.S1_max), ("S2", r.S2_max)):
        assert peak == pytest.approx(float(ref[name][0]), rel=1e-9), name
