"""The Python API (``import tswm_runtime as tswm``): docs/api.md's examples run; scene files and
unit strings give the closed-form answers; bad input is refused with the CLI's message naming it;
``tswm fit`` reads the tables ``tswm simulate -o`` and ``tswm sweep -o`` write and recovers the
parameter they were made at.

The wedge of docs/api.md's scene file (constant drive F1, constant load F2, constant friction
angle rho, one flank) slides with constant acceleration a1 = (F1 + psi F2) / (m1 + psi m2 tan
gamma), psi = tan(gamma + rho), from rest: v1(t) = a1 t. Fits use data made at m2 = 250 kg and
compare the estimate with 250 kg.
"""
import contextlib
import io
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import tswm_runtime as tswm
from tswm_runtime.cli import main
from tswm_runtime.fitting.inputs import FitInputError, read_measured
from tswm_runtime.jit import coldstart
from tswm_runtime.model.contract import load_module
from tswm_runtime.startup import warmup
from tswm_runtime.sweeps.sweep import read_table

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "api.md").read_text()
BLOCK = re.search(r"write_text\('''(.*?)'''\)", PAGE, re.S)[1]   # the page's scene file
M2_TRUE = 250.0
RUNUP = ["--set", "m2=250", "--set", "F2_after=-3 kN", "--set", "t_step=0.06"]
TIGHT = ["--rtol", "1e-9", "--atol", "1e-12"]   # the fit's tolerances (fit.FIT_RUN)


def block_v1(F2: float, t: float) -> float:
    """v1(t) of the page's block scene by its closed form (gamma 10 deg, rho 5 deg, F1 50 N, m1 2 kg, m2 3 kg)."""
    g, rho = math.radians(10), math.radians(5)
    psi = math.tan(g + rho)
    return (50.0 + psi * F2) / (2.0 + psi * 3.0 * math.tan(g)) * t


@pytest.fixture(scope="module")
def scene_cache(tmp_path_factory):
    """One user cache for the module's scene files: the block scene is generated and compiled once."""
    with pytest.MonkeyPatch.context() as patch:
        cache = tmp_path_factory.mktemp("tswm-cache")
        patch.setenv("TSWM_CACHE", str(cache))
        yield cache


@pytest.fixture
def block(scene_cache, tmp_path):
    path = tmp_path / "block.toml"
    path.write_text(BLOCK)
    return path


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_the_page_examples_run_and_compute_the_truth(scene_cache, tmp_path, monkeypatch, capsys):
    """Every python block of docs/api.md, in order, in an empty directory; then their numbers
    against the closed form and the parameter the data were made at."""
    blocks = _python_blocks(PAGE)
    assert len(blocks) >= 6
    monkeypatch.chdir(tmp_path)
    ns = {}
    for code in blocks:
        exec(compile(code, "docs/api.md", "exec"), ns)
    printed = capsys.readouterr().out
    assert "parameter F2 = '-5 kg': 'kg' is a mass unit" in printed
    assert ns["block"].params == {"F2": -30.0}
    assert ns["block"].v1[-1] == pytest.approx(block_v1(-30.0, 0.25), rel=1e-9)
    assert ns["swept"].table["t_step"].tolist() == pytest.approx([0.04, 0.04 + 0.26 / 3, 0.04 + 0.52 / 3, 0.3])
    assert ns["fitted"].estimate["m2"] == pytest.approx(M2_TRUE, rel=1e-6)
    assert ns["from_sweep"].estimate["m2"] == pytest.approx(M2_TRUE, rel=1e-6)
    assert ns["fitted"].profiles["m2"]["verdict"] == "determined"
    assert ns["fitted"].ci["m2"][0] <= M2_TRUE <= ns["fitted"].ci["m2"][1]
    assert {p.name for p in (tmp_path / "fit").iterdir()} == {"fit-report.md", "fit.json", "misfit.png",
                                                              "profile.png"}
    assert (tmp_path / "block-derivation.md").read_text().count("$$") >= 2
    assert set(ns["sampled"].table["F2"]) == set(np.random.default_rng(1).uniform(-20000.0, 5000.0, 20))


