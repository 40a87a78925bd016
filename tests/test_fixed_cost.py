"""What a simulate() call computes at once and what it leaves for later: the final state and the
atol check from the kernel's summary (against numpy over the step log), the Result's lazy parts
(built on first access, equal to what the run logged), the scalar rule check against numpy's, and
the remembered settings and initial state shared safely. No timing here (tools/fixed_cost.py)."""
import math
import pickle

import numpy as np
import pytest

from tswm_runtime.model import checks
from tswm_runtime.results import result as result_module
from tswm_runtime.simulation import simulate as sim
from tswm_runtime.simulation.simulate import SimulationInputError, simulate

SCENES = [("paper-runup", None, {}), ("paper", {"F2": -15000.0}, {"v1": 2.0}),
          ("stiff-drive", None, {"method": "rosenbrock23"}), ("backlash", None, {}), ("lost-motion", None, {})]


@pytest.mark.parametrize("scene, params, overrides", SCENES)
def test_final_state_and_largest_states_are_those_of_the_step_log(scene, params, overrides, monkeypatch):
    """The kernel's summary (entry.summarize) against numpy over the steps the run kept: the end of
    the last step, and max |y| per column, which check_atol_scale judges."""
    seen = []
    check = sim.check_atol_scale
    monkeypatch.setattr(sim, "check_atol_scale", lambda module, atol, scales: seen.append(scales) or
                        check(module, atol, scales))
    r = simulate(scene, params, **overrides)
    steps = r.rows.steps
    n = int(steps.count[0])
    assert r.status == "finished" and 0 < n <= steps.f.shape[0]
    names = sim.state_names(r.rows.module, steps.y_hi.shape[1])
    assert r.final_state == dict(zip(names, steps.y_hi[n - 1].tolist()))
    assert seen == [np.abs(steps.y_hi[:n]).max(axis=0).tolist()]


def test_a_run_that_writes_its_rows_is_summarised_from_them(monkeypatch):
    """Beyond the step log's limit: the largest states over the rows written, the final state from
    the last step kept (the same as the full run's)."""
    full = simulate("paper-runup")
    seen = []
    check = sim.check_atol_scale
    monkeypatch.setattr(sim, "check_atol_scale", lambda module, atol, scales: seen.append(scales) or
                        check(module, atol, scales))
    monkeypatch.setattr(sim, "MAX_LOGGED_STEPS", 20)
    monkeypatch.setattr(sim, "_STEPS_NEEDED", {})
    r = simulate("paper-runup")
    written = r.rows.written
    assert written is not None and r.final_state == full.final_state
    assert seen == [np.abs(written.y[written.mode >= 0]).max(axis=0).tolist()]


def test_runs_with_other_tolerances_in_between_are_not_run_twice(monkeypatch):
    """The step log's size is guessed from the last run with the same settings: a long run (rtol 1e-11,
    more steps than the smallest log) after a short one with other settings integrates once."""
    calls = []
    run = sim.entry.run
    monkeypatch.setattr(sim.entry, "run", lambda *a, **k: calls.append(a[4].tol.rtol) or run(*a, **k))
    monkeypatch.setattr(sim, "_STEPS_NEEDED", {})
    for rtol in (1e-11, 1e-4, 1e-11, 1e-4):
        r = simulate("paper-runup", rtol=rtol, atol=rtol * 1e-3)
        assert r.status == "finished"
    assert r.n_steps < sim.MIN_STEP_CAPACITY < simulate("paper-runup", rtol=1e-11, atol=1e-14).n_steps
    assert calls == [1e-11, 1e-11, 1e-4, 1e-11, 1e-4, 1e-11]


def test_a_run_without_steps_stops_where_it_started():
    """Backward sliding at the start, which the scene does not declare: no step; the final state is the
    start, x1 (the integral of v1 here) included."""
    r = simulate("paper", {"m2": 1e6, "F2": 1e5}, v1=-1.0, x1=0.25)
    assert r.status == "undeclared-mode" and r.n_steps == 0 and r.final_state == {"v1": -1.0, "x1": 0.25}


