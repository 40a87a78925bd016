"""Calibration (tswm fit) against measurements made by the independent quadrature reference.

The "measurements" come from ``tswm_runtime.reference.quadrature`` (the hand-written force balance
solved by mpmath quadrature at 34 digits; it imports nothing else of tswm) for the paper's
gear at a known m2, so a fit that recovers m2 shows that the model, the batch, the
residuals and the optimiser agree with physics written independently, not with themselves.
"""
import json
import math

import numpy as np
import pandas as pd
import pytest

from tswm_runtime.reference import quadrature as q
from tswm_runtime.fitting.fit import PENALTY, FitInputError, fit, read_measured
from tswm_runtime.fitting.report import write_outputs
from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module

M2_TRUE = 250.0
F2_TRUE = -3000.0
T_STEPS = (0.3, 0.06, 0.1, 0.04)  # load applied after the run-up (peak in the run-up) or during it


def _peaks(m2, F2, t_step):
    tr = q.solve(q.paper_wedge(m2), [(0.0, 0.0), (t_step, F2)], 0.0, 1.0)
    assert tr.status == "finished"
    S = tr.S_extrema()
    return float(S["S1"][0]), float(S["S2"][0])


@pytest.fixture(scope="module")
def runup_peaks():
    """paper-runup at m2 = 250 kg, F2_after = -3000 N, four load times (quadrature reference)."""
    rows = []
    for t_step in T_STEPS:
        S1, S2 = _peaks(M2_TRUE, F2_TRUE, t_step)
        rows.append({"case": f"ts{t_step}", "F2_after": F2_TRUE, "t_step": t_step, "S1m": S1, "S2m": S2})
    return pd.DataFrame(rows)


def test_fit_recovers_m2_from_reference_peaks_csv(runup_peaks, tmp_path):
    path = tmp_path / "peaks.csv"
    runup_peaks.to_csv(path, index=False)
    res = fit("paper-runup", path, ["m2=50:600"], starts=3, grid_points=9)
    assert res.success and res.measured["form"] == "peaks" and res.measured["known"] == ["F2_after", "t_step"]
    assert res.estimate["m2"] == pytest.approx(M2_TRUE, rel=1e-6)
    lo, hi = res.ci["m2"]
    assert lo <= M2_TRUE <= hi and hi - lo < 1e-3 * M2_TRUE
    assert not res.notes, res.notes
    assert all(s.x[0] == pytest.approx(M2_TRUE, rel=1e-5) for s in res.starts)   # every start finds it
    for case in res.cases:
        for d in case["quantities"].values():
            assert abs(d["relative"]) < 1e-6
    # a start far off: the misfit there is large (the fit is not trivially flat)
    assert max(res.misfit["cost"]) > 1e6 * res.cost


def test_noisy_parquet_measurements_ci_covers_the_truth(runup_peaks, tmp_path):
    """1 % seeded noise on every peak: the estimate moves, its CI widens to hold m2 = 250."""
    noisy = runup_peaks.copy()
    rng = np.random.default_rng(7)
    noisy[["S1m", "S2m"]] *= 1 + 0.01 * rng.standard_normal((len(noisy), 2))
    path = tmp_path / "peaks.parquet"
    noisy.to_parquet(path, index=False)
    res = fit("paper-runup", path, {"m2": (50.0, 600.0)}, starts=2, sampler="lhs", seed=3, misfit=False)
    lo, hi = res.ci["m2"]
    assert lo < M2_TRUE < hi
    assert res.estimate["m2"] == pytest.approx(M2_TRUE, rel=0.03)
    assert 0.2 < hi - lo < 0.2 * M2_TRUE  # a real interval: noise is seen, the data still decide
    assert res.dof == 7 and res.s2 > 0 and res.stderr["m2"] > 0


def test_interval_wider_than_the_bounds_is_flagged(runup_peaks, tmp_path):
    """1 % noise determines m2 to a few kg; bounds of +-2 kg cannot be resolved by these data."""
    noisy = runup_peaks.copy()
    noisy[["S1m", "S2m"]] *= 1 + 0.01 * np.random.default_rng(7).standard_normal((len(noisy), 2))
    path = tmp_path / "peaks.csv"
    noisy.to_csv(path, index=False)
    res = fit("paper-runup", path, ["m2=248:252"], starts=2, misfit=False)
    assert any("covers its whole bound range" in n for n in res.notes), res.notes
    assert res.profiles["m2"]["verdict"] == "not determined" and res.ci["m2"] == (-math.inf, math.inf)
    assert any(n.startswith("m2 is not determined by these data") for n in res.notes), res.notes


