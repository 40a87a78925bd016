"""The cold-start message: before numba compiles the kernels or a model because they
are not in its disk cache, tswm says what it compiles and about how long. Timing is the
bench's business (``bench.empty_cache``); these tests check that the message appears when
the cache is empty, is silent when it is warm, and that the detection reads numba's real
cache (a detection that never finds the cache would announce on every run)."""
import json
import os
import select
import subprocess
import sys
from pathlib import Path

import pytest

from tswm_runtime.jit import coldstart

ROOT = Path(__file__).resolve().parents[1]


def _empty_cache(cache: Path) -> dict:
    """The environment of a process with ``cache`` as its empty numba cache (cache_guard purges
    and marks only the cache directories numba uses, so the checkout's default cache stays)."""
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache)}


def _python(code: str, cache: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                          env=_empty_cache(cache), timeout=120)


def _first_stderr_line(argv: list[str], cache: Path, timeout: float = 60.0) -> str:
    """The first line the process writes to stderr within ``timeout`` seconds (a silent process
    fails the test instead of blocking it); the process is then stopped (it would go on
    compiling for a minute)."""
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            env=_empty_cache(cache))
    try:
        ready, _, _ = select.select([proc.stderr], [], [], timeout)
        assert ready, f"nothing on stderr within {timeout:g} s"
        return proc.stderr.readline()
    finally:
        proc.kill()
        proc.wait()


def test_an_empty_cache_is_cold_and_checking_it_compiles_nothing(tmp_path):
    out = _python("import sys, json\n"
                  "from tswm_runtime.jit import coldstart\n"
                  "cold = coldstart.cold_groups(['integrate', 'batch'])\n"
                  "model = coldstart.model_cold(*coldstart.model_source('paper'))\n"
                  "print(json.dumps([cold, model, 'tswm_runtime.hybrid.machine' in sys.modules]))", tmp_path)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == [["integrate", "batch"], True, False]


