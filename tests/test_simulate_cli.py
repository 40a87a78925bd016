"""`tswm simulate`: the summary, the files of -o, usage errors (exit 2), failed runs (exit 1).

The CLI runs in-process through ``tswm_runtime.cli.main``; every expected number comes
from a direct ``simulate()`` call with the same inputs.
"""
import contextlib
import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

import generated
from tswm_runtime.cli import main
from tswm_runtime.results.export import SERIES
from tswm_runtime.simulation.simulate import simulate

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _strict_json(text: str):
    """json.loads that rejects NaN/Infinity literals (not strict JSON)."""
    def reject(name):
        raise ValueError(f"non-standard JSON constant {name}")
    return json.loads(text, parse_constant=reject)


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory):
    """`simulate paper --set F2=-1000 -o DIR` once, and the same run through simulate()."""
    out = tmp_path_factory.mktemp("paper")
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["simulate", "paper", "--set", "F2=-1000", "-o", str(out)])
    return {"code": code, "out": stdout.getvalue(), "err": stderr.getvalue(), "dir": out,
            "direct": simulate("paper", {"F2": -1000.0})}


def test_exit_code_and_summary(paper_run):
    direct, out = paper_run["direct"], paper_run["out"]
    assert paper_run["code"] == (0 if direct.success else 1), paper_run["err"]
    assert paper_run["err"] == ""
    assert out.startswith("scene paper ")
    assert "F2 = -1000 N" in out and "m2 = " in out
    assert f"status: {direct.status}: {direct.message}" in out
    for ph in direct.phases:
        assert ph.regime in out and f"{ph.t_start:.9g}" in out
    for e in direct.events[:10]:
        assert e.kind in out and f"{e.t:.9g}" in out
    assert f"S1 max = {direct.S1_max:.6g} N at t = {direct.t_S1_max:.6g} s" in out
    assert f"S2 max = {direct.S2_max:.6g} N at t = {direct.t_S2_max:.6g} s" in out
    if direct.KD1 is not None:
        assert f"KD1 = {direct.KD1:.6g}" in out
    assert f"steps {direct.n_steps} (rejected {direct.n_rejected}), rhs calls {direct.nfev}" in out
    assert "wall time" in out


def test_writes_four_files(paper_run):
    names = sorted(p.name for p in paper_run["dir"].iterdir())
    assert names == ["paper-summary.json", "paper.csv", "paper.npz", "paper.png"]
    for name in names:
        assert f"wrote {paper_run['dir'] / name}" in paper_run["out"]


def test_csv_matches_direct_run(paper_run):
    direct = paper_run["direct"]
    with open(paper_run["dir"] / "paper.csv", newline="") as handle:
        rows = list(csv.reader(handle))
    header, body = rows[0], rows[1:]
    assert header == [f"{name} [{unit}]" for name, unit in SERIES] + ["mode", "regime"]
    assert len(body) == direct.t.size
    column = {name: i for i, name in enumerate(header)}
    for name, unit in SERIES:
        values = np.array([float(r[column[f"{name} [{unit}]"]]) for r in body])
        np.testing.assert_array_equal(values, getattr(direct, name), err_msg=name)
    assert [r[column["mode"]] for r in body] == [direct.mode_names[m] for m in direct.mode]
    regime = {ph.mode: ph.regime for ph in direct.phases}
    assert all(r[column["regime"]] == regime[r[column["mode"]]] for r in body)
    # numpy reads it as well (the per-point series, by position)
    table = np.genfromtxt(paper_run["dir"] / "paper.csv", delimiter=",", skip_header=1,
                          usecols=range(len(SERIES)))
    np.testing.assert_array_equal(table[:, column["S1 [N]"]], direct.S1)