def _coverage(runup_peaks, tmp_path, cases: int) -> tuple[int, list[float]]:
    """Synthetic data sets: the reference's peaks at m2 = 250 kg plus Gaussian noise of 1 % of each
    quantity's RMS (seeded); even seeds estimate the noise from the residuals, odd seeds state it.
    Returns how many 95 % profile intervals hold the truth, and their widths."""
    sigma = 0.01 * np.sqrt((runup_peaks[["S1m", "S2m"]] ** 2).mean())
    covered, widths = 0, []
    for seed in range(cases):
        noisy = runup_peaks.copy()
        noisy[["S1m", "S2m"]] += np.random.default_rng(seed).standard_normal((len(noisy), 2)) * sigma.to_numpy()
        path = tmp_path / f"noisy{seed}.csv"
        noisy.to_csv(path, index=False)
        stated = {"S1m": float(sigma["S1m"]), "S2m": float(sigma["S2m"])} if seed % 2 else None
        res = fit("paper-runup", path, ["m2=50:600"], starts=1, misfit=False, noise=stated, profile_points=11)
        prof = res.profiles["m2"]
        assert prof["verdict"] == "determined" and prof["noise"] == ("stated" if stated else
                                                                     "estimated from the residuals")
        assert prof["minimum_on_edge"] is None and not (prof["lower"]["edge"] or prof["upper"]["edge"])
        lo, hi = res.ci["m2"]
        assert lo < res.estimate["m2"] < hi
        covered += lo <= M2_TRUE <= hi
        widths.append(hi - lo)
    return covered, widths


@pytest.mark.heavy
def test_profile_intervals_cover_the_truth(runup_peaks, tmp_path):
    """At least 17 of 20 95 % profile intervals must hold the truth (binomial(20, 0.95) gives >= 17
    with probability 0.98), and every interval must be a real one (determined, inside the bounds)."""
    covered, widths = _coverage(runup_peaks, tmp_path, 20)
    assert covered >= 17, covered
    assert 1.0 < min(widths) and max(widths) < 50.0, widths   # noise is seen, and the data still decide


@pytest.mark.slow
def test_profile_intervals_cover_the_truth_over_200_cases(runup_peaks, tmp_path):
    """The same over 200 data sets: at least 180 (90 %; binomial(200, 0.95) falls below that with
    probability 0.001)."""
    covered, _ = _coverage(runup_peaks, tmp_path, 200)
    assert covered >= 180, covered


@pytest.fixture(scope="module")
def runup_after_speed():
    """Reading (c) by the reference: the load acts once the run-up has reached the motor's no-load
    speed (t = 0.3 s). Scene paper-lostmotion with L between 30 and 50 mm of x2 picks its load up
    in that same steady state, so its peaks do not depend on L there."""
    rows = []
    for F2 in (-5000.0, -10000.0, -15000.0):
        S1, S2 = _peaks(200.0, F2, 0.3)
        rows.append({"case": f"F{-F2:g}", "F2_1": F2, "S1m": S1, "S2m": S2})
    return pd.DataFrame(rows)