def test_reading_status_maxima_and_final_state_builds_nothing_else(monkeypatch):
    """Events, phases, message, KD, parameters are built on first access, once, and equal what the run logged."""
    built = []
    for name in ("_events", "_phases", "status_message"):
        original = getattr(result_module, name)
        monkeypatch.setattr(result_module, name, lambda *a, _f=original, _n=name, **k: built.append(_n) or _f(*a, **k))
    r = simulate("paper-runup", {"F2_after": -12000.0})
    assert (r.status, math.isfinite(r.S1_max), r.final_state["v1"] > 0) == ("finished", True, True)
    assert built == [] and not {"events", "message", "KD1", "params"} & set(vars(r))
    assert r.message == "reached t_end = 1 s with 0 mode changes and 1 other event" and r.message is r.message
    assert built == ["_events", "status_message"]
    log, k = r.record.log, r.record.n_events
    assert [(e.t, e.guard, e.from_mode, e.to_mode) for e in r.events] == [(log.t[0], "load_step", "fwd_a", "fwd_a")]
    assert k == 1 and r.events[0].state == {"v1": log.state[0, 0]} and r.events[0].x1 == log.state[0, 1]
    assert r.params == {"m2": 200.0, "F2_after": -12000.0, "t_step": 0.3}
    assert r.KD1 == pytest.approx(abs(r.S1_max) / 990.0) and r.KD2 == pytest.approx(abs(r.S2_max) / 8303.7)


def test_a_pickled_result_carries_its_lazy_parts_not_its_module():
    r = simulate("paper-runup")
    back = pickle.loads(pickle.dumps(r))
    assert back.record is None and back.to_dict() == r.to_dict() and back.message == r.message


def test_the_scalar_rule_check_agrees_with_numpy_on_random_rows():
    """checks.row_violation (plain floats) against checks.violations (numpy) on rows inside and
    outside every rule of several scenes: the same verdict and message."""
    from tswm_runtime.model.scenes import load_model

    rng = np.random.default_rng(7)
    for scene in ("paper-runup", "paper", "mesh", "lost-motion", "valve-travel", "load-schedule"):
        module = load_model(scene)
        defaults = np.array(module.PARAM_DEFAULTS, dtype=float)
        bad = 0
        for _ in range(200):
            factors = rng.choice([1.0, -1.0, 0.0, 1e-12, 1e13, 2.0], size=defaults.size, p=[.5, .1, .1, .1, .1, .1])
            row = defaults * factors
            expected = checks.violations(module, [row])[0]
            assert checks.row_violation(module, tuple(row.tolist())) == expected
            assert _compiled_verdict(module, row.tolist()) == (expected == "")
            bad += bool(expected)
        assert bad > 10


def test_the_scalar_rule_check_agrees_with_numpy_on_the_jam_rule():
    """The jam rule (a free slope: gamma + the largest friction angle < 90 deg), for both friction laws,
    a friction coefficient c of 0 (a division by zero: numpy's inf) and NaN included."""
    from types import ModuleType

    for law in ("constant", "decreasing"):
        module = ModuleType(f"jam_{law}")   # a stand-in for a generated module: the checks are remembered per module
        vars(module).update(PARAM_NAMES=("gamma", "friction"), PARAM_UNITS=("rad", ""), FIXED={},
                            PARAM_CHECKS=(("jam", "gamma", "wedge.gamma", "friction", law, "gamma + rho below 90 deg"),))
        for gamma in (0.1, 1.5, math.pi / 2):
            for friction in (0.0, -0.0, 0.01, 0.2, 1.0, 1.6, math.inf, math.nan):
                expected = checks.violations(module, [[gamma, friction]])[0]
                assert checks.row_violation(module, (gamma, friction)) == expected, (law, gamma, friction)
                assert _compiled_verdict(module, [gamma, friction]) == (expected == ""), (law, gamma, friction)


