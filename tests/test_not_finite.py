"""Numbers a run cannot compute end as status not-finite (exit 1), naming the quantity and the
time, never as a result; values beyond where double arithmetic holds are refused before a run."""
import math
from pathlib import Path

import numpy as np
import pytest

from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module
from tswm_runtime.simulation.simulate import SimulationInputError, simulate
from tswm_runtime.sweeps.sweep import sweep

ROOT = Path(__file__).resolve().parents[1]
LOAD_STEP = "    return ((F2_before) if (load_piece < 1/2) else (F2_after))\n"
# The same step load, growing as exp(2000 (t - t_step)) after the step: it overflows a double
# (exp(709.8)) 0.3549 s after t_step, so with t_step = 0.3 s and t_end = 1 s mid-run.
OVERFLOWING = "    return ((F2_before) if (load_piece < 1/2) else (F2_after*math.exp(2000.0*(t - p[2]))))\n"
OVERFLOW_AFTER = math.log(np.finfo(np.float64).max / 15000.0) / 2000.0


@pytest.fixture(scope="module")
def overflowing(tmp_path_factory):
    """paper-runup with its load law edited by hand to overflow (a module file; it compiles once)."""
    source = (ROOT / "generated" / "paper_runup.py").read_text()
    assert source.count(LOAD_STEP) == 1
    path = tmp_path_factory.mktemp("edited") / "overflowing.py"
    path.write_text(source.replace(LOAD_STEP, OVERFLOWING))
    return path


@pytest.mark.heavy
def test_a_law_that_overflows_mid_run_ends_not_finite_naming_quantity_and_time(overflowing, capsys):
    result = simulate(str(overflowing))
    assert result.status == "not-finite" and not result.success
    assert result.message.startswith("S2 = -inf N at t = "), result.message
    t_named = float(result.message.split("at t = ")[1].split(" s")[0])
    # the first output point (spacing 1 ms) at which F2 = -15000 exp(2000 (t - 0.3)) N is -inf
    assert 0.3 + OVERFLOW_AFTER <= t_named < 0.3 + OVERFLOW_AFTER + 1e-3
    assert "likely cause" in result.message and "overflows" in result.message
    assert main(["simulate", str(overflowing)]) == 1
    out = capsys.readouterr().out
    assert "status: not-finite: S2 = -inf N at t = " in out


@pytest.mark.heavy
def test_a_sweep_records_not_finite_cases_and_goes_on(overflowing):
    """t_step 0.3 s overflows before t_end = 1 s; t_step 0.8 s would only at 1.15 s: finished."""
    module = load_module(overflowing)
    table = sweep(module, np.array([[200.0, -15000.0, 0.3], [200.0, -15000.0, 0.8]])).table
    assert list(table["status"]) == ["not-finite", "finished"]
    assert "not finite" in table["problem"][0] and table["problem"][1] == ""
    assert np.isfinite(table.loc[1, ["S1m", "S2m", "x1", "v1"]].astype(float)).all()


@pytest.mark.parametrize("value, message", [
    ("1e308", "parameter m2 = 1e+308 kg: |value| must be <= 1e+09 kg"),
    ("1e-12 kg", "parameter m2 = 1e-12 kg: |value| must be >= 1e-09 kg"),
])
def test_masses_beyond_double_arithmetic_are_refused(value, message, capsys):
    """m2 = 1e308 kg printed S1 = inf as a result with exit 0."""
    with pytest.raises(SimulationInputError, match=message.replace("+", r"\+").replace("|", r"\|")):
        simulate("paper", {"m2": value})
    assert main(["simulate", "paper", "--set", f"m2={value}"]) == 2
    assert message in capsys.readouterr().err


def test_a_sweep_over_masses_beyond_the_bounds_marks_them_invalid():
    table = sweep("paper", np.array([[1e308, -5000.0], [200.0, -5000.0]]), {"t_end": 0.01}).table
    assert list(table["status"]) == ["invalid-parameter", "finished"]
    assert "m2 = 1e+308 kg: must be in [1e-09, 1e+09] kg" in table["problem"][0]


def test_forces_of_1e300_are_refused_in_settings_and_parameters(capsys):
    assert main(["simulate", "paper", "--set", "F2=1e300"]) == 2
    assert "parameter F2 = 1e+300 N: |value| must be <= 1e+12 N" in capsys.readouterr().err
    with pytest.raises(SimulationInputError, match=r"^v1 = 1e\+300: \|v1\| must be <= 1e\+12 m/s"):
        simulate("paper", v1=1e300)
