"""A cold numba cache: the CLI runs interpreted while a background process compiles
(startup.warmup: the first result within 15 s). The interpreted kernels are the same
source run by Python: they must give the compiled kernels' results. The decisions (interpret
or compile first, one background compile at a time, rerun compiled on Python-only arithmetic
errors) are checked on their own."""
import fcntl
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tswm_runtime.jit import coldstart
from tswm_runtime.startup import warmup
from tswm_runtime.sweeps import rows as sweep_rows
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module

ROOT = Path(__file__).resolve().parents[1]
SCENES = ["paper", "paper-runup", "load-schedule", "stiff-drive", "asymmetric", "one-sided", "seating",
          "valve-travel", "paper-literal", "paper-lostmotion", "backlash", "mesh", "lost-motion"]
# Every shipped scene with both methods, but mesh with dopri5: at k = 1e9 dopri5 steps at its stability
# limit, where one ulp changes step decisions (1e-5 apart in S1, both within the tolerance of the run).
RUNS = [f"{scene}/{method}" for scene in SCENES for method in ("dopri5", "rosenbrock23")
        if (scene, method) != ("mesh", "dopri5")]
# The default run's runs: together they execute every line of the kernels (tswm_runtime/integration,
# hybrid, jit) that the 25 runs execute interpreted (a line tracer over each run, 1158 lines, 7 of the 25 runs);
# -m slow runs the other 18.
KEPT = ["paper/dopri5", "load-schedule/dopri5", "seating/dopri5", "paper-literal/dopri5", "backlash/rosenbrock23",
        "mesh/rosenbrock23", "lost-motion/dopri5"]


def _env(cache: Path, mode: str) -> dict:
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache), warmup.ENV: mode}


INTERPRETED = """
import json, sys
import numba
numba.config.DISABLE_JIT = True
from tswm_runtime.simulation.simulate import simulate
out = {}
for run in sys.argv[1:]:
    scene, method = run.split("/")
    r = simulate(scene, method=method)
    out[run] = {"t": r.t.tolist(), "x1": r.x1.tolist(), "v1": r.v1.tolist(), "S1": r.S1.tolist(),
                "events": [e.t for e in r.events], "steps": r.n_steps, "status": r.status}
print(json.dumps(out))
"""


@pytest.mark.heavy
@pytest.mark.parametrize("runs", [pytest.param(KEPT, id="kept"),
                                  pytest.param([run for run in RUNS if run not in KEPT], id="rest",
                                               marks=pytest.mark.slow)])
def test_interpreted_kernels_give_the_compiled_results(tmp_path, runs):
    """Shipped scenes and methods (RUNS): the kernels run by Python (numba's jit off, in a fresh
    process) against the compiled kernels in this one. Same steps and statuses; states and event
    times to 1e-9 (math functions of Python and of LLVM may differ in the last bit)."""
    assert set(KEPT) <= set(RUNS)
    run = subprocess.run([sys.executable, "-c", INTERPRETED, *runs], capture_output=True, text=True, cwd=ROOT,
                         env=_env(tmp_path, "interpret"), timeout=600)
    assert run.returncode == 0, run.stderr
    interpreted = json.loads(run.stdout)
    assert not list(tmp_path.rglob("*.nbi")), "an interpreted run compiled something"
    assert sorted(interpreted) == sorted(runs)
    for key, got in interpreted.items():
        scene, method = key.split("/")
        ref = simulate(scene, method=method)
        assert (got["status"], got["steps"]) == (ref.status, ref.n_steps), key
        np.testing.assert_array_equal(got["t"], ref.t, err_msg=key)
        np.testing.assert_allclose(got["events"], [e.t for e in ref.events], rtol=1e-12, atol=1e-12, err_msg=key)
        for name in ("x1", "v1", "S1"):
            scale = max(1.0, float(np.max(np.abs(getattr(ref, name)))))
            np.testing.assert_allclose(got[name], getattr(ref, name), rtol=1e-9, atol=1e-9 * scale,
                                       err_msg=f"{key} {name}")


def test_a_cold_cli_run_is_interpreted_and_says_so(tmp_path):
    """TSWM_COLD_START=interpret on an empty cache: the message first (naming what is missing and
    that the run is interpreted), the result, nothing compiled; the written file holds the
    compiled run's numbers."""
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "tswm_runtime.cli", "simulate", "paper-runup", "--no-plot",
                          "-o", str(out)], capture_output=True, text=True, cwd=ROOT,
                         env=_env(tmp_path / "cache", "interpret"), timeout=300)
    assert run.returncode == 0, run.stderr
    first = run.stderr.splitlines()[0]
    assert first.startswith("tswm: the integration kernels") and "the model `paper-runup`" in first
    assert "this run is interpreted" in first and "TSWM_COLD_START=interpret: nothing is compiled" in first
    assert "status: finished" in run.stdout
    assert not list((tmp_path / "cache").rglob("*.nbi"))
    got, ref = np.load(out / "paper-runup.npz"), simulate("paper-runup")
    np.testing.assert_allclose(got["S1"], ref.S1, rtol=1e-9, atol=1e-9 * float(np.max(np.abs(ref.S1))))


