"""On-disk caches across processes: kernel edits invalidate, path-loaded models reload."""
import shutil
import subprocess
import sys
from pathlib import Path

from tswm_runtime.integration import cache_guard

ROOT = Path(__file__).parents[1]
KERNEL_USER = '''
from tswm_runtime.integration.cache_guard import compile_cached

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


def test_a_stale_kernel_digest_flushes_the_cache_and_is_renewed(tmp_path):
    """The marker beside the cache holds the kernel digest; a stale one (as after an edit
    of dopri5.py, rosenbrock.py or events.py) makes the next import flush and renew it."""
    (tmp_path / "kernel_user.py").write_text(KERNEL_USER)
    assert _python("import kernel_user", tmp_path).strip() == "42.0"
    [marker] = tmp_path.rglob("*.kernel-sha256")
    assert marker.read_text() == cache_guard.kernel_digest()
    marker.write_text("an older kernel")
    assert _python("import kernel_user", tmp_path).strip() == "42.0"
    assert marker.read_text() == cache_guard.kernel_digest()


def test_a_module_loaded_by_path_runs_again_from_its_cache(tmp_path):
    """numba rebuilds a cached function's module by name: load_module must register it."""
    shutil.copy(ROOT / "generated" / "paper.py", tmp_path / "paper.py")
    code = ("from tswm_runtime.apps.simulate import simulate; "
            f"print(simulate({str(tmp_path / 'paper.py')!r}, {{'F2': -1000.0}}).status)")
    assert _python(code, tmp_path).strip() == "finished"
    assert list(tmp_path.glob("__pycache__/*.nbi")), "the model was cached"
    assert _python(code, tmp_path).strip() == "finished"


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
