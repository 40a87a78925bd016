"""Sweeps: rows equal simulate(), failures recorded, resume, dask, CLI errors."""
import json
import math

import numpy as np
import pandas as pd
import pytest

from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module
from tswm_runtime.results.result import STATUS_NAMES
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.sweeps.rows import REGIME_LETTERS
from tswm_runtime.sweeps.sweep import SweepInputError, grid_cases, parse_grid, read_table, sweep

LETTER = REGIME_LETTERS


def _check_rows_match_simulate(scene, table, overrides):
    module = load_module(scene)
    for row in table.to_dict("records"):
        params = {name: row[name] for name in module.PARAM_NAMES}
        r = simulate(scene, params, **overrides)
        assert row["status"] == r.status, (params, r.message)
        assert row["S1m"] == r.S1_max and row["S2m"] == r.S2_max, params
        assert row["tS1m"] == r.t_S1_max and row["t_stop"] == r.t_stop
        assert row["regimes"] == "".join(LETTER[ph.regime] for ph in r.phases), params
        assert row["n_events"] == len(r.events) and row["steps"] == r.n_steps and row["nfev"] == r.nfev
        if r.status == "finished":
            assert row["v1"] == r.v1[-1] and row["x1"] == pytest.approx(r.x1[-1], rel=1e-14, abs=1e-300)
        if r.KD1 is not None:
            assert row["KD1"] == r.KD1 and row["KD2"] == r.KD2
            Ft1, Ft2 = (params.get(k, module.FIXED.get(k)) for k in ("Ft1", "Ft2"))  # KD = |S max| / Ft, eq. (10)
            assert row["KD1"] == pytest.approx(abs(row["S1m"]) / Ft1, rel=1e-15)
            assert row["KD2"] == pytest.approx(abs(row["S2m"]) / Ft2, rel=1e-15)


def test_sweep_rows_equal_simulate_runup():
    module = load_module("paper-runup")
    P = grid_cases(module, parse_grid(["m2=150:250:2", "F2_after=-15000:5000:3"], module))
    out = sweep("paper-runup", P, {"rtol": 1e-7, "atol": 1e-10}, chunk_size=4)
    assert len(out.table) == 6 and list(out.table.columns[:3]) == ["m2", "F2_after", "t_step"]
    assert set(out.table["t_step"]) == {0.3}
    _check_rows_match_simulate("paper-runup", out.table, {"rtol": 1e-7, "atol": 1e-10})


def test_failed_cases_are_recorded_and_the_sweep_goes_on():
    """paper from v1 = 0.05: m2 = 5000, F2 = 30000 is inconsistent (Painleve), the
    others run; with max_steps = 5 every moving case stops with max-steps."""
    module = load_module("paper")
    P = np.array([[5000.0, 30000.0], [200.0, -15000.0], [200.0, -1000.0]])
    out = sweep(module, P, {"v1": 0.05})
    assert list(out.table["status"]) == ["inconsistent", "finished", "finished"]
    assert out.table["regimes"][1] == "TS"  # slows down and sticks
    _check_rows_match_simulate("paper", out.table, {"v1": 0.05})
    out = sweep(module, P, {"v1": 2.0, "max_steps": 5})
    assert set(out.table["status"]) <= set(STATUS_NAMES.values())
    assert (out.table["status"] == "max-steps").sum() >= 2
    assert math.isnan(out.table["v1"][out.table["status"] == "max-steps"].iloc[0])
    _check_rows_match_simulate("paper", out.table, {"v1": 2.0, "max_steps": 5})


def test_resume_skips_finished_chunks(tmp_path):
    module = load_module("paper")
    P = grid_cases(module, parse_grid(["F2=-15000:-1000:6"], module))
    first = sweep(module, P, {"v1": 2.0}, output=tmp_path, chunk_size=2)
    assert first.computed == [0, 1, 2] and first.skipped == []
    chunks = sorted((tmp_path / "chunks").glob("chunk-*.parquet"))
    assert len(chunks) == 3
    chunks[1].unlink()
    again = sweep(module, P, {"v1": 2.0}, output=tmp_path, chunk_size=2)
    assert again.computed == [1] and again.skipped == [0, 2]
    pd.testing.assert_frame_equal(first.table, again.table)
    changed = sweep(module, P, {"v1": 2.5}, output=tmp_path, chunk_size=2)  # other settings: no reuse
    assert changed.computed == [0, 1, 2]
    pd.testing.assert_frame_equal(read_table(tmp_path / "paper-sweep.parquet"), changed.table)
    pd.testing.assert_frame_equal(read_table(tmp_path / "paper-sweep.csv"), changed.table, check_exact=True)
    written = ["m2 [kg]", "F2 [N]", "status", "problem", "t_stop [s]", "S1m [N]", "tS1m [s]", "S2m [N]", "tS2m [s]",
               "KD1", "KD2", "x1 [m]", "v1 [m/s]", "regimes", "modes", "n_events", "steps", "rejected", "nfev",
               "njev", "n_switches", "impacts", "impact_energy [J]"]
    assert list(pd.read_parquet(tmp_path / "paper-sweep.parquet").columns) == written
    assert list(pd.read_csv(tmp_path / "paper-sweep.csv").columns) == written