def test_a_cold_cli_sweep_is_interpreted_and_gives_the_compiled_table(tmp_path):
    """A small sweep on an empty cache runs interpreted (fewer cases than the probe: no timing
    needed); its table is the compiled sweep's for the same rows (the chunk keys prove the rows)."""
    from tswm_runtime.sweeps.sweep import read_table, sample_cases, sweep

    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "tswm_runtime.cli", "sweep", "paper", "--samples", "6", "--range",
                          "F2=-20000:5000", "--range", "m2=100:400", "--no-progress", "-o", str(out)],
                         capture_output=True, text=True, cwd=ROOT, env=_env(tmp_path / "cache", "interpret"),
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert "this run is interpreted" in run.stderr.splitlines()[0] and "finished 6" in run.stdout
    got = read_table(out / "paper-sweep.parquet")
    module = load_module("paper")
    P = sample_cases(module, 6, {"F2": (-20000.0, 5000.0), "m2": (100.0, 400.0)}, 0)
    ref = sweep(module, P).table
    np.testing.assert_array_equal(got[["m2", "F2"]].to_numpy(), P)
    assert (got["status"] == ref["status"]).all() and (got["regimes"] == ref["regimes"]).all()
    assert (got["steps"] == ref["steps"]).all()
    for column in ("S1m", "S2m", "v1", "x1", "KD1"):
        np.testing.assert_allclose(got[column], ref[column], rtol=1e-9, err_msg=column)


