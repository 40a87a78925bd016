"""Sizes, tolerances and paths without bounds are refused before anything is allocated or run,
naming the option and the allowed range (exit 2, no traceback)."""
import math

import numpy as np
import pytest

from derivation.scene import SceneError, parse_scene
from tswm_runtime.cli import main
from tswm_runtime.simulation.simulate import MAX_EVENTS, MAX_POINTS, SimulationInputError, simulate

from test_injection import PAPER


@pytest.mark.parametrize("argv, named", [
    (["--points", "100000000"], ["--points", "in [1, 1e6]", "MB"]),
    (["--points", "99999999999999999999999999"], ["--points", "in [1, 1e6]"]),
    (["--max-events", "1000000000"], ["--max-events", "in [1, 1e6]", "MB"]),
    (["--max-steps", "1180591620717411303424"], ["--max-steps", "in [1, 1e9]"]),
    (["--atol", "1e-300"], ["--atol", "in [1e-20, 1]"]),
    (["--atol", "1e300"], ["--atol", "in [1e-20, 1]"]),
    (["--rtol", "1e-300"], ["--rtol"]),
    (["--rtol", "0.1"], ["--rtol", "rtol = 0.1", "in [1e-13, 0.01]"]),
    (["--rtol", "1e-13"], ["--rtol", "rtol = 1e-13", ">= 1e-12 with method dopri5"]),
    (["--method", "rosenbrock23", "--rtol", "1e-10"],
     ["--rtol", "rtol = 1e-10", ">= 1e-09 with method rosenbrock23", "use dopri5"]),
    (["--t-end", "inf"], ["t_end", "finite"]),
    (["--set", "F2=1e400"], ["F2", "finite"]),
])
def test_simulate_refuses_unbounded_settings(argv, named, capsys, tmp_path):
    assert main(["simulate", "paper", *argv, "-o", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("tswm simulate: error: ") and "Traceback" not in captured.err
    assert all(part in captured.err for part in named), captured.err
    assert captured.out == "" and not (tmp_path / "out").exists()


def test_limits_are_the_documented_ones():
    assert (MAX_POINTS, MAX_EVENTS) == (10**6, 10**6)
    with pytest.raises(SimulationInputError, match=r"points = 1000001"):
        simulate("paper", points=MAX_POINTS + 1)


def test_remembered_settings_do_not_let_a_lookalike_through():
    """simulate() remembers settings that passed; values equal in Python but not valid (True and
    1.0 for 1) are still refused after the valid one ran, and -0.0 stays -0.0."""
    assert simulate("paper", points=1, t_end=1e-3).settings["points"] == 1
    for bad in (True, 1.0):
        with pytest.raises(SimulationInputError, match=r"points = (True|1\.0): must be an integer"):
            simulate("paper", points=bad, t_end=1e-3)
    for zero in (0.0, np.float64(0.0)):
        assert math.copysign(1.0, simulate("paper", points=2, t_end=1e-3, x1=zero).settings["x1"]) == 1.0
        assert math.copysign(1.0, simulate("paper", points=2, t_end=1e-3, x1=-zero).settings["x1"]) == -1.0


@pytest.mark.parametrize("command", [["generate", "paper"], ["simulate", "paper", "--no-plot"],
                                     ["sweep", "paper", "--grid", "F2=1:2:2", "--no-progress"],
                                     ["paper", "--no-derivation", "--no-progress"]])
def test_output_naming_an_existing_file_is_refused_before_any_work(command, tmp_path, capsys):
    target = tmp_path / "a-file"
    target.write_text("keep me")
    assert main([*command, "-o", str(target)]) == 2
    captured = capsys.readouterr()
    assert "exists and is not a directory" in captured.err and str(target) in captured.err
    assert captured.out == "" and target.read_text() == "keep me"


@pytest.mark.parametrize("text, named", [
    ("a = " + "[" * 5000 + "]" * 5000, "nested too deeply"),
    ('name = "x"\nwedge = ' + "{a = " * 600 + "1" + "}" * 600, "nested too deeply"),
    (PAPER.replace('name = "paper"', 'name = "' + "a" * 5000 + '"'), "(5000 characters)"),
    (PAPER.replace('description = "', 'description = "' + "d" * 3000), "at most 2000"),
    ("# " + "x" * 1_000_001, "at most 1000000 bytes"),
])
def test_hostile_scene_files_are_refused_cleanly(text, named, tmp_path, capsys):
    with pytest.raises(SceneError, match="s.toml") as error:
        parse_scene(text, "s.toml")
    assert named in str(error.value) and len(str(error.value)) < 500
    path = tmp_path / "s.toml"
    path.write_text(text)
    assert main(["derive", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tswm derive: error: ") and named in err


@pytest.mark.parametrize("argv, named", [
    (["paper", "--case", "inf,-15000", "--no-derivation", "--no-progress"], "--case inf,-15000"),
    (["paper", "--case", "-5,-15000", "--no-derivation", "--no-progress"], "--case"),
    (["paper", "--case", "0,1", "--no-derivation", "--no-progress"], "M2 must be a finite mass > 0"),
    (["bench", "--cases", "99999999999999999999"], "--cases 99999999999999999999: must be in [1, 1e+07]"),
])
def test_paper_and_bench_refuse_unusable_sizes_and_cases(argv, named, capsys, tmp_path):
    try:
        code = main([*argv, "-o", str(tmp_path / "out")])
    except SystemExit as stop:   # argparse's own refusal ("-5,..." reads as an option)
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and named in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_promises_page_states_the_limits_the_code_enforces():
    from pathlib import Path

    from tswm_runtime.simulation import simulate as sim
    from tswm_runtime.sweeps import sweep

    page = (Path(__file__).resolve().parents[1] / "docs" / "promises.md").read_text()
    rows = {
        "`--points` | [1, 10^{}]".format(round(math.log10(sim.MAX_POINTS))): "simulate.MAX_POINTS",
        "`--max-events` | [1, 10^{}]".format(round(math.log10(sim.MAX_EVENTS))): "simulate.MAX_EVENTS",
        "`--max-steps` | [1, 10^{}]".format(round(math.log10(sim.MAX_STEPS))): "simulate.MAX_STEPS",
        "`--atol` | [{:g}, {:g}]".format(*sim.ATOL_RANGE): "simulate.ATOL_RANGE",
        "`--rtol` | [{:g}, {:g}]".format(*sim.RTOL_RANGE): "simulate.RTOL_RANGE",
        "dopri5 from {:g}, rosenbrock23 from {:g}".format(sim.METHOD_RTOL_MIN["dopri5"][0],
                                                          sim.METHOD_RTOL_MIN["rosenbrock23"][0]):
            "simulate.METHOD_RTOL_MIN",
        "above 10^{} the sweep".format(round(math.log10(sweep.LARGE_SWEEP))): "sweep.LARGE_SWEEP",
        "above 10^{} refused".format(round(math.log10(sweep.MAX_SWEEP_CASES))): "sweep.MAX_SWEEP_CASES",
    }
    for text, constant in rows.items():
        assert text in page and constant in page, (text, constant)


@pytest.mark.parametrize("command", [["sweep", "paper", "--grid", "F2=-5000:-4000:2", "--no-progress"],
                                     ["fit", "paper", "--measured", "unused.csv", "--free", "m2=100:400"]])
def test_sweep_and_fit_hold_rtol_to_the_same_bound(command, capsys, tmp_path):
    """rtol 0.1 left S1 max of paper-runup 90 % off a run at rtol 1e-12 with status finished: refused
    by every command that runs the model, naming the option."""
    assert main([*command, "--rtol", "0.1", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "--rtol" in err and "rtol = 0.1" in err and "Traceback" not in err, err


def test_scene_run_rtol_has_the_same_bound():
    with pytest.raises(SceneError, match=r"run.rtol = 0.1: must be in \[1e-13, 0.01\]"):
        parse_scene(PAPER.replace("rtol = 1e-6", "rtol = 0.1"), "s.toml")


def test_atol_loose_against_the_states_reached_is_refused(capsys):
    """paper-runup: v1 runs up towards the drive's V0 = 7.85 m/s (the scene file), so
    atol = 1 m/s lets a step be off by 13 % of it; refused naming --atol (exit 2), and a tight atol runs."""
    assert main(["simulate", "paper-runup", "--atol", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tswm simulate: error: --atol: atol = 1: must be <= 0.01 x the largest |state|"), err
    assert "v1" in err
    with pytest.raises(SimulationInputError, match=r"^atol = 0.1: "):
        simulate("paper-runup", atol=0.1)
    assert simulate("paper-runup", atol=1e-3).status == "finished"
