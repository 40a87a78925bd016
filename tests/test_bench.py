"""The work-precision benchmark: peers against the independent quadrature reference, the
report files of a tiny run, the verdict arithmetic. No wall-clock comparisons here (the
bench reports times; asserting on them would test the machine's load)."""
import math

import pandas as pd
import pytest

from tswm_runtime.bench import bench, targets
from tswm_runtime.bench import report as bench_report
from tswm_runtime.bench.cases import CASES, errors, reference, run_peer
from tswm_runtime.bench.peers import PeerGaveUp, available_methods, peer_run
from tswm_runtime.cli import main

RUNUP, FLANK, STICK = CASES["run-up then load"], CASES["flank switch near V0"], CASES["decelerate-and-stick"]
SCHEDULE = CASES["load schedule: stall, restart"]


def test_dop853_matches_the_quadrature_reference_on_the_run_up():
    e = errors(run_peer(RUNUP, "DOP853", 1e-10, 1e-13), reference(RUNUP))
    assert e["err"] <= 1e-7 and e["err_t"] == 0.0


@pytest.mark.heavy
@pytest.mark.parametrize("method", available_methods())
@pytest.mark.parametrize("case", [RUNUP, FLANK, STICK, SCHEDULE], ids=lambda c: c.name)
def test_each_peer_agrees_with_the_reference_at_its_tolerance(method, case):
    """rtol 1e-8 (atol 1e-11): the same events as the reference, every error below 1e-5
    (a global error a few hundred times the local tolerance at most; the loosest is
    CVODE's max |S1| taken on its steps without dense output)."""
    out = run_peer(case, method, 1e-8, 1e-11)
    e = errors(out, reference(case))
    assert [k for k, _ in out.events] == [k for k, _ in reference(case).events]
    assert e["err"] <= 1e-5, e


@pytest.mark.parametrize("method", ["RK45", "LSODA", "Radau"])
def test_peers_under_a_load_linear_in_time_agree_with_the_reference(method):
    """slow load T=10 (a load linear in t from 0.05 s): the peer splits at the breakpoint and
    integrates the changing load; at rtol 1e-8 within 1e-5 of the DOP853 reference (rtol 1e-13),
    and tswm's rows agree with it too (tests/test_auto.py)."""
    case = CASES["slow load T=10"]
    out = run_peer(case, method, 1e-8, 1e-11)
    e = errors(out, reference(case))
    assert [k for k, _ in out.events] == ["load"] and e["err"] <= 1e-5, e
    assert out.steps > 0


def test_free_run_up_does_not_chatter_at_synchronous_speed():
    """F2 = 0: phi -> 0 at V0 from above; the guarded peer logs no flank switch, at a loose
    and at a tight tolerance, and still finds the real one under an assisting load."""
    for rtol in (1e-4, 1e-11):
        out = peer_run("RK45", rtol, rtol * 1e-3, 200.0, [(0.0, 0.0)], 0.0, 1.0)
        assert out.events == [] and out.v_end == pytest.approx(7.85, abs=1e-3)
    out = peer_run("LSODA", 1e-10, 1e-13, 200.0, [(0.0, 200.0)], 0.0, 1.0)
    assert [k for k, _ in out.events] == ["phi"]


def test_backward_sliding_is_refused_not_guessed():
    with pytest.raises(PeerGaveUp):
        peer_run("RK45", 1e-6, 1e-9, 200.0, [(0.0, 0.0)], -1.0, 1.0)


def test_cost_at_interpolates_the_front_and_never_extrapolates():
    pts = [(1e-3, 1.0), (1e-6, 10.0), (1e-4, 20.0)]  # (error, time); the last is off the front
    assert bench_report.cost_at(pts, 1e-3) == 1.0
    assert bench_report.cost_at(pts, 1e-2) == 1.0
    assert bench_report.cost_at(pts, 1e-4) == pytest.approx(10 ** (1 / 3))  # a third of the way in log
    assert math.isnan(bench_report.cost_at(pts, 1e-7))