def test_dask_local_cluster_rows_equal_in_process_rows():
    distributed = pytest.importorskip("distributed")
    module = load_module("paper-runup")
    P = grid_cases(module, parse_grid(["m2=150:250:2", "F2_after=-15000:5000:2"], module))
    local = sweep(module, P, chunk_size=1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = sweep(module, P, chunk_size=1, client=client)
    assert remote.computed and sorted(remote.computed) == [0, 1, 2, 3]
    pd.testing.assert_frame_equal(local.table, remote.table)


def test_cli_sweep_writes_tables(tmp_path, capsys):
    assert main(["sweep", "paper", "--samples", "5", "--range", "F2=-15000:-1000", "--seed", "3",
                 "-o", str(tmp_path), "--no-progress"]) == 0
    table = pd.read_parquet(tmp_path / "paper-sweep.parquet")
    assert len(table) == 5 and table["F2 [N]"].between(-15000, -1000).all() and (table["m2 [kg]"] == 200).all()
    out = capsys.readouterr().out
    assert "5 cases" in out
    # the run's description beside the tables, as the README says, and named in the output
    about = json.loads((tmp_path / "paper-sweep.json").read_text())
    assert about["scene"] == "paper" and about["cases"] == 5 and about["columns"] == list(table.columns)
    assert about["chunks"] == [path.name for path in sorted((tmp_path / "chunks").glob("chunk-*.parquet"))]
    for name in ("paper-sweep.parquet", "paper-sweep.csv", "paper-sweep.json"):
        assert f"wrote {tmp_path / name}" in out


@pytest.mark.parametrize("argv, fragment", [
    (["--grid", "mass=1:2:3"], "'mass'"),
    (["--grid", "gamma=0.1:0.2:3"], "gamma is fixed"),
    (["--grid", "F2=1:2"], "F2=1:2"),
    (["--grid", "F2=1:2:0"], "count 0 must be in [1, 1e+07]"),
    (["--grid", "F2=a:2:3"], "F2 = 'a': expected a force"),
    (["--samples", "4", "--range", "F2=5:1"], "lo = 5 must be < hi = 1"),
    (["--samples", "0", "--range", "F2=1:5"], "--samples 0"),
    (["--grid", "F2=1:2:2000", "--grid", "m2=1:2:1000"], "2000000 cases, about 440 MB"),
    (["--grid", "F2=1:2:2000", "--grid", "m2=1:2:1000", "--large", "--chunk-size", "1"], "--chunk-size to at least 20"),
    (["--grid", "F2=1:2:99999999999999999999"], "must be in [1, 1e+07]"),
    (["--samples", "3", "--range", "F2=1:5", "--seed", "-1"], "--seed -1"),
    (["--grid", "F2=1:2:2", "--max-events", "1000000000"], "--max-events"),
    (["--grid", "F2=1:2:2", "--atol", "1e-300"], "in [1e-20, 1]"),
    (["--samples", "4"], "--range"),
    ([], "--grid"),
    (["--grid", "F2=1:2:2", "--rtol", "2"], "--rtol"),
])
def test_cli_sweep_bad_input_exits_2_naming_it(argv, fragment, capsys):
    assert main(["sweep", "paper", "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tswm sweep: error: ") and fragment in err, err


def test_parse_grid_single_value_and_duplicates():
    module = load_module("paper")
    assert parse_grid(["F2=-5"], module)["F2"].tolist() == [-5.0]
    assert parse_grid(["F2=-15 kN:-5 kN:3"], module)["F2"].tolist() == [-15000.0, -10000.0, -5000.0]
    assert parse_grid(["m2=0.2 t"], module)["m2"].tolist() == [200.0]
    with pytest.raises(SweepInputError, match="twice"):
        parse_grid(["F2=1:2:2", "F2=3"], module)


def test_mode_sequences_are_spelt_per_case_and_long_ones_end_in_an_ellipsis():
    from types import SimpleNamespace

    from tswm_runtime.sweeps.rows import SEQ_LEN, sequence_texts

    module = SimpleNamespace(MODE_REGIME=("tractive", "stick", "free flight"))
    seq = np.full((4, SEQ_LEN), -1)
    seq[0, :3] = [0, 1, 2]                 # a third mode written but not counted: left out
    seq[1, :] = [0, 2] * (SEQ_LEN // 2)   # exactly SEQ_LEN modes: nothing left out
    seq[2, :] = seq[1]                    # one mode more than kept
    n_modes = np.array([2, SEQ_LEN, SEQ_LEN + 1, 0])
    distinct_regimes, distinct_codes, which = sequence_texts(module, seq, n_modes)
    regimes, codes = np.array(distinct_regimes)[which], np.array(distinct_codes)[which]
    assert list(regimes) == ["TS", "TG" * (SEQ_LEN // 2), "TG" * (SEQ_LEN // 2) + "…", ""]
    assert list(codes) == ["0 1", " ".join(["0 2"] * (SEQ_LEN // 2)), " ".join(["0 2"] * (SEQ_LEN // 2)) + " …", ""]


def test_cases_that_share_a_record_do_not_see_each_other():
    """hybrid/batch.py runs each chunk of CHUNK_CASES cases on one record and parameter vector, reset
    per case: a row is the one its case gets alone, whatever ran before it on that record (here an
    inconsistent case's infinite maxima and latched parameters, finished runs' counts and maxima)."""
    from tswm_runtime.hybrid.batch import CHUNK_CASES
    module = load_module("paper")
    P = np.array([[5000.0, 30000.0], [200.0, -15000.0], [200.0, -1000.0]] * (CHUNK_CASES // 3 + 2))
    table = sweep(module, P, {"v1": 0.05}, chunk_size=len(P)).table
    backwards = sweep(module, P[::-1], {"v1": 0.05}, chunk_size=len(P)).table[::-1].reset_index(drop=True)
    pd.testing.assert_frame_equal(table, backwards)
    alone = sweep(module, P[:3], {"v1": 0.05}, chunk_size=1).table
    for k in range(len(P)):
        assert table.iloc[k].equals(alone.iloc[k % 3]), k