def test_warm_kernels_and_a_cold_model_run_interpreted_together(tmp_path):
    """The kernels in numba's cache, the model not (a copy of generated/paper.py elsewhere: its
    cache is empty): checking the cache must not import the kernels compiled, or the compiled
    batch kernel meets the interpreted model (TypeError: No matching definition ... pyobject).
    The sweep runs interpreted, kernels and model alike, and gives the compiled table."""
    from tswm_runtime.sweeps.sweep import read_table, sample_cases, sweep

    import tswm_runtime.sweeps.rows  # noqa: F401  (the kernels compiled into the cache, if they were not)
    model = tmp_path / "paper.py"
    model.write_bytes((ROOT / "generated" / "paper.py").read_bytes())
    out = tmp_path / "out"
    env = {**os.environ, warmup.ENV: "interpret"}
    run = subprocess.run([sys.executable, "-m", "tswm_runtime.cli", "sweep", str(model), "--samples", "20", "--range",
                          "m2=100:300", "--no-progress", "-o", str(out)], capture_output=True, text=True, cwd=ROOT,
                         env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stderr.startswith("tswm: the model `paper` not in numba's cache yet: this run is interpreted")
    assert not list(tmp_path.rglob("*.nbi")), "an interpreted run compiled something"
    P = sample_cases(load_module("paper"), 20, {"m2": (100.0, 300.0)}, 0)
    got, ref = read_table(out / "paper-sweep.parquet"), sweep("paper", P).table
    assert (got["status"] == ref["status"]).all() and (got["steps"] == ref["steps"]).all()
    for column in ("S1m", "v1", "x1"):
        np.testing.assert_allclose(got[column], ref[column], rtol=1e-9, err_msg=column)


def test_an_unknown_cold_start_mode_is_refused_by_name(monkeypatch, capsys):
    monkeypatch.setenv(warmup.ENV, "later")
    assert main(["simulate", "paper", "--points", "2"]) == 2
    err = capsys.readouterr().err
    assert "TSWM_COLD_START='later'" in err and "background, foreground, interpret" in err


def test_background_mode_starts_one_compile_of_what_is_cold_and_the_run_method(monkeypatch):
    spawned = []
    monkeypatch.setattr(warmup, "_spawn", lambda groups, spec, log: spawned.append((groups, spec)))
    monkeypatch.setattr(warmup, "running", lambda: False)
    cold = warmup.ColdStart(("integrate",), "paper", "background")
    text = warmup.begin(cold, "rosenbrock23")
    assert spawned == [(["integrate", "rosenbrock23"], "paper")]
    assert "background process compiles them" in text and "the model `paper`" in text
    seconds = coldstart.estimate(["integrate", "rosenbrock23"], "paper")
    assert f"about {max(5 * round(seconds / 5), 5)} s" in text
    monkeypatch.setattr(warmup, "running", lambda: True)
    assert "already under way" in warmup.begin(cold, "dopri5") and len(spawned) == 1
    assert "nothing is compiled" in warmup.begin(warmup.ColdStart(("batch",), None, "interpret"), None)
    assert len(spawned) == 1


def test_an_unwritable_temporary_directory_costs_the_background_compile_not_the_run(monkeypatch, tmp_path):
    monkeypatch.setattr(warmup, "running", lambda: False)
    monkeypatch.setattr(warmup, "lock_path", lambda: tmp_path / "missing" / "tswm-warmup.lock")
    text = warmup.begin(warmup.ColdStart(("integrate",), "paper", "background"), "dopri5")
    assert "this run is interpreted" in text and not (tmp_path / "missing").exists()


def test_a_second_background_compile_leaves_at_once_while_the_lock_is_held(tmp_path):
    env = _env(tmp_path, "foreground")
    lock = subprocess.run([sys.executable, "-c", "from tswm_runtime.startup import warmup; print(warmup.lock_path())"],
                          capture_output=True, text=True, cwd=ROOT, env=env, check=True).stdout.strip()
    with open(lock, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        run = subprocess.run([sys.executable, "-m", "tswm_runtime.startup.warmup", "integrate", "--model", "paper"],
                             capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)
    assert run.returncode == 0 and "holds the lock" in run.stdout, run.stderr
    assert not list(tmp_path.rglob("*.nbi"))


def test_a_sweep_compiles_first_when_interpreting_its_cases_would_take_longer(monkeypatch):
    cold = warmup.ColdStart(("integrate", "batch"), None, "background")
    module = load_module("paper")
    P = np.tile(np.array([[200.0, -15000.0]]), (40, 1))
    monkeypatch.setattr(coldstart, "estimate", lambda groups, model: 1e9)
    assert warmup.interpreting_is_quicker(cold, module, P, {}, "dopri5")
    monkeypatch.setattr(coldstart, "estimate", lambda groups, model: 0.0)
    assert not warmup.interpreting_is_quicker(cold, module, P, {}, "dopri5")
    assert warmup.interpreting_is_quicker(cold, module, P[:warmup.PROBE_CASES], {}, "dopri5")  # too few to time
    assert warmup.interpreting_is_quicker(warmup.ColdStart((), None, "interpret"), module, P, {}, "dopri5")
    monkeypatch.setattr(coldstart, "estimate", lambda groups, model: 1e9)
    monkeypatch.setattr(sweep_rows, "case_table", lambda *args: 1.0 / 0.0)   # Python-only arithmetic: compile
    assert not warmup.interpreting_is_quicker(cold, module, P, {}, "dopri5")


def test_python_only_arithmetic_in_an_interpreted_run_reruns_the_command_compiled(monkeypatch):
    """x / 0.0 on Python floats raises where compiled code (error_model numpy) gives inf: the
    command is run again, compiled, with the same arguments."""
    import tswm_runtime.simulation.simulate as sim

    reruns = []
    monkeypatch.setattr(warmup, "interpret_if_cold",
                        lambda groups, spec: warmup.ColdStart(tuple(groups), None, "interpret"))
    monkeypatch.setattr(warmup, "begin", lambda cold, method: "")
    monkeypatch.setattr(warmup, "rerun_compiled", lambda argv, error: reruns.append((argv, type(error))) or 7)

    def divide(*args, **kwargs):
        return 1.0 / 0.0
    monkeypatch.setattr(sim, "simulate", divide)
    argv = ["simulate", "paper", "--points", "2"]
    assert main(argv) == 7 and reruns == [(argv, ZeroDivisionError)]


@pytest.mark.parametrize("args", [["--rtol", "5"], ["--set", "F2=abc"], ["--set", "Fx=1"], ["--points", "0"]],
                         ids=["rtol", "set-value", "set-name", "points"])
def test_bad_input_exits_2_before_the_background_compile_starts(monkeypatch, capsys, args):
    """A cold cache: --rtol and --set are checked before warmup.begin spawns the compile."""
    begun = []
    monkeypatch.setattr(warmup, "interpret_if_cold",
                        lambda groups, spec: warmup.ColdStart(tuple(groups), None, "background"))
    monkeypatch.setattr(warmup, "begin", lambda cold, method: begun.append(method) or "")
    assert main(["simulate", "paper", *args]) == 2
    assert begun == [] and capsys.readouterr().err.startswith("tswm simulate: error: ")


def test_an_error_in_the_kernel_thread_reaches_the_caller():
    from tswm_runtime.simulation.simulate import _in_a_thread

    def kernel():
        raise OverflowError("math range error")
    with pytest.raises(OverflowError, match="math range error"):
        _in_a_thread(kernel, (), np.zeros(8, np.int64))


@pytest.mark.slow
def test_background_mode_fills_the_cache_and_the_next_run_is_silent(tmp_path):
    """The whole cycle on an empty cache (about a minute on 2 cores): the first run interpreted
    and quick, the background compile finishing, the next run compiled and silent."""
    env = _env(tmp_path, "background")
    argv = [sys.executable, "-m", "tswm_runtime.cli", "simulate", "paper", "--points", "2"]
    first = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert first.returncode == 0 and "background process compiles them" in first.stderr, first.stderr
    subprocess.run([sys.executable, "-c", "from tswm_runtime.startup import warmup; warmup.wait()"], cwd=ROOT, env=env,
                   check=True, timeout=900)
    second = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert second.returncode == 0 and second.stderr == "", second.stderr
    assert first.stdout.split("wall time")[0] == second.stdout.split("wall time")[0]