def test_verdicts_report_the_measured_factor():
    rows = [dict(case="c", solver=s, err=e, t_med=t) for s, e, t in (
        ("tswm simulate", 1e-7, 0.002), ("tswm simulate", 1e-10, 0.016),
        ("RK45", 1e-7, 0.05), ("RK45", 1e-10, 0.4), ("LSODA", 1e-7, 0.03))]
    v = {r["error"]: r for r in bench_report.speedup_verdicts(rows)}
    assert v[1e-6]["fastest_peer"] == "LSODA" and v[1e-6]["factor"] == pytest.approx(15.0)
    assert v[1e-6]["verdict"] == "missed: 15x, 2.67x short of the 40x target"
    # at 1e-9, two thirds of the way (in log) from 1e-7 to 1e-10: tswm 0.008 s, RK45 0.2 s
    assert v[1e-9]["fastest_peer"] == "RK45" and v[1e-9]["factor"] == pytest.approx(25.0)
    assert v[1e-9]["verdict"] == "missed: 25x, 1.6x short of the 40x target"
    rows[2]["t_med"] = 0.2  # RK45 at 1e-7 now 100x slower than tswm there, LSODA 15x
    assert bench_report.speedup_verdicts(rows)[0]["verdict"] == "missed: 15x, 2.67x short of the 40x target"
    rows[4]["t_med"] = 0.5
    assert bench_report.speedup_verdicts(rows)[0]["verdict"] == "met: 100x faster (target 40x)"
    assert v[1e-6]["floor"] == "not measured"
    rows.append(dict(case="c", solver=bench_report.TSWM_FIXED_COST, err=math.nan, t_med=0.00625))
    v = {r["error"]: r for r in bench_report.speedup_verdicts(rows)}  # RK45 fastest: 0.2 s at 1e-6, 0.317 s at 1e-9
    assert v[1e-6]["target_allows_s"] == pytest.approx(0.005) and v[1e-6]["fixed_cost_s"] == 0.00625
    assert v[1e-6]["floor"] == "out of reach: a call without steps takes 1.25x the target's time"
    assert v[1e-9]["target_allows_s"] == pytest.approx(0.2 * 2 ** (2 / 3) / 40)
    assert v[1e-9]["floor"] == "room for integration: 0.00169 s"
    assert bench_report.threshold_text(5000.0, 20000.0, "cases/s") == \
        "missed: 5000 cases/s, 4x below the target 20000"
    assert bench_report.threshold_text(3.0, 2.0, "x", higher_is_better=False).startswith("missed: 3 x, 1.5x above")


def test_each_tswm_method_is_timed_down_to_the_tightest_rtol_it_accepts():
    """simulate() refuses an rtol below a method's bound (METHOD_RTOL_MIN): the bench does not ask
    for it, and asks for every method at every rtol the method accepts (the full run failed on it)."""
    from tswm_runtime.model.scenes import load_model
    from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN

    tols = (1e-6, 1e-9, 1e-11)
    timed = {(solver, rtol) for _, solver, rtol, _, _ in bench.configurations([RUNUP], tols, (), 2)}
    own = load_model(RUNUP.scene).RUN["method"]
    for method, (least, _) in METHOD_RTOL_MIN.items():
        solver = "tswm simulate" if method == own else f"tswm simulate {method}"
        assert {rtol for s, rtol in timed if s == solver} == {t for t in tols if t >= least}, method


def test_rounds_time_every_configuration_once_each_in_its_own_order():
    """No configuration always follows the same one (a call finds the caches its predecessor left)."""
    from tswm_runtime.bench.peers import Outcome

    calls = []
    configs = [(RUNUP, bench_report.TSWM_FIXED_COST, 1e-6, lambda i=i: calls.append(i) or Outcome(0.0, 0.0, None, 1), 1)
               for i in range(8)]
    rows = bench.measure(configs, repeats=3, log=lambda *a: None)
    assert calls[:8] == list(range(8)) and all(r["repeats"] == 3 for r in rows)
    rounds = [calls[8 * k:8 * k + 8] for k in (1, 2, 3)]
    assert all(sorted(r) == list(range(8)) for r in rounds)
    predecessors = {i: {r[r.index(i) - 1] for r in rounds if r.index(i) > 0} for i in range(8)}
    assert len({tuple(r) for r in rounds}) == 3 and any(len(p) > 1 for p in predecessors.values())


