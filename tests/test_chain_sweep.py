"""The chain batch (tswm_runtime/chains/batch.py) against single runs, and the chain sweep's chunks
(tswm_runtime/sweeps/chain.py): every answer of every case as simulate_chain gives it, bit for bit (both
read it from their run's record with chains/answers.py; the runs themselves are the batch's and
run_chain's), over grids with cases that stall, never trip, stop (too many events, a Painleve case at
the start) or are refused; a chunk removed is recomputed alone and the table is the same."""
from __future__ import annotations

import math

import numpy as np
import pytest

from tests.chains import TIGHT, wedges
from tswm_runtime.chains.batch import run_cases
from tswm_runtime.chains.run import first_room
from tswm_runtime.model.contract import load_module
from tswm_runtime.simulation.chain import settings, simulate_chain
from tswm_runtime.sweeps import columns
from tswm_runtime.sweeps.chain import case_rows, sizing

PAINLEVE = wedges("painleve", gammas=(5.0,), mus=(math.tan(8 * math.pi / 180),), masses=(1.0, 1000.0),
                  forces=(100.0, 0.0))
VOLTAGES = [0.05, 0.2, 0.25, 0.8, 1.0, 2.0]   # no start, a stall before the trip, moving on the seat at the end, holds


def _number(value) -> float:
    return math.nan if value is None else float(value)


def _batch_and_single(module, voltages, overrides, params=None):
    """(the batch's answers, one simulate_chain per case) for the scene's values with ``params`` at
    ``voltages`` (its p rows as the sweep prepares them: sweeps.chain.case_rows)."""
    run = settings(module, overrides)
    with_voltage = hasattr(module, "MOTOR_VOLTAGE")
    cases = [{**(params or {}), **({"voltage": v} if with_voltage else {})} for v in voltages]
    swept = sorted({name for case in cases for name in case})
    P, refused = case_rows(module, run, swept, np.array([[case[n] for n in swept] for case in cases]))
    assert refused == [None] * len(cases)
    batch = run_cases(module, P, t_end=run["t_end"], v0=run["v0"], rtol=run["rtol"], atol=run["atol"],
                      t_out=np.linspace(0.0, run["t_end"], run["points"]), max_steps=run["max_steps"],
                      max_events=run["max_events"])
    singles = [simulate_chain(module, case, **overrides) for case in cases]
    return batch, singles


def _assert_same(batch, singles):
    assert [batch.status_words[k] for k in batch.status] == [r.status for r in singles]
    assert [batch.verdict_words[k] for k in batch.verdict] == [r.answers["holds"]["verdict"] for r in singles]
    expected = {"t_stop": [r.t_stop for r in singles], "events": [len(r.events) for r in singles],
                "steps": [r.n_steps for r in singles]}
    trips = [r.answers["trip"] or {} for r in singles]
    peaks = [r.answers["peak_after_trip"] or {} for r in singles]
    for name, key in (("t_trip", "t"), ("thrust", "thrust"), ("drive", "drive"), ("travel", "travel")):
        expected[name] = [_number(t.get(key)) for t in trips]
    expected["peak"] = [_number(p.get("thrust")) for p in peaks]
    expected["t_peak"] = [_number(p.get("t")) for p in peaks]
    expected["extra_travel"] = [_number(r.answers["extra_travel"]) for r in singles]
    for name, values in expected.items():
        np.testing.assert_array_equal(getattr(batch, name), np.array(values), err_msg=name)
    for name in ("needed", "pull_out", "stall_margin"):
        np.testing.assert_array_equal(getattr(batch, name), [_number(r.answers[name]) for r in singles], err_msg=name)


@pytest.mark.parametrize("overrides", [{}, {"t_end": 2.2}, {"max_events": 3}], ids=["scene", "short", "few-events"])
def test_the_batch_gives_every_answer_of_single_runs(overrides):
    """mov over voltages from one that cannot start the motor to twice the rated one: at 0.05 the chain
    never moves, at 0.2 it stalls before the switch trips, at 0.25 it trips but still moves on the seat at
    3 s, above it holds; a run of 2.2 s ends before the hold is decided; 3 events stop the runs that move
    (too-many-events) beside those that finish. Each case's answers equal the single run's bit for bit."""
    module = load_module("mov")
    batch, singles = _batch_and_single(module, VOLTAGES, overrides)
    _assert_same(batch, singles)
    words = {r.answers["holds"]["verdict"] for r in singles}
    if not overrides:
        assert {"no trip: the motor was not cut", "holds",
                "undecided: still moving on the seat at the end of the run"} <= words
        assert not np.isnan(batch.peak[-1]) and batch.peak[-1] > batch.thrust[-1] > 0 < batch.extra_travel[-1]
    if "max_events" in overrides:
        assert {"finished", "too-many-events"} <= {r.status for r in singles}