def _compiled_verdict(module, row: list) -> bool:
    """checks.row_check's verdict on a row; where it divides by zero (it raises), simulate asks
    row_violation (numpy's inf), so that one's verdict stands."""
    try:
        return bool(checks.row_check(module)(row))
    except ArithmeticError:
        return checks.row_violation(module, tuple(row)) == ""


@pytest.mark.parametrize("scene", ["paper-runup", "paper", "lost-motion", "valve-travel"])
def test_a_float_parameter_is_held_to_the_same_limits_as_its_text(scene):
    """simulate takes a finite float within its quantity's limits as it is (parameter_vector's shortcut);
    the same number as text goes through si_value: the same vector, or the same message."""
    module = sim._load(scene)
    values = [0.0, -0.0, 1e-300, 1e-12, 1e-10, 1e-9, 0.5, -7.5, 1e6, 1.0000001e6, 1e9, 1.0000001e9, 1e12,
              -1.0000001e12, 1e13, 1e15, 1e16, math.inf, -math.inf, math.nan]
    refused = 0
    for name in module.PARAM_NAMES:
        for value in values:
            outcomes = []
            for given in (value, repr(value)):
                try:
                    outcomes.append(sim.parameter_vector(module, {name: given}).tolist())
                except SimulationInputError as error:
                    outcomes.append(str(error))
            assert outcomes[0] == outcomes[1], (name, value, outcomes)
            refused += isinstance(outcomes[0], str)
    assert refused > 3 * len(module.PARAM_NAMES)


def test_a_runs_arrays_are_disjoint_views_that_fill_their_two_blocks():
    """entry.record_views lays every array of a run (the summary, the Outputs but their times, the
    EventLog, the maxima, the counters, the StepLog) in its two blocks without overlap or gap."""
    r = simulate("paper-runup", {"F2_after": -12000.0}, points=11)
    arrays = r.record.arrays
    summary, record = arrays.views
    out, log, mon, counters, steps = record
    views = [summary, *out[1:], *log, mon, counters, *steps]
    for block, dtype in ((arrays.floats, np.float64), (arrays.ints, np.int64)):
        mine = [v for v in views if v.dtype == dtype]
        assert all(v.base is block and v.flags.c_contiguous for v in mine)
        assert sum(v.size for v in mine) == block.size
        assert not any(np.shares_memory(a, b) for i, a in enumerate(mine) for b in mine[i + 1:] if a.size and b.size)
    assert r.n_steps == counters[0] and r.S1_max == mon[0, 1] and list(r.final_state.values()) == summary[2:].tolist()


def test_a_new_value_is_checked_after_a_valid_one_ran():
    simulate("paper", {"m2": 200.0}, t_end=1e-3)
    with pytest.raises(SimulationInputError, match=r"parameter m2 = 0 kg: must be > 0 kg"):
        simulate("paper", {"m2": 0.0}, t_end=1e-3)
    with pytest.raises(SimulationInputError, match=r"parameter m2 = nan: must be finite"):
        simulate("paper", {"m2": math.nan}, t_end=1e-3)


def test_remembered_settings_and_initial_state_are_not_changed_by_a_caller():
    """A Result's settings are its own; the initial state the runs share is never written."""
    r = simulate("paper", v1=2.0, t_end=0.01)
    y0 = sim.prepared(r.rows.module, {"v1": 2.0, "t_end": 0.01}).y0.copy()
    r.settings["v1"] = 99.0
    again = simulate("paper", v1=2.0, t_end=0.01)
    assert again.settings["v1"] == 2.0 and again.final_state == r.final_state
    assert sim.settings(r.rows.module, {"v1": 2.0, "t_end": 0.01})["v1"] == 2.0
    np.testing.assert_array_equal(sim.prepared(r.rows.module, {"v1": 2.0, "t_end": 0.01}).y0, y0)