TINY = dict(quick=True, case_names=["decelerate-and-stick"], peers=("RK45",), tols=(1e-5, 1e-8), repeats=1, sweep_n=2,
            cases=16)


@pytest.mark.heavy
def test_tiny_run_writes_the_report(tmp_path, capsys):
    assert bench.main(output=tmp_path, skip=bench.PARTS, **TINY) == 0
    runs = pd.read_csv(tmp_path / "runs.csv")
    assert set(runs["solver"]) == {"tswm simulate", "tswm simulate rosenbrock23", "tswm simulate rodas4",
                                   "tswm simulate auto",
                                   "tswm simulate points=2",
                                   "tswm sweep per case", "RK45", bench_report.TSWM_FIXED_COST}
    assert (runs["status"] == "finished").all() and (runs["repeats"] == 1).all()
    fixed = runs[runs["solver"] == bench_report.TSWM_FIXED_COST]
    assert len(fixed) == 1 and fixed["err"].isna().all() and (fixed["nfev"] > 0).all()
    assert (runs["t_min"] <= runs["t_med"]).all() and (runs["t_med"] <= runs["t_max"]).all()
    verdicts = pd.read_csv(tmp_path / "verdicts.csv")
    assert list(verdicts["error"]) == [1e-6, 1e-9]
    assert (verdicts["fixed_cost_s"] == fixed["t_med"].iloc[0]).all()
    md = (tmp_path / "work-precision.md").read_text()
    assert "loadavg_before" in md and "cpu" in md and "cases/s" in md
    assert (tmp_path / "work-precision.png").stat().st_size > 1000
    assert "Targets" in capsys.readouterr().out
    table = pd.read_csv(tmp_path / "targets.csv", keep_default_na=False)
    assert set(table["item"]) == {1, 2, 3, 4, 5, 6} and (table["target"] != "").all()
    assert set(table["verdict"]) <= {"met", "missed", "not measured"}
    assert (table[table["item"] == 2]["verdict"] != "not measured").all()  # from the work-precision rows
    assert (table[table["item"] == 3]["remaining"] == "left out of this run").all()
    assert (tmp_path / "work-precision-decelerate-and-stick.png").stat().st_size > 1000


def test_every_timed_call_gets_new_parameters(monkeypatch):
    """simulate() and the peers see an m2 no earlier call had, within 1e-11 of the case's (the reference's)."""
    from tswm_runtime.bench import cases

    seen = []
    monkeypatch.setattr(cases, "peer_run", lambda method, rtol, atol, m2, *a, **k: seen.append(m2))
    for _ in range(3):
        cases.run_peer(STICK, "RK45", 1e-6, 1e-9)
    seen.append(cases.new_m2(RUNUP))
    assert len(set(seen)) == 4 and all(m != 200.0 and abs(m / 200.0 - 1) < 1e-11 for m in seen)


def test_the_figure_has_a_curve_per_method_and_peer_per_case_and_names_machine_and_load():
    """One panel per case, one curve per solver in it (tswm's methods and the peers), log-log, the
    machine and the load in its title."""
    rows = [dict(case=c, solver=s, rtol=r, err=r * f, t_med=r ** -0.2 * f) for c in ("a", "b")
            for s, f in (("tswm simulate", 1.0), ("tswm simulate rosenbrock23", 2.0), ("RK45", 3.0))
            for r in (1e-4, 1e-6, 1e-8)]
    info = {"cpu": "Some CPU", "cores": 2, "loadavg_before": (3.25, 0, 0), "loadavg_after": (4.5, 0, 0)}
    fig = bench_report.work_precision_figure(rows, bench_report.machine_note(info))
    assert fig._suptitle.get_text() == "Some CPU, 2 cores; 1-minute load 3.2 before, 4.5 after"
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["a", "b"]
    for ax in panels:
        assert ax.get_xscale() == ax.get_yscale() == "log"
        assert [line.get_label() for line in ax.get_lines()] == ["tswm simulate", "tswm simulate rosenbrock23", "RK45"]
        assert all(len(line.get_xdata()) == 3 for line in ax.get_lines())