def test_npz_loads_without_pickle(paper_run):
    direct = paper_run["direct"]
    with np.load(paper_run["dir"] / "paper.npz", allow_pickle=False) as data:
        for name, _ in SERIES:
            np.testing.assert_array_equal(data[name], getattr(direct, name), err_msg=name)
        np.testing.assert_array_equal(data["mode"], direct.mode)
        assert tuple(data["mode_names"]) == direct.mode_names
        events = data["events"]
        assert len(events) == len(direct.events)
        np.testing.assert_array_equal(events["t"], [e.t for e in direct.events])
        assert list(events["kind"]) == [e.kind for e in direct.events]
        assert list(events["to_mode"]) == [e.to_mode or "" for e in direct.events]
        assert list(data["phases"]["regime"]) == [ph.regime for ph in direct.phases]
        assert dict(zip(data["param_names"], data["param_values"])) == direct.params
        for name in ("S1_max", "t_S1_max", "S2_max", "t_S2_max", "n_steps", "nfev"):
            assert data[name][()] == getattr(direct, name), name
        assert str(data["status"]) == direct.status and str(data["message"]) == direct.message
        if direct.KD1 is not None:
            assert data["KD1"][()] == direct.KD1
        assert json.loads(str(data["settings_json"]))["method"] == direct.settings["method"]


def test_summary_json(paper_run):
    direct = paper_run["direct"]
    summary = _strict_json((paper_run["dir"] / "paper-summary.json").read_text())
    assert summary["status"] == direct.status and summary["message"] == direct.message
    assert summary["success"] == direct.success
    assert summary["params"] == direct.params
    assert summary["maxima"]["S1"] == {"value": direct.S1_max, "t": direct.t_S1_max, "unit": "N"}
    assert summary["maxima"]["S2"]["value"] == direct.S2_max
    assert summary["KD1"] == direct.KD1 and summary["KD2"] == direct.KD2
    assert [ph["regime"] for ph in summary["phases"]] == [ph.regime for ph in direct.phases]
    assert [(e["t"], e["kind"]) for e in summary["events"]] == [(e.t, e.kind) for e in direct.events]
    assert summary["counts"]["n_steps"] == direct.n_steps
    assert summary["counts"]["n_points"] == direct.t.size


def test_png(paper_run):
    path = paper_run["dir"] / "paper.png"
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    image = imread(path)
    height, width = image.shape[:2]
    assert image.ndim == 3 and 1000 <= height <= 4000 and 1000 <= width <= 4000
    assert image.std() > 0.01  # not a blank canvas


def test_unit_strings_and_module_path(tmp_path, capsys):
    """--set takes "<number> <unit>"; SCENE may be a generated module's path; --no-plot."""
    module = Path(generated.__file__).parent / "paper.py"
    code = main(["simulate", str(module), "--set", "F2=-1 kN", "--set", "m2=0.2 t", "--t-end", "0.05",
                 "--points", "11", "-o", str(tmp_path), "--no-plot"])
    direct = simulate("paper", {"F2": -1000.0, "m2": 200.0}, t_end=0.05, points=11)
    assert code == (0 if direct.success else 1)
    assert "F2 = -1000 N" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paper-summary.json", "paper.csv", "paper.npz"]
    summary = _strict_json((tmp_path / "paper-summary.json").read_text())
    assert summary["params"] == {"F2": -1000.0, "m2": 200.0} | direct.params
    assert summary["settings"]["t_end"] == 0.05 and summary["counts"]["n_points"] == direct.t.size


@pytest.mark.parametrize("args, named", [
    (["paper", "--set", "Fx=1"], "'Fx'"),
    (["paper", "--set", "F2=nan"], "F2 = nan"),
    (["paper", "--set", "F2=abc"], "F2 = 'abc'"),
    (["paper", "--set", "F2=-5 kg"], "F2 = '-5 kg'"),
    (["paper", "--set", "F2"], "--set 'F2'"),
    (["paper", "--rtol", "5"], "rtol"),
    (["paper", "--atol", "0"], "atol"),
    (["paper", "--t-end", "-1"], "t_end"),
    (["paper", "--points", "0"], "points"),
    (["no-such-scene"], "no-such-scene"),
    (["missing/scene.toml"], "missing/scene.toml"),  # a scene file runs as it is; a missing one is named
    (["missing/model.py"], "missing/model.py"),
], ids=["unknown-param", "nan", "not-a-number", "wrong-unit", "no-equals", "rtol", "atol", "t-end",
        "points", "unknown-scene", "toml-path", "missing-module"])
