"""The bench's sweeps end to end: the grid the processes and the diffrax batch share, the errors
and the choice of equal accuracy, the optional diffrax peer (against the quadrature reference
where jax is installed; a clear message where it is not). No times asserted."""
import math
import os

import numpy as np
import pytest

from tswm_runtime.bench import bench, diffrax_peer, sweeps
from tswm_runtime.model.contract import load_module
from tswm_runtime.sweeps.sweep import grid_cases, parse_grid


def test_the_command_line_grid_and_the_in_process_grid_are_the_same_cases():
    module = load_module(sweeps.SCENE)
    for cases in (1000, 10_000, 100_000):
        options = sweeps._grid_options(cases)
        P = grid_cases(module, parse_grid(options[1::2], module))
        m2, F2 = sweeps.grid(cases)
        assert len(m2) == cases
        assert np.array_equal(P[:, module.PARAM_NAMES.index("m2")], m2)
        assert np.allclose(P[:, module.PARAM_NAMES.index("F2_after")], F2, rtol=1e-15, atol=0)


def test_largest_errors_are_the_benchs_errors_and_a_failed_case_is_inf():
    refs = [{"S1": 1000.0, "v_end": 0.5, "x_end": 2.0}, {"S1": -400.0, "v_end": 7.0, "x_end": 5.0}]
    out = {"S1": [1000.1, -400.0], "v_end": [0.5 + 1e-6, 7.0 - 7e-5], "x_end": [2.0, 5.0 + 5e-4], "ok": [True, True]}
    e = sweeps.largest_errors(out, refs)
    assert e["err_S1"] == pytest.approx(1e-4)
    assert e["err_v1"] == pytest.approx(1e-5)   # 1e-6 / max(0.5, 1) < 7e-5 / 7
    assert e["err_x1"] == pytest.approx(1e-4)
    assert sweeps.largest_errors({**out, "ok": [True, False]}, refs) == dict.fromkeys(e, math.inf)


def test_without_jax_the_diffrax_peer_is_left_out_with_a_message(monkeypatch):
    monkeypatch.setattr(diffrax_peer, "available", lambda: False)
    monkeypatch.delenv(sweeps.JAX_PYTHON, raising=False)
    runs, why = sweeps.diffrax_runs([])
    assert runs is None and "bench-jax" in why and sweeps.JAX_PYTHON in why


def test_the_report_says_when_the_end_to_end_figures_were_not_measured():
    assert "not measured" in "\n".join(bench._end_to_end_markdown(None))


def test_diffrax_peer_agrees_with_the_quadrature_reference():
    """At rtol 1e-10 every accuracy case finishes and its S1 max, v1(T), x1(T) are within 1e-8 of
    the reference (needs jax and diffrax here, or an interpreter with them in TSWM_BENCH_JAX_PYTHON)."""
    m2, F2 = (list(c) for c in zip(*sweeps.ACCURACY_CASES))
    runs, why = sweeps.diffrax_runs([{"m2": m2, "F2": F2, "rtol": 1e-10, "atol": 1e-13}])
    if runs is None:
        pytest.skip(why)
    e = sweeps.largest_errors(runs["runs"][0], sweeps.reference_outcomes())
    assert all(value <= 1e-8 for value in e.values()), e


def test_equal_accuracy_is_the_loosest_tolerance_matching_all_three_errors_and_x1_alone():
    tswm = {"err_S1": 1e-9, "err_v1": 1e-9, "err_x1": 1e-6}
    levels = [{"rtol": r, "err_S1": 10 * r, "err_v1": r, "err_x1": r} for r in (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11)]
    chosen = sweeps._levels(levels, tswm)
    assert [(lv["rtol"], why) for lv, why in chosen] == [(1e-10, "S1 max, v1(T), x1(T)"), (1e-6, "x1(T) only")]
    never = sweeps._levels(levels, {**tswm, "err_S1": 1e-13})
    assert [(lv["rtol"], why) for lv, why in never] == [(1e-11, "none (the tightest tried)"), (1e-6, "x1(T) only")]


def test_the_report_shows_the_processes_and_the_diffrax_timings_beside_their_targets():
    process = {"command": "tswm sweep paper-runup ...", "cases": 10_000, "wall_s_median": 2.0, "wall_s_min": 1.9,
               "wall_s_max": 2.2, "cpu_s_median": 3.5, "load_1min": "1.0", "cases_per_s": 5000.0,
               "verdict": "missed: 5000 cases/s, 2x below the target 10000"}
    timing = {"diffrax_rtol": 1e-7, "matches_tswm_on": "x1(T) only", "diffrax_s_median": 4.0,
              "diffrax_cpu_s_median": 4.0, "diffrax_cases_per_s": 2500.0, "tswm_over_diffrax": 2.0,
              "verdict": "missed: 2 x, 1.5x below the target 3"}
    errors = {"err_S1": 1e-12, "err_v1": 1e-12, "err_x1": 1e-6}
    dx = {"scene": "paper-runup", "tswm_rtol": 1e-6, "tswm_errors": errors, "diffrax": "in python",
          "versions": {"jax": "0", "diffrax": "0"}, "diffrax_levels": [{"rtol": 1e-7, **errors}], "cases": 10_000,
          "tswm_s_median": 1.0, "tswm_cpu_s_median": 2.0, "tswm_cases_per_s": 10_000.0, "tswm_threads": 2,
          "timings": [timing], "load_1min": [1.0, 1.5]}
    md = "\n".join(bench._end_to_end_markdown({"processes": [process], "diffrax": dx}))
    assert process["verdict"] in md and timing["verdict"] in md and "10000 cases >= 10000 cases/s" in md
    assert "x1(T) only" in md and "jax 0" in md


def test_every_timed_sweep_process_starts_from_an_empty_output_directory(monkeypatch):
    """A process that found the chunks of the run before it would time reading them, not a sweep."""
    seen = []

    def fake(argv):
        out = argv[argv.index("-o") + 1]
        seen.append(sorted(os.listdir(out)))
        open(os.path.join(out, "chunk-00000-x.parquet"), "w").close()
        return {"wall_s": 1.0, "cpu_s": 1.0, "load": 0.0}
    monkeypatch.setattr(sweeps, "_process", fake)
    rows = sweeps.processes(sizes=(1000,), repeats=2, log=lambda *a: None)
    assert seen == [[]] * 6 and [r["cases"] for r in rows] == [1, 1000]