@pytest.mark.heavy
def test_a_parameter_the_data_do_not_depend_on_is_not_determined(runup_after_speed, tmp_path):
    """Noise-free peaks that do not depend on L: the misfit's differences over L are the
    integrator's error, so L must be reported as not determined, with the range it could take,
    however narrow the linearised interval from that noise is."""
    path = tmp_path / "peaks.csv"
    runup_after_speed.assign(m2=200.0).to_csv(path, index=False)
    for seed in (1, 6):   # starts where the linearised interval alone was 18 and 3.4 mm wide, with no note
        res = fit("paper-lostmotion", path, ["load_at1=0.03:0.05"], starts=1, seed=seed, misfit=False,
                  profile_points=11)
        assert res.cost < 1e-12   # the peaks match the reference: only the integrator's noise is left
        prof = res.profiles["load_at1"]
        assert prof["verdict"] == "not determined" and res.ci["load_at1"] == (-math.inf, math.inf)
        assert prof["range"] == [0.03, 0.05]
        assert prof["numerical"]["floor"] > 0 and prof["numerical"]["different_modes"] == 0
        assert any(n.startswith("load_at1 is not determined by these data") for n in res.notes), res.notes
    write_outputs(res, tmp_path / "out")
    assert "| load_at1 [m] | " in (tmp_path / "out" / "fit-report.md").read_text()
    assert (tmp_path / "out" / "profile.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.heavy
def test_with_noise_or_a_second_free_parameter_it_stays_undetermined(runup_after_speed, tmp_path):
    """Three noisy data sets (0.5 % of each quantity's RMS): L is never called determined. With m2
    free as well (L re-optimised along m2's profile and the other way round) neither is: once the
    drive runs at its no-load speed the reference's peaks are S2m = F2 and an S1m set by F2 alone,
    whatever m2 is."""
    sigma = 0.005 * np.sqrt((runup_after_speed[["S1m", "S2m"]] ** 2).mean()).to_numpy()
    assert runup_after_speed["S2m"].tolist() == pytest.approx(runup_after_speed["F2_1"].tolist(), rel=1e-12)
    for seed in range(3):
        noisy = runup_after_speed.assign(m2=200.0)
        noisy[["S1m", "S2m"]] += np.random.default_rng(seed).standard_normal((len(noisy), 2)) * sigma
        path = tmp_path / f"noisy{seed}.csv"
        noisy.to_csv(path, index=False)
        res = fit("paper-lostmotion", path, ["load_at1=0.03:0.05"], starts=1, misfit=False, profile_points=7)
        assert res.profiles["load_at1"]["verdict"] == "not determined", res.notes
    path = tmp_path / "both.csv"
    runup_after_speed.to_csv(path, index=False)
    res = fit("paper-lostmotion", path, ["m2=100:400", "load_at1=0.03:0.05"], starts=1, misfit=False,
              profile_points=5)
    assert {p["verdict"] for p in res.profiles.values()} == {"not determined"}, res.notes


@pytest.mark.heavy
def test_two_parameters_with_correlation_and_contour(runup_peaks, tmp_path):
    """m2 and F2_after both free (the file gives t_step only): both recovered, a 2x2 correlation,
    a contour plot."""
    path = tmp_path / "peaks.csv"
    runup_peaks.drop(columns=["F2_after"]).to_csv(path, index=False)
    res = fit("paper-runup", path, ["m2=100:400", "F2_after=-6000:-1000"], starts=2, grid_points=5,
              profile_points=7)
    assert res.estimate["m2"] == pytest.approx(M2_TRUE, rel=1e-5)
    assert res.estimate["F2_after"] == pytest.approx(F2_TRUE, rel=1e-5)
    for name, truth in (("m2", M2_TRUE), ("F2_after", F2_TRUE)):   # profiles with the other re-optimised
        lo, hi = res.ci[name]
        assert res.profiles[name]["verdict"] == "determined" and lo <= truth <= hi and hi - lo < 1e-3 * abs(truth)
    corr = np.array(res.correlation)
    assert corr.shape == (2, 2) and np.allclose(np.diag(corr), 1) and abs(corr[0, 1]) < 1
    assert np.array(res.misfit["cost"]).shape == (5, 5)
    paths = write_outputs(res, tmp_path / "out")
    assert sorted(p.name for p in paths) == ["fit-report.md", "fit.json", "misfit.png", "profile.png"]
    assert (tmp_path / "out" / "misfit.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_non_identifiable_m2_is_flagged(tmp_path):
    """Scene `paper` (load from t = 0): the drive sticks, S1 = F1(0) and S2 = F2 whatever m2 is
    (the reference says so too), so m2 cannot be fitted: the fit must say it."""
    rows = []
    for F2 in (-5000.0, -15000.0):
        tr = q.solve(q.paper_wedge(200.0), [(0.0, F2)], 0.0, 1.0)
        S = tr.S_extrema()
        assert [p.mode for p in tr.phases] == ["stick"]
        rows.append({"F2": F2, "S1m": float(S["S1"][0]), "S2m": float(S["S2"][0])})
    path = tmp_path / "stuck.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    res = fit("paper", path, ["m2=50:600"], starts=3, grid_points=5)
    assert any(n.startswith("not identifiable") and "m2" in n for n in res.notes), res.notes
    assert res.ci["m2"] == (-math.inf, math.inf) and res.rank == 0
    assert res.cost < 1e-12  # the stuck peaks themselves agree with the reference
    data = json.loads(json.dumps(res.to_dict()))   # finite JSON: unbounded as null
    assert data["ci"]["m2"] == [None, None]
    write_outputs(res, tmp_path / "out")
    assert "not identifiable" in (tmp_path / "out" / "fit-report.md").read_text()


@pytest.mark.heavy
def test_time_history_of_v1_and_s1(tmp_path):
    """Samples of v1 and S1 during the run-up of two cases (reference: v(t) by quadrature, S1
    from the force balance in the mode the reference reports)."""
    W = q.paper_wedge(M2_TRUE)
    rows = []
    for case, F2, t_step in (("a", -3000.0, 0.06), ("b", -1000.0, 0.3)):
        tr = q.solve(W, [(0.0, 0.0), (t_step, F2)], 0.0, 1.0)
        for t in (0.01, 0.03, 0.05, 0.08, 0.15):
            v = tr.v_at(t)
            load = F2 if t > t_step else 0.0
            rows.append({"case": case, "t": t, "F2_after": F2, "t_step": t_step, "v1": float(v),
                         "S1": float(W.reactions(v, 1, 1, load)[0])})
    path = tmp_path / "history.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    res = fit("paper-runup", path, ["m2=100:400"], overrides={"points": 2001}, starts=2, misfit=False)
    assert res.measured["form"] == "history" and res.measured["cases"] == 2 and res.measured["rows"] == 10
    assert res.estimate["m2"] == pytest.approx(M2_TRUE, rel=1e-4)
    lo, hi = res.ci["m2"]
    assert lo < hi < 1.05 * M2_TRUE and lo > 0.95 * M2_TRUE


def test_failed_cases_carry_the_penalty_and_exit_1(runup_peaks, tmp_path, capsys):
    path = tmp_path / "peaks.csv"
    runup_peaks.to_csv(path, index=False)
    res = fit("paper-runup", path, ["m2=50:600"], overrides={"max_steps": 5}, starts=1, misfit=False)
    assert not res.success and len(res.failed) == 4 and {f["status"] for f in res.failed} == {"max-steps"}
    assert math.isfinite(res.cost) and res.cost == pytest.approx(0.5 * 8 * PENALTY ** 2)
    assert any("did not finish" in n for n in res.notes)
    code = main(["fit", "paper-runup", "--measured", str(path), "--free", "m2=50:600", "--max-steps", "5",
                 "--starts", "1", "--no-plot", "--no-progress", "-o", str(tmp_path / "out")])
    assert code == 1
    data = json.loads((tmp_path / "out" / "fit.json").read_text())
    assert data["success"] is False and len(data["failed"]) == 4


def test_cli_writes_the_report(runup_peaks, tmp_path, capsys):
    path = tmp_path / "peaks.csv"
    runup_peaks.to_csv(path, index=False)
    out = tmp_path / "out"
    code = main(["fit", "paper-runup", "--measured", str(path), "--free", "m2=50:600", "--starts", "2",
                 "--grid-points", "5", "--no-progress", "-o", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "m2 = 250" in text and "95% profile CI" in text and "determined" in text
    data = json.loads((out / "fit.json").read_text())
    assert data["estimate"]["m2"] == pytest.approx(M2_TRUE, rel=1e-6)
    assert data["provenance"]["model_digest"] and data["provenance"]["versions"]["scipy"]
    assert data["settings"]["rtol"] == 1e-9 and data["fit_settings"]["starts"] == 2
    assert len(data["starts"]) == 2 and len(data["cases"]) == 4
    assert {"fit-report.md", "fit.json", "misfit.png", "profile.png"} <= {p.name for p in out.iterdir()}


BASE = "F2_after,t_step,S1m\n-3000,0.1,500\n-3000,0.3,400\n"


@pytest.mark.parametrize("text, free, expected", [
    ("F2_after,t_step,bogus\n-3000,0.1,1\n", "m2=50:600", "unknown column 'bogus'"),
    ("F2_after,t_step,S1m\n-3000,,500\n", "m2=50:600", "column 't_step', data row 1: missing"),
    ("F2_after,t_step,S1m\n-3000,0.1,nan\n", "m2=50:600", "column 'S1m', data row 1: missing"),
    ("F2_after,t_step,S1m\n-3000,0.1,abc\n", "m2=50:600", "column 'S1m', data row 1: 'abc' is not a finite"),
    ("F2_after,t_step,S1m\n-3000,0.1,inf\n", "m2=50:600", "column 'S1m', data row 1"),
    ("F2_after,t_step,S1m\n", "m2=50:600", "no rows"),
    ("F2_after,t_step\n-3000,0.1\n", "m2=50:600", "no measured quantity"),
    (BASE, "mass=50:600", "--free 'mass=50:600': scene 'paper-runup' has no such free parameter"),
    (BASE, "gamma=0:1", "gamma is fixed in this scene"),
    (BASE, "t_step=0:1", "column 't_step' is also given as --free t_step"),
    (BASE, "m2", "give bounds as m2=LO:HI"),
    (BASE, "m2=600:50", "lo = 600 must be < hi = 50"),
    (BASE, "m2=-10:50", "must be > 0 kg"),
    ("F2_after,t_step,S1\n-3000,0.1,5\n", "m2=50:600", "column 'S1' does not belong in peaks"),
    ("t,case,S1m\n0.1,a,5\n", "m2=50:600", "column 'S1m' does not belong in a time history"),
    ("t,case,v1\n-0.1,a,5\n", "m2=50:600", "t = -0.1 s is before the start"),
    ("t,case,v1\n2.5,a,5\n", "m2=50:600", "after t_end = 1 s"),
    ("t,case,F2_after,v1\n0.1,a,-1,5\n0.2,a,-2,5\n", "m2=50:600", "case 'a' has different values"),
    ("case,F2_after,S1m\n<b>,-1,5\n", "m2=50:600", "is not a case label"),
    ("case,F2_after,S1m\nx,-1,5\nx,-2,6\n", "m2=50:600", "label 'x' appears twice"),
    ("S1m\n5\n", "m2=50:600\x00F2_after=-5000:0", "1 measured values for 2 free parameters"),
])
def test_bad_inputs_exit_2_naming_the_problem(tmp_path, capsys, text, free, expected):
    path = tmp_path / "m.csv"
    path.write_text(text)
    argv = ["fit", "paper-runup", "--measured", str(path), "--no-progress", "-o", str(tmp_path / "out")]
    for item in free.split("\x00"):
        argv += ["--free", item]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("tswm fit: error: ") and expected in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


@pytest.mark.parametrize("noise, expected", [
    (["S1m=-5"], "--noise S1m=-5: the noise must be a finite number > 0"),
    (["S1m=5 kg"], "--noise S1m=5 kg: 'kg' is a mass unit"),
    (["bogus=5"], "--noise bogus=5: 'bogus' is not a measured quantity of this file (S1m)"),
    (["S1m=5", "S1m=6"], "--noise S1m: given twice"),
])
def test_bad_noise_exits_2(tmp_path, capsys, noise, expected):
    path = tmp_path / "m.csv"
    path.write_text(BASE)
    argv = ["fit", "paper-runup", "--measured", str(path), "--free", "m2=50:600", "--no-progress",
            "-o", str(tmp_path / "out")]
    for item in noise:
        argv += ["--noise", item]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err, err


def test_bad_files_exit_2(tmp_path, capsys):
    cases = {
        "missing.csv": (None, "no such file"),
        "empty.csv": (b"", "the file is empty"),
        "m.txt": (b"S1m\n5\n", "expected a .csv or .parquet"),
        "latin1.csv": ("S1m,F2_after\n5,\xe9\n".encode("latin-1"), "not UTF-8"),
        "broken.parquet": (b"PAR1 this is not parquet PAR1", "not a readable Parquet file"),
    }
    for name, (data, expected) in cases.items():
        path = tmp_path / name
        if data is not None:
            path.write_bytes(data)
        code = main(["fit", "paper-runup", "--measured", str(path), "--free", "m2=50:600", "--no-progress",
                     "-o", str(tmp_path / "out")])
        err = capsys.readouterr().err
        assert code == 2 and expected in err, (name, err)


def test_scene_without_load_factors_refuses_kd(tmp_path):
    module = load_module("one-sided")
    path = tmp_path / "kd.csv"
    path.write_text("KD1\n1.0\n")
    if module.HAS_LOAD_FACTORS:
        pytest.skip("one-sided gives Ft1, Ft2")
    with pytest.raises(FitInputError, match="no load factors"):
        read_measured(path, module, [])


def test_csv_and_parquet_read_alike(runup_peaks, tmp_path):
    module = load_module("paper-runup")
    runup_peaks.to_csv(tmp_path / "m.csv", index=False)
    runup_peaks.to_parquet(tmp_path / "m.parquet", index=False)
    a = read_measured(tmp_path / "m.csv", module, ["m2"])
    b = read_measured(tmp_path / "m.parquet", module, ["m2"])
    assert a.kind == b.kind == "peaks" and a.cases == b.cases == [f"ts{t}" for t in T_STEPS]
    assert a.known == b.known == ["F2_after", "t_step"] and a.quantities == b.quantities == ["S1m", "S2m"]
    np.testing.assert_array_equal(a.params, b.params)
    np.testing.assert_allclose(a.values, b.values, rtol=1e-15)
