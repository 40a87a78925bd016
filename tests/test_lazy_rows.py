"""Rows evaluated after the run from its step log: the same rows as written during the run, ``sol``
at any t against the independent quadrature reference, every state, event instants, held tails,
the Painleve approach, and rows evaluated once."""
import functools

import numpy as np
import pytest

from tswm_runtime.hybrid import entry
from tswm_runtime.integration import steplog
from tswm_runtime.model import modes
from tswm_runtime.reference import quadrature as q
from tswm_runtime.results import rows as lazy_rows
from tswm_runtime.simulation import simulate as sim
from tswm_runtime.simulation.simulate import simulate

PAINLEVE = {"m2": 5000.0, "F2_after": 60000.0, "t_step": 0.04}  # D -> 0+ at t* > t_step (test_events_exact)


def both_ways(scene, params=None, t_out=None, **overrides):
    """One run that writes its rows as it goes (at t_out, default 4001 points) and keeps its steps:
    (rows written, which were reached, rows evaluated from the steps, their segments, the step log)."""
    module = sim._load(scene)
    run = sim.settings(module, overrides)
    y0, quad = sim.initial_state(module, run)
    t_out = np.linspace(0.0, run["t_end"], 4001) if t_out is None else t_out
    sim.method_step(run["method"])
    *_, out, log, mon, counters, steps = entry.integrate(
        sim.METHODS[run["method"]], module, sim.parameter_vector(module, params), modes.tables(module), y0,
        run["t_end"], rtol=run["rtol"], atol=run["atol"], t_out=t_out, max_events=run["max_events"], quad=quad,
        hmax=run["hmax"], max_steps=run["max_steps"], steps=(50_000, 10_000))
    assert steps.count[0] <= steps.f.shape[0] and steps.count[1] <= steps.seg_mode.size
    kept = out.mode >= 0
    y, segment = lazy_rows.states(steps, len(module.STATES), t_out[kept])
    return out, kept, y, segment, steps


def kinds_at(steps, t):
    """The kind of the step each time lies in (the left limit at an event)."""
    n = int(steps.count[0])
    k = np.searchsorted(steps.f[:n, 2], t, side="left")
    return steps.index[k, 0]


@pytest.mark.parametrize("scene, params, overrides", [
    ("paper-runup", None, {}),                                   # a load step
    ("paper-runup", None, {"t_end": 20.0}),                      # an equilibrium held to the end
    ("paper", {"F2": -15000.0}, {"v1": 2.0}),                    # decelerate and stick
    ("stiff-drive", None, {"method": "rosenbrock23"}),           # the stiff method's interpolant
    ("backlash", None, {}),                                      # impacts, four states
    ("lost-motion", None, {}),                                   # the stem's pickup
])
def test_rows_from_the_steps_are_the_rows_written_during_the_run(scene, params, overrides):
    """Bit for bit: the same step, the same interpolant, the same formula (the mode and the latched
    parameters of each row's segment too)."""
    out, kept, y, segment, steps = both_ways(scene, params, **overrides)
    assert kept.sum() > 100
    np.testing.assert_array_equal(y, out.y[kept])
    np.testing.assert_array_equal(steps.seg_mode[segment], out.mode[kept])
    np.testing.assert_array_equal(steps.seg_p[segment], out.p[kept])
    if overrides.get("t_end") == 20.0:
        assert steplog.HELD in steps.index[:steps.count[0], 0]


@functools.lru_cache(maxsize=1)
def painleve_run():
    """(Once per file.) The Painleve run, its reference, and the reference's clock shifted onto tswm's D = 0 (tswm's
    t* is 2.5e-13 s later: near t* v1 - v* ~ sqrt(t* - t), so unshifted the two differ by far more
    than either's error)."""
    ref = q.solve(q.paper_wedge(5000.0), [(0.0, 0.0), (0.04, 60000.0)], 0.0, 1.0)
    r = simulate("paper-runup", PAINLEVE, rtol=1e-10, atol=1e-13)
    assert r.status == "inconsistent" and ref.status == "inconsistent"
    shift = r.t_stop - float(ref.t_stop)
    steps, n = r.rows.steps, int(r.rows.steps.count[0])
    in_sigma = steps.f[:n][steps.index[:n, 0] == steplog.SUNDMAN]
    assert len(in_sigma) >= 2
    return r, (lambda t: np.array([float(ref.v_at(s - shift)) for s in t])), in_sigma


def _row_tolerance(r):
    """The promise for rows (docs/runtime.md): within 10 rtol of the quantity's scale, max |v1|."""
    return 10 * r.settings["rtol"] * np.max(np.abs(r.v1))


@pytest.mark.heavy
def test_rows_in_the_painleve_approach_follow_its_dense_output_in_sundman_time():
    """Rows inside the approach from the step log's dense output in sigma, against the reference;
    outside it bit for bit the rows written during the run. (Those written during the run in the
    step that lands on D = 0 solve t(sigma) = t_out on the whole step, past D = 0, and are off by
    6e-5 m/s here: the log bounds the search by where the step landed.)"""
    r, v_ref, in_sigma = painleve_run()
    t_out = np.union1d(np.linspace(0.0, 1.0, 1001), np.linspace(in_sigma[0, 0], in_sigma[-1, 2], 500))
    out, kept, y, segment, steps = both_ways("paper-runup", PAINLEVE, t_out, rtol=1e-10, atol=1e-13)
    t = out.t[kept]
    sundman = kinds_at(steps, t) == steplog.SUNDMAN
    assert sundman.sum() >= 400
    np.testing.assert_array_equal(y[~sundman], out.y[kept][~sundman])
    inside = np.flatnonzero(sundman & (t < r.t_stop))
    # Against the reference (each value inverts the 34-digit quadrature): every 10th row inside the
    # approach and all of its last 50, those of the step that lands on D = 0.
    checked = np.union1d(inside[::10], inside[-50:])
    np.testing.assert_allclose(y[checked, 0], v_ref(t[checked]), rtol=0.0, atol=_row_tolerance(r))