def test_usage_errors_exit_2(args, named, capsys, tmp_path):
    code = main(["simulate", *args, "-o", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.err.startswith("tswm simulate: error: ")
    assert named in captured.err
    assert captured.out == ""
    assert not (tmp_path / "out").exists()


def test_failed_run_exit_code(capsys):
    """paper-literal at its default F2: the exit code follows Result.success (1 when it failed)."""
    direct = simulate("paper-literal")
    code = main(["simulate", "paper-literal"])
    out = capsys.readouterr().out
    assert code == (0 if direct.success else 1)
    assert f"status: {direct.status}: {direct.message}" in out


def test_stopped_run_exits_1_and_still_writes(tmp_path, capsys):
    """A run that stops early (here: out of step attempts) is not a usage error: exit 1,
    the summary with its status and message, and the files, which record the status."""
    direct = simulate("paper", max_steps=3)
    assert not direct.success
    code = main(["simulate", "paper", "--max-steps", "3", "-o", str(tmp_path), "--no-plot"])
    captured = capsys.readouterr()
    assert code == 1 and captured.err == ""
    assert f"status: {direct.status}: {direct.message}" in captured.out
    summary = _strict_json((tmp_path / "paper-summary.json").read_text())
    assert (summary["status"], summary["success"], summary["t_stop"]) == (direct.status, False, direct.t_stop)


def test_files_get_the_umask_mode(tmp_path):
    """write_atomic's files are created like open() would (mkstemp alone would make them 0600)."""
    import os

    mask = os.umask(0o027)
    try:
        main(["simulate", "paper", "--t-end", "0.01", "--points", "3", "-o", str(tmp_path), "--no-plot"])
    finally:
        os.umask(mask)
    assert {p.stat().st_mode & 0o777 for p in tmp_path.iterdir()} == {0o640}


def test_ctrl_c_stops_a_long_run_at_once():
    """A run of 1e9 s with a huge step budget: progress lines on stderr, and SIGINT ends
    it with exit 130 and a message (the kernel runs in a GIL-free worker thread). The valve
    under a light load runs on at its no-load speed with x1 a state, so it is no held
    equilibrium: with dopri5 the run would take hours (auto switches to RODAS4, whose steps
    grow without bound on this linear growth of x1, and finishes in 79 steps)."""
    import signal
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "tswm_runtime.cli", "simulate", "valve-travel", "--set", "F2_2=-1000",
           "--t-end", "1e9", "--max-steps", "1000000000", "--no-plot", "--method", "dopri5"]
    # SIGINT at its default in the child, as in a terminal: a shell's background job (a CI script run
    # with &) starts with SIGINT ignored, which Python then keeps (no KeyboardInterrupt at all).
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        line = proc.stderr.readline()          # the first progress line: the kernel is running
        assert "running:" in line and "Ctrl-C stops" in line, line
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)  # a hang guard, not a timing assertion
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted (Ctrl-C)" in err and "Traceback" not in err


