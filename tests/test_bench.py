"""The work-precision benchmark: a smoke run (CI) and the full run (slow)."""
import math

import pandas as pd
import pytest

from tswm_runtime import bench
from tswm_runtime.cli import main


def test_peer_runner_matches_the_hand_reference():
    """The solve_ivp peer (hand formulas, events, restarts) finds the stop of the
    decelerating gear where tswm does, and sticks there."""
    S, v, t_first, n_events, _ = bench.peer_run("DOP853", 1e-10, 1e-13, 200.0, [(0.0, -15000.0)], 2.0)
    assert v == 0.0 and n_events == 1 and t_first == pytest.approx(0.0190126569, rel=1e-8)
    S, v, t_first, n_events, _ = bench.peer_run("RK45", 1e-6, 1e-9, 200.0, [(0.0, 0.0), (0.3, -15000.0)], 0.0)
    assert t_first == 0.3 and n_events == 1 and 6.0 < v < 7.5


def test_bench_quick_smoke(tmp_path, capsys):
    assert main(["bench", "--quick", "-o", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "work-precision.csv")
    assert set(table["solver"]) == {"tswm dopri5", "RK45"} and len(table) == 4
    assert (table["status"] == "finished").all()
    tswm = table[table["solver"] == "tswm dopri5"]
    # event time error at or below the requested tolerance on the 1 s time scale
    assert (tswm["err_t_first"] <= tswm["rtol"] * 1.0).all() and tswm["err_t_first"].min() < 1e-9
    assert (tswm["time_s"] < tswm["simulate_s"]).all()
    assert "speedup" in (tmp_path / "work-precision.md").read_text()
    assert "decelerate-and-stick" in capsys.readouterr().out


@pytest.mark.slow
def test_bench_full(tmp_path):
    assert bench.main(output=tmp_path, cases=1000) == 0
    speed = pd.read_csv(tmp_path / "speedups.csv")
    assert speed["speedup"].dropna().map(math.isfinite).all()