@pytest.mark.heavy
@pytest.mark.parametrize("times", [20, pytest.param(200, marks=pytest.mark.slow)])
def test_sol_follows_the_quadrature_reference_at_random_times_and_across_the_load_step(times):
    """At random times and beside the load step. Each reference value inverts the 34-digit
    quadrature, most of this test's time (323 s of 200 times in a run at load 8): the default
    run takes 20 random times, -m slow all 200."""
    ref = q.solve(q.paper_wedge(200.0), [(0.0, 0.0), (0.3, -15000.0)], 0.0, 1.0)
    r = simulate("paper-runup", rtol=1e-10, atol=1e-13, points=11)   # few output points: sol does not use them
    t = np.sort(np.r_[np.random.default_rng(3).uniform(0.0, 1.0, times), 0.3 - 1e-9, 0.3, 0.3 + 1e-9, 1.0])
    x, v = r.sol(t)
    np.testing.assert_allclose(v, [float(ref.v_at(s)) for s in t], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(x, [float(ref.x_at(s)) for s in t], rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(r.sol(0.3, side="right"), r.sol(0.3))   # v1 continuous at the step
    assert np.isnan(r.sol([-1e-9, 1.0 + 1e-9])).all()


@pytest.mark.heavy
def test_sol_covers_the_painleve_approach():
    r, v_ref, in_sigma = painleve_run()
    t = np.linspace(in_sigma[0, 0], r.t_stop, 50)[:-1]
    np.testing.assert_allclose(r.sol(t)[1], v_ref(t), rtol=0.0, atol=_row_tolerance(r))
    assert r.sol(r.t_stop)[1, 0] == r.final_state["v1"]


def test_sol_holds_the_equilibrium_tail():
    ref = q.solve(q.paper_wedge(200.0), [(0.0, 0.0)], 0.0, 50.0)
    r = simulate("paper-runup", {"t_step": 100.0}, t_end=50.0, rtol=1e-10, atol=1e-13)
    held = r.rows.steps.index[:r.rows.steps.count[0], 0] == steplog.HELD
    assert held.any()
    t_hold = r.rows.steps.f[np.argmax(held), 0]
    t = np.linspace(t_hold, 50.0, 7)
    x, v = r.sol(t)
    np.testing.assert_allclose(v, [float(ref.v_at(s)) for s in t], rtol=1e-9)
    np.testing.assert_allclose(x, [float(ref.x_at(s)) for s in t], rtol=1e-9)


def test_sol_gives_every_state_and_both_limits_at_an_impact():
    r = simulate("backlash", rtol=1e-10, atol=1e-14)
    assert r.sol_names == ("x1", "v1", "gap", "gap_rate")
    impact = r.impacts[0]
    left, right = r.sol(impact.t, side="left")[:, 0], r.sol(impact.t, side="right")[:, 0]
    assert left[1] == pytest.approx(impact.jump.v1_before, rel=1e-12)
    assert right[1] == pytest.approx(impact.v1, rel=1e-12)
    assert right[2] == pytest.approx(impact.state["gap"], abs=1e-15)
    assert left[1] != right[1]
    np.testing.assert_array_equal(r.sol(r.t)[2], r.gap)   # at the output points: the rows
    with pytest.raises(ValueError, match="side"):
        r.sol(0.1, side="middle")


def test_rows_are_evaluated_once_and_only_when_read(monkeypatch):
    calls = []
    original = lazy_rows.states_at
    monkeypatch.setattr(lazy_rows, "states_at", lambda *a: calls.append(1) or original(*a))
    r = simulate("paper-runup", {"F2_after": -12345.0})
    assert (r.status, r.to_dict()["counts"]["n_points"]) == ("finished", 1001)
    assert np.isfinite(r.S1_max) and r.final_state["v1"] > 0
    assert not calls   # status, maxima, final state, counts: no row evaluated
    assert r.S1 is r.S1 and r.t is r.t
    r.to_dataframe(), r.v1, r.x2
    assert len(calls) == 1
    assert r.final_state == {"v1": r.v1[-1], "x1": r.x1[-1]}


def test_a_run_beyond_the_step_logs_limit_writes_its_rows_as_it_goes(monkeypatch):
    """Memory stays bounded by the output points: the same rows and final state, written by the
    kernel; no sol."""
    full = simulate("paper-runup")
    monkeypatch.setattr(sim, "MAX_LOGGED_STEPS", 20)
    monkeypatch.setattr(sim, "_STEPS_NEEDED", {})
    r = simulate("paper-runup")
    assert full.n_steps > 20 and r.rows.written is not None and r.rows.steps.f.shape[0] == 1
    assert r.final_state == full.final_state and r.to_dict()["counts"]["n_points"] == 1001
    for name in ("t", "x1", "v1", "a1", "S1", "S2", "F1", "F2", "mode"):
        np.testing.assert_array_equal(getattr(r, name), getattr(full, name))
    with pytest.raises(ValueError, match="kept for sol"):
        r.sol(0.5)


def test_a_result_pickles_with_its_rows_and_sol():
    import pickle

    r = simulate("backlash")
    back = pickle.loads(pickle.dumps(r))
    for name in ("t", "x1", "v1", "gap", "S1", "mode", "event_a1"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
    np.testing.assert_array_equal(back.sol([0.1, 0.2], side="right"), r.sol([0.1, 0.2], side="right"))
    assert back.to_dict() == r.to_dict()
