"""On-disk caches across processes: kernel edits invalidate, path-loaded models reload."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tswm_runtime.jit import cache_guard

ROOT = Path(__file__).parents[1]
KERNEL_USER = '''
from tswm_runtime.jit.cache_guard import compile_cached

@compile_cached("float64(float64)")
def twice(x):
    return 2.0 * x

print(twice(21.0))
'''


def _python(code: str, cwd: Path) -> str:
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True,
                          env={"PYTHONPATH": f"{ROOT}:{cwd}", "PATH": ""})
    assert done.returncode == 0, done.stderr
    return done.stdout


def _python_cached(code: str, cwd: Path, cache: Path) -> str:
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True,
                          env={"PYTHONPATH": f"{ROOT}:{cwd}", "PATH": "", "NUMBA_CACHE_DIR": str(cache)})
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_stale_kernel_digest_purges_the_kernel_caches_once_and_only_there(tmp_path):
    """Each directory of kernel caches holds the kernel digest; a stale one (as after an edit of
    dopri5.py or events.py) makes the next compile purge that directory's kernel caches and
    renew it. A right one purges nothing, and under NUMBA_CACHE_DIR only that cache is touched,
    never the checkout's __pycache__."""
    cache = tmp_path / "cache"
    (tmp_path / "kernel_user.py").write_text(KERNEL_USER)
    checkout = sorted((ROOT / "tswm_runtime").glob("*/__pycache__/*.nb[ic]"))
    assert _python_cached("import kernel_user", tmp_path, cache).strip() == "42.0"
    markers = {("integration" if "integration" in str(m) else "hybrid"): m for m in cache.rglob(cache_guard.MARKER)}
    assert set(markers) == {"integration", "hybrid"}
    assert all(m.read_text() == cache_guard.kernel_digest() for m in markers.values())
    old = {key: m.parent / f"{'segment' if key == 'integration' else 'machine'}.kernel-7.py311.1.nbi"
           for key, m in markers.items()}
    for path in old.values():
        path.write_text("compiled from older kernels")
    assert _python_cached("import kernel_user", tmp_path, cache).strip() == "42.0"
    assert all(path.exists() for path in old.values()), "a right marker purges nothing"
    markers["integration"].write_text("an older kernel")
    assert _python_cached("import kernel_user", tmp_path, cache).strip() == "42.0"
    assert not old["integration"].exists() and old["hybrid"].exists()
    assert markers["integration"].read_text() == cache_guard.kernel_digest()
    assert sorted((ROOT / "tswm_runtime").glob("*/__pycache__/*.nb[ic]")) == checkout


@pytest.mark.heavy
def test_a_module_loaded_by_path_runs_again_from_its_cache(tmp_path):
    """numba rebuilds a cached function's module by name: load_module must register it."""
    shutil.copy(ROOT / "generated" / "paper.py", tmp_path / "paper.py")
    code = ("from tswm_runtime.simulation.simulate import simulate; "
            f"print(simulate({str(tmp_path / 'paper.py')!r}, {{'F2': -1000.0}}).status)")
    assert _python(code, tmp_path).strip() == "finished"
    assert list(tmp_path.glob("__pycache__/*.nbi")), "the model was cached"
    assert _python(code, tmp_path).strip() == "finished"


@pytest.mark.heavy
def test_a_cache_directory_that_vanishes_while_compiling_costs_the_cache_not_the_run(tmp_path, monkeypatch, capsys):
    """numba writing its cache index into a __pycache__ that another process just deleted: the run
    goes on compiled in memory (exit 0), with a warning, instead of exiting 2 as if the input were bad."""
    import pytest
    from numba.core import caching

    from tswm_runtime.cli import main

    def vanished(self, key, data):
        raise FileNotFoundError(2, "No such file or directory", str(tmp_path / "__pycache__" / "m.nbi.tmp"))

    model = tmp_path / "seating_copy.py"
    shutil.copyfile(ROOT / "generated" / "seating.py", model)
    monkeypatch.setattr(caching.IndexDataCacheFile, "save", vanished)
    with pytest.warns(cache_guard.CacheIOWarning, match="compiled in memory only"):
        code = main(["simulate", str(model), "--t-end", "0.01", "--no-plot"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "status: finished" in captured.out


@cache_guard.njit(error_model="numpy")
def _shifted(k, x):
    return x + k


@cache_guard.njit(error_model="numpy", no_cpython_wrapper=False)
def _calls_with_constants(x):
    i = 0  # a constant first, widened to int64 by the loop
    for _ in range(3):
        i = _shifted(i, 1)
    return _shifted(3, x) + _shifted(4, x) + i


def test_helpers_compile_once_per_argument_types_not_per_constant_passed():
    """cache_guard.njit types constant arguments as plain int64: numba's own njit would compile
    _shifted three times or more here (Literal[int](0), (3), (4), then int64). Built without a
    CPython wrapper, a helper refuses a call from Python (numba would crash)."""
    assert _calls_with_constants(1.0) == 12.0
    assert [tuple(map(str, s)) for s in _shifted.signatures] == [("int64", "int64"), ("int64", "float64")]
    with pytest.raises(TypeError, match="helper of compiled code"):
        _shifted(1, 2.0)