@pytest.mark.heavy
def test_a_kernel_compiled_on_import_survives_the_first_stale_cache_check(tmp_path):
    """The first compile into an empty cache writes the kernel marker and purges the kernel
    caches without it; a kernel compiled eagerly before that purge (``segment.no_jacobian``,
    compiled when segment.py is imported) lost its cache file, and the next run found the
    integration kernels cold after a forced foreground compile."""
    out = _python("from tswm_runtime.integration import segment\n"
                  "from tswm_runtime.jit import cache_guard, coldstart\n"
                  "cache_guard.check_kernel_caches()\n"
                  "print(coldstart.is_cached(coldstart.RUNTIME / 'integration' / 'segment.py', 'no_jacobian',\n"
                  "      'tswm_runtime.integration.segment', True, cache_guard.kernel_digest()))", tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True"]


WARM_CHECK = """
import json
from tswm_runtime.jit import coldstart
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.jit.cache_guard import kernel_digest

model = coldstart.model_source("paper")   # (None once the module is imported)
simulate("paper", points=2)   # compiled now, or loaded: in numba's cache either way
machine = coldstart.RUNTIME / "hybrid" / "machine.py"
print(json.dumps([coldstart.cold_groups(["integrate", "dopri5"]), coldstart.model_cold(*model),
                  coldstart.is_cached(machine, "integrate_hybrid", "tswm_runtime.hybrid.machine", True,
                                      kernel_digest()),
                  coldstart.is_cached(machine, "integrate_hybrid", "tswm_runtime.hybrid.machine", True, "0" * 64)]))
"""


def test_a_warm_cache_is_found_and_a_stale_kernel_marker_is_not():
    """Once a process has imported (compiled or loaded) the kernels and the model, numba's
    cache holds them: the check must see that through numba's own locator, file names and
    freshness test (a check that never finds the cache would announce every run). A
    kernel marker that differs from the kernel sources' digest makes compile_cached purge
    the kernel caches: that is cold. In a subprocess: other tests purge the kernel caches
    (cache_guard) after this process has loaded them."""
    run = subprocess.run([sys.executable, "-c", WARM_CHECK], capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout.splitlines()[-1]) == [[], False, True, False]


def test_a_run_compiles_or_loads_only_the_step_of_its_own_method():
    """The methods' steps are first-class function arguments of the mode machine, compiled (or
    loaded from the cache) on a method's first run: a dopri5 run never compiles rosenbrock23."""
    code = ("from tswm_runtime.simulation.simulate import simulate\n"
            "from tswm_runtime.integration import segment\n"
            "simulate('paper', method='dopri5', points=2)\n"
            "print(len(segment.dopri5_attempt.signatures), len(segment.rosenbrock23_attempt.signatures))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["1", "0"]


def test_the_model_entries_are_the_functions_compiled_with_a_signature():
    source = coldstart.model_source("paper-runup")[0] if "generated.paper_runup" not in sys.modules \
        else Path(sys.modules["generated.paper_runup"].__file__)
    assert coldstart.model_entries(source) == ["rhs", "jac", "guards", "impact", "observe", "outputs"]


def test_the_message_names_what_is_compiled_and_a_measured_time():
    text = coldstart.message(["integrate", "batch"], "paper", coldstart.estimate(["integrate", "batch"], "paper"))
    assert "integration kernels" in text and "sweep kernel" in text and "`paper`" in text
    seconds = coldstart.measured()["seconds"]
    assert {"integrate", "batch", "model:paper"} <= set(seconds)
    assert f"about {5 * round(sum(seconds[k] for k in ('integrate', 'batch', 'model:paper')) / 5)} s" in text


@pytest.mark.parametrize("argv, expected", [
    (["-m", "tswm_runtime.cli", "simulate", "paper"], ("integration kernels", "the model `paper`")),
    (["-m", "tswm_runtime.cli", "sweep", "paper", "--samples", "4", "--range", "F2=-20000:5000"],
     ("integration kernels", "sweep kernel", "the model `paper`")),
    (["-c", "from tswm_runtime.simulation.simulate import simulate; simulate('paper')"], ("integration kernels",)),
    (["-m", "tswm_runtime.cli", "simulate", "mov"], ("integration kernels", "drive-train kernel")),
    (["-m", "tswm_runtime.cli", "sweep", "mov", "--grid", "voltage=0.9,1"],
     ("integration kernels", "drive-train kernel", "drive-train sweep kernel")),
], ids=["cli-simulate", "cli-sweep", "api-simulate", "cli-simulate-chain", "cli-sweep-chain"])
def test_a_first_run_with_an_empty_cache_says_what_it_compiles(tmp_path, argv, expected):
    line = _first_stderr_line([sys.executable, *argv], tmp_path)
    assert line.startswith("tswm: compiling "), line
    assert all(part in line for part in expected), line
    assert "about " in line and " once" in line


def test_a_warm_run_says_nothing_about_compiling():
    argv = [sys.executable, "-m", "tswm_runtime.cli", "simulate", "paper", "--points", "2"]
    first = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=900)  # compiles if need be
    assert first.returncode == 0, first.stderr
    run = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "compiling" not in run.stderr


@pytest.mark.slow
def test_an_empty_cache_run_completes_after_its_message(tmp_path):
    """The whole first run (about a minute on 2 cores): message first, then the result; a
    second run in the same cache is silent."""
    argv = [sys.executable, "-m", "tswm_runtime.cli", "simulate", "paper", "--points", "2"]
    env = _empty_cache(tmp_path)
    first = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=env, timeout=900)
    assert first.returncode == 0 and first.stderr.startswith("tswm: compiling "), first.stderr
    second = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert second.returncode == 0 and "compiling" not in second.stderr


@pytest.mark.slow
def test_a_forced_compile_leaves_a_cache_that_the_next_runs_find(tmp_path):
    """TSWM_COLD_START=foreground on an empty cache compiles what a sweep needs (the integration
    kernels with the segment kernel, the sweep kernel, the dopri5 step, the model); the next
    simulate and sweep, in the default mode, which would say so and run interpreted if anything
    were cold, find it all: nothing on stderr, and the sweep prints the forced run's table."""
    sweep = [sys.executable, "-m", "tswm_runtime.cli", "sweep", "paper", "--samples", "4", "--range",
             "F2=-20000:5000", "--no-progress"]
    simulate = [sys.executable, "-m", "tswm_runtime.cli", "simulate", "paper", "--points", "2"]
    forced = subprocess.run(sweep, capture_output=True, text=True, cwd=ROOT, timeout=1800,
                            env={**_empty_cache(tmp_path), "TSWM_COLD_START": "foreground"})
    assert forced.returncode == 0 and forced.stderr.startswith("tswm: compiling "), forced.stderr
    later = {**_empty_cache(tmp_path), "TSWM_COLD_START": "background"}
    for argv in (simulate, sweep):
        run = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=later, timeout=300)
        assert run.returncode == 0 and run.stderr == "", (argv[3], run.stderr)
    table = [run.stdout.split(" in ")[0], *run.stdout.splitlines()[1:]]   # the seconds taken aside
    assert table == [forced.stdout.split(" in ")[0], *forced.stdout.splitlines()[1:]] and "status:" in run.stdout