def test_cli_quick_option_reaches_the_bench(monkeypatch, tmp_path):
    seen = {}
    monkeypatch.setattr(bench, "main", lambda **kw: seen.update(kw) or 0)
    assert main(["bench", "--quick", "-o", str(tmp_path)]) == 0
    assert seen == {"quick": True, "output": str(tmp_path), "cases": None}


@pytest.mark.slow
def test_bench_full_run(tmp_path):
    """The full benchmark (a few minutes): every configuration finishes, every target gets a verdict."""
    assert main(["bench", "-o", str(tmp_path)]) == 0
    runs = pd.read_csv(tmp_path / "runs.csv")
    assert (runs["status"] == "finished").all() and set(runs["case"]) == set(CASES)
    verdicts = pd.read_csv(tmp_path / "verdicts.csv")
    assert len(verdicts) == 2 * len(CASES) and verdicts["verdict"].str.match("(met|missed|tswm|no peer)").all()


@pytest.mark.heavy
def test_empty_cache_rows_time_the_message_and_the_first_result(monkeypatch, tmp_path):
    """The empty-cache measurement's mechanics on a stand-in command (the real one compiles for
    minutes: test_bench_full_run): the stderr message and the result line are timed from the
    process start, the targets get verdicts, and the report shows them. The stand-in "fills the
    cache" (a file in NUMBA_CACHE_DIR) on its first run, so in background mode its second run,
    after the wait for the background compile's lock, is silent."""
    fake = ("import os, sys, time; marker = os.path.join(os.environ['NUMBA_CACHE_DIR'], 'filled')\n"
            "if not os.path.exists(marker): print('tswm: compiling the stand-in', file=sys.stderr, flush=True)\n"
            "open(marker, 'w').close(); time.sleep(0.2); print('  status: finished', flush=True)")
    monkeypatch.setattr(bench, "EMPTY_CACHE", [("stand-in", mode, ["-c", fake], "status:")
                                               for mode in ("background", "foreground")])
    background, foreground = bench.empty_cache(log=lambda *a: None)
    for row in (background, foreground):
        assert row["exit"] == 0 and row["message"] == "tswm: compiling the stand-in"
        assert 0 < row["message_s"] < row["first_result_s"] <= row["process_s"]
        assert row["message_verdict"].startswith(("met", "missed")) and row["result_verdict"].startswith("met")
        assert row["over_target_s"] == 0.0
    assert background["process_s"] < background["cache_filled_s"]
    for row in (background, foreground):
        assert row["next_run_silent"] is True and row["next_run_s"] > 0.2
    monkeypatch.setattr(bench, "FORCED_COMPILE", bench.EMPTY_CACHE[1:])
    assert bench.main(output=tmp_path, skip=set(bench.PARTS) - {"empty cache"}, log=lambda *a: None, **TINY) == 0
    md = (tmp_path / "work-precision.md").read_text()
    assert "First run with an empty numba cache" in md and "stand-in" in md and "tswm: compiling the stand-in" in md
    table = pd.read_csv(tmp_path / "targets.csv", keep_default_na=False)
    cold = table[table["item"] == 5]
    assert len(cold) == 2 and set(cold["verdict"]) <= {"met", "missed"}
    assert cold["figure"].iloc[0].startswith("a forced compile leaves a cache that the next run finds (stand-in)")


def test_a_forced_compile_whose_next_run_compiles_again_misses_its_target(monkeypatch):
    """The stand-in never fills its cache: the next run prints its notice again."""
    fake = "import sys; print('tswm: compiling', file=sys.stderr); print('status: x')"
    monkeypatch.setattr(bench, "EMPTY_CACHE", [("never cached", "foreground", ["-c", fake], "status:")])
    rows = bench.empty_cache(log=lambda *a: None)
    assert rows[0]["next_run_silent"] is False
    assert targets.cold_rows(rows)[0]["verdict"] == "missed"


def test_an_empty_cache_that_prints_nothing_is_reported_as_such(monkeypatch):
    monkeypatch.setattr(bench, "EMPTY_CACHE", [("silent", "foreground", ["-c", "print('status: x')"], "status:")])
    (row,) = bench.empty_cache(log=lambda *a: None)
    assert row["message_verdict"] == "none printed" and math.isnan(row["message_s"])