def test_a_reader_that_closes_early_ends_the_command_quietly():
    """``tswm simulate paper | head``: stdout's reader is gone before tswm writes (closed at
    once here, so the broken pipe is certain). tswm stops as a Unix tool stopped by SIGPIPE:
    exit 141, nothing on stderr: no traceback, no path error."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "tswm_runtime.cli", "simulate", "paper"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        proc.stdout.close()                    # the reader goes away before the first line
        _, err = proc.communicate(timeout=120)  # a hang guard, not a timing assertion
    finally:
        proc.kill()
    assert proc.returncode == 141, err
    assert "Traceback" not in err and "check -o" not in err and "Broken pipe" not in err, err
    assert err == "", err


def test_a_scene_file_runs_straight_from_its_file(tmp_path, monkeypatch, capsys):
    """simulate takes a .toml: generated once into the user cache (TSWM_CACHE), reused after;
    generated/ is not touched. The constant-force wedge is checked against its closed form."""
    monkeypatch.setenv("TSWM_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "block.toml"
    scene.write_text('''name = "block"
[wedge]
flanks = ["a"]
gamma = "10 deg"
m1 = "2 kg"
m2 = "3 kg"
[friction]
law = "constant"
rho = "5 deg"
[drive]
law = "constant"
F1 = "50 N"
[load]
law = "constant"
F2 = "-20 N"
[run]
t_end = "0.5 s"
''')
    before = sorted(p.name for p in (Path(__file__).parents[1] / "generated").iterdir())
    capsys.readouterr()
    assert main(["simulate", str(scene), "--no-plot", "-o", str(tmp_path / "out")]) == 0
    cached = list((tmp_path / "cache" / "models").glob("block_*/block.py"))
    assert len(cached) == 1
    out = capsys.readouterr().out
    assert _printed_module(out) == cached[0].resolve()            # the module that ran, a real file
    assert f", from {scene})" in out.splitlines()[0]
    for line in out.splitlines():
        if line.startswith("  wrote "):
            assert Path(line[len("  wrote "):]).is_file(), line
    assert main(["generate", str(scene), "-o", str(tmp_path / "gen")]) == 0     # generate names its file too
    wrote = capsys.readouterr().out.split(":")[0]
    assert wrote == f"wrote {tmp_path / 'gen' / 'block.py'}" and (tmp_path / "gen" / "block.py").is_file()
    stamp = cached[0].stat().st_mtime_ns
    assert main(["simulate", str(scene), "--no-plot"]) == 0
    assert cached[0].stat().st_mtime_ns == stamp                      # reused, not regenerated
    assert sorted(p.name for p in (Path(__file__).parents[1] / "generated").iterdir()) == before
    g, rho, F1, F2, m1, m2 = math.radians(10), math.radians(5), 50.0, -20.0, 2.0, 3.0
    psi = math.tan(g + rho)
    a1 = (F1 + psi * F2) / (m1 + psi * m2 * math.tan(g))          # constant: v1 = a1 t
    data = json.loads((tmp_path / "out" / "block-summary.json").read_text())
    assert data["status"] == "finished"
    csv = (tmp_path / "out" / "block.csv").read_text().splitlines()
    last = [float(x) for x in csv[-1].split(",")[:3]]
    assert last[2] == pytest.approx(a1 * 0.5, rel=1e-9)


def _printed_module(out: str) -> Path:
    """The module path that simulate's first line names, checked to exist, resolved."""
    import re

    found = re.match(r"scene \S+ \((?:consistent|literal) equations, (.+?)(?:, from .+)?\)$", out.splitlines()[0])
    assert found, out.splitlines()[0]
    path = Path(found.group(1))
    assert path.is_file() and path.suffix == ".py", out.splitlines()[0]
    return path.resolve()


def test_simulate_prints_the_path_of_the_module_that_ran(capsys):
    from tswm_runtime.model.contract import load_module

    assert main(["simulate", "paper", "--t-end", "0.01", "--points", "3", "--no-plot"]) == 0
    assert _printed_module(capsys.readouterr().out) == Path(load_module("paper").__file__).resolve()


@pytest.mark.parametrize("value, text", [(-15000.0, "-15 kN"), (-16932.7, "-16.93 kN"), (727.63, "727.6 N"),
                                         (1729.4, "1729 N"), (-5000.0, "-5000 N"), (0.0, "0 N")])
def test_force_text(value, text):
    from tswm_runtime.results.plot import force_text

    assert force_text(value) == text


def test_plot_labels_forces_without_exponents():
    """The maxima's labels read '-15 kN', not '-1.5e+04 N' (a stuck paper run: S2 = F2)."""
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.results.plot import figure

    r = simulate("paper", {"m2": 200.0, "F2": -15000.0}, points=11)
    from matplotlib.text import Text

    labels = [t.get_text() for t in figure(r, load_module("paper")).findobj(Text)]
    assert r.S2_max == -15000.0
    assert any(label.startswith("S2 = -15 kN at t = ") for label in labels), labels
    assert not any("e+" in label for label in labels), labels


def test_the_simulation_path_imports_neither_sympy_nor_derivation(tmp_path):
    """A shipped scene's simulate, its files and a sweep run without the CAS: in a fresh
    process, neither sympy, jinja2's code generation nor derivation/ is imported."""
    import subprocess
    import sys

    script = (
        "import sys\n"
        "from tswm_runtime.cli import main\n"
        f"assert main(['simulate', 'paper', '--t-end', '0.01', '--points', '5', '-o', {str(tmp_path)!r}]) == 0\n"
        "from tswm_runtime.sweeps.sweep import sweep\n"
        "sweep('paper', [[200.0, -1000.0]], {'t_end': 0.01})\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'sympy', 'derivation'}))\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]", out