def test_import_loads_no_kernels_and_no_sympy():
    script = ("import sys\nimport tswm_runtime as tswm\n"
              "functions = [tswm.simulate, tswm.sweep, tswm.fit, tswm.derive]\n"
              "assert {'simulate', 'sweep', 'fit', 'derive'} <= set(dir(tswm))\n"
              "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'sympy', 'derivation', 'generated')"
              " or m.startswith(('tswm_runtime.hybrid', 'tswm_runtime.integration'))))\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert out.strip() == "[]"
    with pytest.raises(AttributeError, match="no attribute 'simulat'"):
        tswm.simulat  # noqa: B018


def test_scene_file_and_unit_strings(block):
    run = tswm.simulate(block, {"F2": "-0.03 kN"}, t_end="250 ms", points=11)
    assert run.status == "finished" and run.params == {"F2": -30.0} and run.settings["t_end"] == 0.25
    np.testing.assert_allclose(run.v1, [block_v1(-30.0, t) for t in run.t], rtol=1e-9, atol=1e-12)
    swept = tswm.sweep(str(block), {"F2": "-30 N:-0.01 kN:3"}, t_end=0.4)
    assert swept.table["F2"].tolist() == [-30.0, -20.0, -10.0]
    np.testing.assert_allclose(swept.table["v1"], [block_v1(F2, 0.4) for F2 in (-30.0, -20.0, -10.0)], rtol=1e-9)
    cli_strings = tswm.sweep(str(block), ["F2=-30:-10:3"], t_end=0.4)
    pd.testing.assert_frame_equal(cli_strings.table, swept.table)


def test_samples_in_ranges_with_units():
    out = tswm.sweep("paper", samples=5, ranges={"F2": ("-20 kN", "5 kN"), "m2": "0.1 t:400 kg"}, seed=3, t_end=0.01)
    rng = np.random.default_rng(3)
    F2, m2 = rng.uniform(-20000.0, 5000.0, 5), rng.uniform(100.0, 400.0, 5)
    np.testing.assert_array_equal(out.table["F2"], F2)
    np.testing.assert_array_equal(out.table["m2"], m2)


@pytest.mark.parametrize("call, named", [
    (lambda: tswm.simulate("no-such-scene"), "scene 'no-such-scene': no generated module"),
    (lambda: tswm.simulate("missing/scene.toml"), "missing/scene.toml"),
    (lambda: tswm.simulate("missing/model.py"), "scene 'missing/model.py': no such file"),
    (lambda: tswm.simulate("paper", {"F2": "-5 kg"}), "parameter F2 = '-5 kg': 'kg' is a mass unit"),
    (lambda: tswm.simulate("paper", {"F2": "five"}), "parameter F2 = 'five': expected a force"),
    (lambda: tswm.simulate("paper", {"Fx": 1.0}), "parameter 'Fx': scene 'paper' has no such free parameter"),
    (lambda: tswm.simulate("paper", rtol=5), "rtol = 5"),
    (lambda: tswm.simulate("paper", t_end="2 kg"), "t_end = '2 kg'"),
    (lambda: tswm.sweep("paper", {"F2": "-5 kg:0:3"}), "--grid 'F2=-5 kg:0:3': parameter F2 = '-5 kg'"),
    (lambda: tswm.sweep("paper", {"mass": "1:2:3"}), "--grid 'mass'"),
    (lambda: tswm.sweep("paper", {"F2": None}), "--grid F2=None"),
    (lambda: tswm.sweep("paper"), "give --grid"),
    (lambda: tswm.sweep("paper", {"F2": 1.0}, samples=3), "not both"),
    (lambda: tswm.sweep("paper", samples=3, ranges={"F2": ("5 kN", "1 kN")}), "lo = 5000 must be < hi = 1000"),
    (lambda: tswm.fit("paper-runup", "missing.csv", {"m2": (50, 600)}), "--measured missing.csv: no such file"),
    (lambda: tswm.fit("paper-runup", "missing.csv", {"mass": (1, 2)}), "--free 'mass=1:2'"),
    (lambda: tswm.fit("paper-runup", "missing.csv", {"m2": (1, 2, 3)}), "--free m2=(1, 2, 3)"),
    (lambda: tswm.fit("paper-runup", "missing.csv", {"m2": "50 kg:600 s"}), "parameter m2 = '600 s'"),
    (lambda: tswm.fit("paper-runup", pd.DataFrame(), ["m2=50:600"]), "measured = DataFrame: expected the path"),
    (lambda: tswm.derive("no-such-scene"), "no-such-scene: cannot read scene file"),
], ids=["scene", "toml", "py", "unit", "word", "param", "rtol", "t-end-unit", "grid-unit", "grid-name",
        "grid-none", "no-grid", "grid-and-samples", "range-order", "measured", "free-name", "free-triple",
        "free-unit", "measured-frame", "derive"])
def test_bad_input_is_a_value_error_naming_it(call, named):
    with pytest.raises(ValueError) as caught:
        call()
    assert named in str(caught.value)


@pytest.mark.parametrize("argv, api", [
    (["simulate", "paper", "--set", "F2=-5 kg"], lambda: tswm.simulate("paper", {"F2": "-5 kg"})),
    (["sweep", "paper", "--grid", "F2=-5 kg:0:3"], lambda: tswm.sweep("paper", {"F2": "-5 kg:0:3"})),
    (["fit", "paper-runup", "--measured", "missing.csv", "--free", "m2=50:600"],
     lambda: tswm.fit("paper-runup", "missing.csv", ["m2=50:600"])),
])
def test_the_cli_prints_the_api_message(argv, api, capsys):
    with pytest.raises(ValueError) as caught:
        api()
    assert main(argv) == 2
    assert capsys.readouterr().err == f"tswm {argv[0]}: error: {caught.value}\n"


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """`tswm simulate paper-runup -o` at m2 = 250 kg, F2_after = -3 kN, t_step = 0.06 s, at the output
    points the fit's runs have (1001 by default), so that S1 and S2 are compared where both were computed."""
    out = tmp_path_factory.mktemp("simulated")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "paper-runup", *RUNUP, *TIGHT, "--no-plot", "-o", str(out)]) == 0
    return out / "paper-runup.csv"


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """`tswm sweep paper-runup -o` over four load times at m2 = 250 kg, F2_after = -3 kN."""
    out = tmp_path_factory.mktemp("swept")
    argv = ["sweep", "paper-runup", "--grid", "m2=250", "--grid", "F2_after=-3 kN", "--grid", "t_step=0.04:0.3:4",
            *TIGHT, "--no-progress", "-o", str(out)]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(argv) == 0
    return out