@pytest.mark.parametrize("mu_2", [0.05, 0.15, 0.3])
def test_the_batch_gives_the_single_runs_answers_for_any_friction(mu_2):
    """mu_2 a slot of p: the stem nut does not self-lock at 0.05 (tan 4.55 deg = 0.0796 > 0.05 / cos 15 deg),
    self-locks at 0.15 and 0.3; every answer per case equals the single run's with the same values."""
    module = load_module("mov")
    batch, singles = _batch_and_single(module, [0.8, 1.0], {}, {"mu_2": mu_2})
    _assert_same(batch, singles)
    assert [r.answers["holds"]["self_locking"] == [2] for r in singles] == [mu_2 > 0.1] * 2


def test_the_batch_reports_a_painleve_case_as_the_single_run(chain_module):
    """A light input on a heavy output through a self-locking wedge: indeterminate at the start, in the
    batch as in the single run (no motor, no switch: no trip)."""
    module = chain_module(PAINLEVE)
    batch, singles = _batch_and_single(module, [1.0, 1.0], TIGHT)
    assert [r.status for r in singles] == ["indeterminate"] * 2
    _assert_same(batch, singles)


def test_a_run_of_more_phases_than_the_first_record_holds_is_run_again_with_more_room(chain_module):
    """A frictionless wedge on a spring oscillates: every reversal is an event, 12 s make more phases than
    the record's first room (kernel.RECORD_FULL); the batch runs those cases again with twice the room and
    gives the single run's answers."""
    module = chain_module(wedges("oscillator", gammas=(30.0,), mus=(0.0,), masses=(1.0, 1.0), forces=(0.0, 0.0),
                                 spring=400.0, v0=1.0, t_end=12.0))
    batch, singles = _batch_and_single(module, [1.0, 1.0, 1.0], {})
    assert [r.status for r in singles] == ["finished"] * 3 and len(singles[0].events) > first_room(1000) + 1
    _assert_same(batch, singles)


def test_a_refused_case_is_recorded_and_the_sweep_goes_on():
    """voltage 3 is refused by the run settings (U / U_n in (0, 2]), mu_2 = 11 by the scene's range: their
    rows say so, the others run and give the single runs' answers."""
    module = load_module("mov")
    table = sizing(module, {"mu_2": [0.15, 11.0], "voltage": [1.0, 3.0, 0.05]}, {}).table
    assert list(table["status"][:3]) == ["finished", "error: voltage = 3.0: must be U / U_n in (0, 2]", "finished"]
    assert all(s.startswith("error: parameter mu_2 = 11") for s in table["status"][3:]), list(table["status"][3:])
    assert list(table["holds"]) == ["holds", "-", "no trip: the motor was not cut", "-", "-", "-"]
    answers = simulate_chain(module, {"mu_2": 0.15, "voltage": 1.0}).answers
    assert table["thrust at trip [N]"][0] == answers["trip"]["thrust"]
    assert table["peak after trip [N]"][0] == answers["peak_after_trip"]["thrust"]
    assert table["extra travel [m]"][0] == answers["extra_travel"]
    assert table["stall margin"][0] == answers["stall_margin"]
    assert math.isnan(table["t_trip [s]"][1]) and math.isnan(table["stall margin"][2])


def test_a_chunk_removed_is_recomputed_alone_and_the_table_is_the_same(tmp_path):
    """Chunks of 2 cases: a rerun reuses all; with one chunk file removed and another altered, only those
    are recomputed (the altered one with a warning) and the table is the same, column for column."""
    module = load_module("mov")
    grid = {"voltage": [0.2, 0.8, 0.9, 1.0, 1.1]}
    first = sizing(module, grid, {"max_events": 4}, output=tmp_path, chunk_size=2)
    assert first.computed == [0, 1, 2] and (tmp_path / "mov-sizing.csv").exists()
    again = sizing(module, grid, {"max_events": 4}, output=tmp_path, chunk_size=2)
    assert again.computed == [] and again.skipped == [0, 1, 2]
    files = sorted((tmp_path / "chunks").glob("chunk-*.parquet"))
    files[1].unlink()
    files[2].write_bytes(files[2].read_bytes()[:-40])
    resumed = sizing(module, grid, {"max_events": 4}, output=tmp_path, chunk_size=2)
    assert resumed.computed == [1, 2] and resumed.skipped == [0] and [i for i, _ in resumed.rejected] == [2]
    assert columns.digest(resumed.rows) == columns.digest(first.rows)
    other = sizing(module, grid, {"max_events": 5}, output=tmp_path, chunk_size=2)
    assert other.computed == [0, 1, 2]   # another setting: no chunk of the first sweep is reused
