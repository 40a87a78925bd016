"""The bench's targets table: every figure of the speed issue beside its target, with met or missed
judged from the measured numbers and, for a miss, the cost that remains. Hand-made part results
(no timing); tests/test_bench.py checks the table of a tiny real run."""
import math

import pytest

from tswm_runtime.bench import sweeps, targets


def _only(rows):
    (row,) = rows
    return row


def test_fixed_cost_is_judged_against_60_us_and_a_miss_says_by_how_much():
    f = {"case": "run-up then load", "calls": 300, "steps": 1, "whole_us": 90.0, "cpu_us": 85.0, "kernel_us": 30.0,
         "fixed_us": 60.0, "fixed_p90_us": 75.0}
    assert _only(targets.fixed_cost_rows([f]))["verdict"] == "met"
    row = _only(targets.fixed_cost_rows([f | {"fixed_us": 72.5}]))
    assert row["verdict"] == "missed" and row["remaining"].startswith("12.5 us")


def test_speedup_rows_keep_the_target_cases_and_the_40x_target():
    v = {"case": "run-up then load", "error": 1e-6, "tswm_s": 500e-6, "fastest_peer": "LSODA", "peer_s": 15e-3,
         "factor": 30.0, "verdict": "", "target_allows_s": 375e-6, "fixed_cost_s": 100e-6, "floor": "room"}
    rows = targets.speedup_rows([v, v | {"case": "long run T=100"}, v | {"factor": 52.0, "tswm_s": 15e-3 / 52}])
    assert [r["verdict"] for r in rows] == ["missed", "met"]
    assert rows[0]["remaining"].startswith("a call must take 375 us, takes 500 us: 125 us to lose")
    assert "goal met" in rows[1]["measured"]
    assert len(targets.speedup_rows(None, "left out")) == 6


@pytest.mark.parametrize("auto, peer, verdict", [(1e-3, 2e-3, "met"), (3e-3, 2e-3, "missed"),
                                                 (math.nan, 2e-3, "missed"), (1e-3, math.nan, "met")])
def test_auto_is_never_slower_than_the_fastest_peer(auto, peer, verdict):
    c = {"case": "slow load T=100", "error": 1e-9, "auto_s": auto, "fastest_peer": "LSODA", "peer_s": peer}
    assert _only(targets.auto_rows([c]))["verdict"] == verdict


def test_sweep_processes_and_diffrax_rows(monkeypatch):
    def proc(cases, target_cases, wall):
        return {"cases": cases, "target_cases": target_cases, "wall_s_median": wall, "cpu_s_median": wall / 2,
                "load_1min": "1.0", "cases_per_s": cases / wall}
    ends = {"processes": [proc(1, 1, 0.25), proc(1000, 10_000, 0.05), proc(10_000, 100_000, 1.0)],
            "diffrax": {"diffrax": "in this process", "cases": 1000, "tswm_cases_per_s": 9000.0,
                        "timings": [{"diffrax_rtol": 1e-8, "matches_tswm_on": "x1(T) only", "tswm_over_diffrax": 2.0,
                                     "tswm_over_diffrax_cpu": 2.5, "diffrax_cases_per_s": 4500.0}]}}
    rows = targets.sweep_rows(ends)
    assert [r["verdict"] for r in rows] == ["met", "met", "missed", "missed"]
    assert "measured on 1000 cases" in rows[1]["figure"] and rows[1]["target"] == ">= 10000 cases/s"
    assert rows[2]["remaining"].startswith("100 us wall a case, the target allows 33.3 us")
    assert rows[3]["remaining"] == f"tswm's sweep must be {sweeps.DIFFRAX_TARGET / 2:.3g}x faster"
    missing = targets.sweep_rows({"processes": ends["processes"], "diffrax": {"diffrax": "jax not importable"}})
    assert missing[-1]["verdict"] == "not measured" and missing[-1]["remaining"] == "jax not importable"


def test_generate_rows_take_the_slowest_scene_and_compare_the_guards_call():
    def gen(kind, scene, n, wall, outcome="ok"):
        return {"kind": kind, "scene": scene, "breakpoints": n, "wall_s": wall, "cpu_s": wall, "outcome": outcome,
                "load_1min": 1.0}
    generated = [gen("shipped", "paper", None, 2.0), gen("shipped", "mesh", None, 6.0),
                 gen("schedule", "load-t-steps-3", 3, 2.0), gen("schedule", "load-t-steps-999", 999, 3.0)]
    events = [{"breakpoints": 3, "events": 3, "run_s": 0.1, "guards_call_s": 1.0e-9},
              {"breakpoints": 999, "events": 999, "run_s": 0.5, "guards_call_s": 1.2e-9}]
    shipped, schedule, event = targets.generate_rows({"runs": generated, "events": events})
    assert shipped["verdict"] == "missed" and "mesh" in shipped["measured"]
    assert shipped["remaining"].startswith("1 s over on mesh")
    assert schedule["verdict"] == "met" and event["verdict"] == "met"
    generated[-1]["outcome"] = "exit 1"
    events[1]["guards_call_s"] = 2e-9
    _, schedule, event = targets.generate_rows({"runs": generated, "events": events})
    assert schedule["verdict"] == "missed" and "failed: load-t-steps-999" in schedule["measured"]
    assert event["verdict"] == "missed" and event["remaining"] == "a guards() call costs 2x"


def test_the_cold_notice_is_judged_on_the_latest_run():
    def run(mode, message_s, silent=True):
        return {"command": "tswm simulate paper", "TSWM_COLD_START": mode, "message_s": message_s,
                "next_run_s": 1.0, "next_run_silent": silent}
    found, notice = targets.cold_rows([run("background", 0.5), run("foreground", 1.5)])
    assert found["verdict"] == "met" and notice["verdict"] == "missed" and notice["remaining"] == "0.5 s late"
    _, notice = targets.cold_rows([run("foreground", math.nan)])
    assert notice["verdict"] == "missed" and notice["measured"] == "none printed"


def test_chain_rows_judge_the_20x_target():
    result = {"verdicts": [{"level": 1e-6, "peer": "DOP853", "peer_s": 0.02, "tswm_s": 0.001, "factor": 20.0},
                           {"level": 1e-9, "peer": "DOP853", "peer_s": 0.03, "tswm_s": 0.003, "factor": 10.0}]}
    assert [r["verdict"] for r in targets.chain_rows(result)] == ["met", "missed"]
    assert targets.chain_rows(result)[1]["remaining"] == "a call must take 1500 us, takes 3000 us"


def test_every_item_has_rows_when_nothing_was_measured():
    rows = targets.all_rows({}, {})
    assert {r["item"] for r in rows} == {"1", "2", "3", "4", "5", "6"}
    assert all(r["verdict"] == "not measured" and r["target"] and r["remaining"] == "not run" for r in rows)