def test_fit_recovers_m2_from_the_csv_simulate_writes(simulated):
    header = simulated.read_text().splitlines()[0]
    assert header.startswith("t [s],x1 [m],v1 [m/s],") and header.endswith(",mode,regime")
    res = tswm.fit("paper-runup", simulated, {"m2": ("50 kg", "0.6 t")}, starts=2, plot=False)
    assert res.measured["form"] == "history" and res.measured["rows"] == 1001
    assert res.measured["quantities"] == ["v1", "S1", "S2"] and res.measured["known"] == ["F2_after", "t_step"]
    assert res.estimate["m2"] == pytest.approx(M2_TRUE, rel=1e-6) and res.success


def test_simulate_csv_without_its_summary_runs_at_the_scenes_values(simulated, tmp_path):
    lone = tmp_path / simulated.name
    lone.write_bytes(simulated.read_bytes())
    measured = read_measured(lone, load_module("paper-runup"), ["m2"])
    assert measured.known == [] and measured.quantities == ["v1", "S1", "S2"]
    (tmp_path / "paper-runup-summary.json").write_text(json.dumps({"scene": "paper", "params": {}}))
    with pytest.raises(FitInputError, match="a run of scene 'paper', not 'paper-runup'"):
        read_measured(lone, load_module("paper-runup"), ["m2"])


@pytest.mark.parametrize("name", ["paper-runup-sweep.parquet", "paper-runup-sweep.csv"])
def test_fit_recovers_m2_from_the_tables_sweep_writes(swept, name, tmp_path, capsys):
    code = main(["fit", "paper-runup", "--measured", str(swept / name), "--free", "m2=50:600", "--starts", "2",
                 "--no-plot", "--no-progress", "-o", str(tmp_path)])
    assert code == 0, capsys.readouterr().err
    data = json.loads((tmp_path / "fit.json").read_text())
    assert data["estimate"]["m2"] == pytest.approx(M2_TRUE, rel=1e-6)
    assert data["measured"]["known"] == ["F2_after", "t_step"]
    assert data["measured"]["quantities"] == ["S1m", "S2m", "KD1", "KD2"]
    assert data["measured"]["cases"] == 4


def test_written_sweep_columns_carry_units_and_read_back(swept):
    written = pd.read_parquet(swept / "paper-runup-sweep.parquet")
    assert list(written.columns[:9]) == ["m2 [kg]", "F2_after [N]", "t_step [s]", "status", "problem", "t_stop [s]",
                                         "S1m [N]", "tS1m [s]", "S2m [N]"]
    assert {"KD1", "x1 [m]", "v1 [m/s]", "impact_energy [J]"} <= set(written.columns)
    assert list(pd.read_csv(swept / "paper-runup-sweep.csv").columns) == list(written.columns)
    back = read_table(swept / "paper-runup-sweep.csv")
    assert back["t_step"].tolist() == pytest.approx([0.04, 0.04 + 0.26 / 3, 0.04 + 0.52 / 3, 0.3])
    pd.testing.assert_frame_equal(back, read_table(swept / "paper-runup-sweep.parquet"))


