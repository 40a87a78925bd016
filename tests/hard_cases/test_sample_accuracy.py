"""Output rows are accurate to the tolerance: every sample, not only the step ends.

Against the independent dense reference (``reference.dense``: the quadrature's events,
DOP853 at rtol 1e-13 between them, on hand-written formulas), the worst sample error of x1,
v1, S1 and S2, |y - y_ref| / (rtol * Y) with Y the quantity's scale over the run (for S1, S2
with their sensitivity to v1, see ``dense.worst_ratios``), stays within 10 in the first
5 ms after each segment boundary and everywhere else, for rtol 1e-3..1e-9 and both methods:
a run-up from rest with a load step while it still accelerates, a stall to stick and a
breakaway, and a gear braking from 2 m/s to rest. Before, rows between step ends came from
a DOPRI5 interpolant whose error was not controlled (up to 103 rtol) and rosenbrock23's
second-order global error grew like rtol^(2/3) (up to 382 rtol at rtol 1e-9).
"""
import functools
import itertools

import pytest

from subsets import slow_unless_kept
from tswm_runtime.reference import dense
from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN, SimulationInputError, simulate

LIMIT = 10.0  # worst sample error in units of rtol (measure above)
POINTS = 20001  # rows over 1 s: 50 us apart, 100 in the first 5 ms after a boundary
CASES = {  # scene, free parameters, v1(0); the reference's m2, load schedule
    "runup-load-step": ("paper-runup", {"F2_after": -5000.0, "t_step": 0.05}, 0.0,
                        (200.0, ((0.0, 0.0), (0.05, -5000.0)))),
    "stall-stick-breakaway": ("load-schedule", {}, 0.0, (200.0, ((0.0, 0.0), (0.3, -30000.0), (0.6, -2000.0)))),
    "brake-to-stick": ("paper", {"F2": -15000.0}, 2.0, (200.0, ((0.0, -15000.0),))),
}
METHODS = ("dopri5", "rosenbrock23", "rodas4", "auto")  # auto: slow run only
RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
GRID = list(itertools.product(sorted(CASES), RTOLS, METHODS))
# The default run: every case with each method, at rtol 1e-4 to 1e-9 (rosenbrock23 at 1e-9 is
# where its global error was worst, 382 rtol). Each of these fails when its run is integrated at
# 100 rtol and judged at rtol (worst ratio 27 to 345); judged at rtol 1e-3 and run at 0.01 (the
# largest allowed), brake-to-stick (both methods) and runup-load-step (rosenbrock23) stayed within
# 10, and brake-to-stick with dopri5 at 1e-4 and 1e-5 too: those are left to -m slow. Run on
# commit 46b74eb (before the accuracy fix), 3 of the kept 6 fail (stall dopri5 1e-9: v1 103 rtol).
KEPT = [("brake-to-stick", 1e-7, "dopri5"), ("runup-load-step", 1e-6, "dopri5"),
        ("stall-stick-breakaway", 1e-9, "dopri5"), ("brake-to-stick", 1e-9, "rosenbrock23"),
        ("runup-load-step", 1e-4, "rosenbrock23"), ("stall-stick-breakaway", 1e-6, "rosenbrock23"),
        ("stall-stick-breakaway", 1e-3, "rodas4"), ("brake-to-stick", 1e-3, "rodas4")]
# rodas4's two at rtol 1e-3 were 26.8 and 22.9 rtol off (S1) before its step was judged by its dense
# output's error too (``rodas.dense_error``): 1.4 and 0.4 after (tools/sample_accuracy.py).


@functools.lru_cache(maxsize=None)
def reference(case):
    scene, params, v0, (m2, schedule) = CASES[case]
    return dense.PaperGear(m2, list(schedule), v0, 1.0)


@pytest.mark.parametrize("case, rtol, method", slow_unless_kept(GRID, KEPT))
def test_every_output_row_is_within_ten_rtol_of_the_reference(case, rtol, method):
    scene, params, v0, _ = CASES[case]
    r = simulate(scene, params, method=method, rtol=rtol, atol=1e-3 * rtol, v1=v0, points=POINTS)
    assert r.status == "finished", r.message
    worst = dense.worst_ratios(r, reference(case), rtol)
    assert max(worst.values()) <= LIMIT, {k: round(v, 2) for k, v in worst.items() if v > LIMIT}


@pytest.mark.parametrize("method", sorted(METHOD_RTOL_MIN))
@pytest.mark.parametrize("case", sorted(CASES))
def test_each_method_delivers_at_the_tightest_rtol_it_accepts(case, method):
    """At METHOD_RTOL_MIN too (dopri5 1e-12, rosenbrock23 1e-9, rodas4 and auto 1e-12; measured worst 3.8,
    3.9, 3.8 and 3.8 rtol); a
    tighter rtol is refused (rosenbrock23 at 1e-10 was 39 rtol off, tests/test_bounds.py)."""
    rtol = METHOD_RTOL_MIN[method][0]
    scene, params, v0, _ = CASES[case]
    r = simulate(scene, params, method=method, rtol=rtol, atol=1e-3 * rtol, v1=v0, points=POINTS)
    assert r.status == "finished", r.message
    worst = dense.worst_ratios(r, reference(case), rtol)
    assert max(worst.values()) <= LIMIT, {k: round(v, 2) for k, v in worst.items() if v > LIMIT}
    with pytest.raises(SimulationInputError, match=f"rtol = {rtol / 10:g}: must be >= {rtol:g} with method {method}"):
        simulate(scene, params, method=method, rtol=rtol / 10)


@pytest.mark.heavy
def test_the_reference_agrees_with_the_quadrature():
    """The dense reference is the quadrature's to about 1e-12 of |v1|, far below 10 rtol at rtol 1e-9."""
    for case in CASES:
        assert reference(case).check() < 1e-11, case