def test_a_sweep_row_that_did_not_finish_is_refused(tmp_path, capsys):
    out = tmp_path / "sweep"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["sweep", "paper-runup", "--grid", "t_step=0.04:0.3:2", "--max-steps", "5", "--no-progress",
                     "-o", str(out)]) == 0
    assert main(["fit", "paper-runup", "--measured", str(out / "paper-runup-sweep.csv"), "--free", "m2=50:600",
                 "--no-progress", "-o", str(tmp_path / "fit")]) == 2
    err = capsys.readouterr().err
    assert "column 'status', data row 1: 'max-steps': that run did not finish" in err and "2 of 2" in err


def test_a_sweep_over_the_fitted_parameter_is_refused(tmp_path):
    path = tmp_path / "paper-runup-sweep.csv"
    path.write_text("m2 [kg],F2_after [N],t_step [s],status,regimes,S1m [N]\n"
                    "100.0,-3000.0,0.3,finished,T,500\n200.0,-3000.0,0.3,finished,T,600\n")
    with pytest.raises(FitInputError, match=r"column 'm2 \[kg\]': the sweep ran 2 values of m2"):
        read_measured(path, load_module("paper-runup"), ["m2"])
    measured = read_measured(path, load_module("paper-runup"), ["F2_after"])
    assert measured.known == ["m2", "t_step"] and measured.params.tolist() == [[100.0, 0.3], [200.0, 0.3]]


def test_units_in_hand_made_column_names(tmp_path):
    module = load_module("paper-runup")
    path = tmp_path / "peaks.csv"
    path.write_text("case,F2_after [kN],t_step [ms],S1m [kN],S2m [N]\na,-3,60,0.5,-5000\n")
    measured = read_measured(path, module, ["m2"])
    assert measured.known == ["F2_after", "t_step"] and measured.params.tolist() == [[-3000.0, 0.06]]
    assert measured.values.tolist() == [[500.0, -5000.0]]
    for text, message in (("S1m [kg]\n1\n", "column 'S1m [kg]': 'kg' is not a unit of a force ('N', 'kN')"),
                          ("case [s],S1m\na,1\n", "column 'case [s]': 'case' takes no unit"),
                          ("bogus [N],S1m\n1,1\n", "unknown column 'bogus [N]'"),
                          ("S1m,S1m [N]\n1,2\n", "columns 'S1m' and 'S1m [N]' both give 'S1m'")):
        path.write_text(text)
        with pytest.raises(FitInputError, match=re.escape(message)):
            read_measured(path, module, ["m2"])


def test_fit_announces_the_compile_on_a_cold_cache(monkeypatch, caplog, tmp_path):
    """`tswm fit` asks prepare_kernels for its kernels before it loads any: on a cold cache (here:
    numba's cache check says so) it says what it compiles, and compiles first (jit stays on)."""
    asked = []

    def cold(groups=(), model=None):
        asked.append((tuple(groups), model))
        return list(groups), coldstart.model_name(model) if model is not None else None

    monkeypatch.setattr(coldstart, "check", cold)
    monkeypatch.setenv(warmup.ENV, "background")
    code = main(["fit", "paper-runup", "--measured", str(tmp_path / "missing.csv"), "--free", "m2=50:600",
                 "--no-progress", "-o", str(tmp_path / "out")])
    assert code == 2
    assert asked[0] == (("integrate", "batch"), "paper-runup")
    assert "compiling the integration kernels" in caplog.text and "the model `paper-runup`" in caplog.text
    import numba

    assert not numba.config.DISABLE_JIT


@pytest.mark.heavy
def test_a_cold_fit_with_interpret_runs_interpreted_and_says_so(tmp_path):
    """TSWM_COLD_START=interpret on an empty numba cache: the fit says it runs interpreted, compiles
    nothing, and still recovers m2 from a peak made at 250 kg (the sweep's, compiled, in this process)."""
    module = load_module("paper-runup")
    row = tswm.sweep(module, {"m2": M2_TRUE, "F2_after": -3000.0, "t_step": 0.06}, rtol=1e-9, atol=1e-12).table
    path = tmp_path / "peak.csv"
    row[["F2_after", "t_step", "S1m", "S2m"]].to_csv(path, index=False)
    cache = tmp_path / "cache"
    run = subprocess.run([sys.executable, "-m", "tswm_runtime.cli", "fit", "paper-runup", "--measured", str(path),
                          "--free", "m2=50:600", "--starts", "1", "--no-plot", "--no-progress", "-o",
                          str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT,
                         env={**os.environ, "NUMBA_CACHE_DIR": str(cache), warmup.ENV: "interpret"})
    assert run.returncode == 0, run.stderr
    assert "this run is interpreted" in run.stderr and "TSWM_COLD_START=interpret: nothing is compiled" in run.stderr
    assert not list(cache.rglob("*.nbi"))
    estimate = json.loads((tmp_path / "out" / "fit.json").read_text())["estimate"]["m2"]
    assert estimate == pytest.approx(M2_TRUE, rel=1e-4)
