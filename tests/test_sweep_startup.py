"""A warm ``tswm sweep`` process loads only what the command needs."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
# What a warm sweep never needs: numba's lowering registries (loaded by its cache's refresh, with
# scipy.linalg), pandas (pyarrow builds and writes the tables), the plots, code generation, the
# cluster, the CAS.
NOT_NEEDED = ("scipy.linalg", "numba.np.linalg", "pandas", "matplotlib", "jinja2", "dask", "distributed", "sympy",
              "derivation")
SWEEP = """
import json, sys
{before}
from tswm_runtime.cli import main
assert main(['sweep', 'paper-runup', '--grid', 'm2=100:400:3', '--grid', 'F2_after=-20000:5000:4', '--no-progress',
             '-o', sys.argv[1]]) == 0
print(json.dumps(sorted(name for name in {not_needed!r} if name in sys.modules)))
"""
NUMBA_OWN_LOAD = ("import tswm_runtime.jit.cache_guard as guard\nfrom numba.core import caching\n"
                  "caching.Cache.load_overload = guard._refreshing_load")


def _sweep(tmp: Path, before: str = "") -> tuple[list[str], bytes]:
    done = subprocess.run([sys.executable, "-c", SWEEP.format(before=before, not_needed=NOT_NEEDED), str(tmp)],
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1]), (tmp / "paper-runup-sweep.csv").read_bytes()


@pytest.mark.heavy
def test_a_warm_sweep_imports_no_registry_pandas_plot_cluster_or_cas_and_computes_the_same(tmp_path):
    """The second of two sweep processes (the first fills numba's cache if it is cold) loads its
    kernels without numba's registries, builds and writes its tables without pandas, and writes
    the same table as numba's own cache load."""
    _sweep(tmp_path / "first")
    loaded, ours = _sweep(tmp_path / "warm")
    assert loaded == []
    _, numbas = _sweep(tmp_path / "numba-load", NUMBA_OWN_LOAD)
    assert ours == numbas


COMMAND = """
import atexit, sys
atexit.register(lambda: print('interpreter teardown ran'))
sys.argv = ['tswm', 'sweep', 'paper-runup', '--grid', 'm2=100:400:3', '--grid', 'F2_after={F2}', '--no-progress',
            '-o', sys.argv[1]]
from tswm_runtime.cli import command
command()
"""


def test_the_command_ends_at_once_with_its_status_and_all_written(tmp_path):
    """``tswm`` (cli.command) skips the interpreter's teardown (numba's finalizers) once its files
    are written: no atexit handler runs, yet stdout, stderr and the tables are complete, and the
    exit status is main's (0 done, 2 bad input)."""
    from tswm_runtime.sweeps.sweep import read_table

    done = subprocess.run([sys.executable, "-c", COMMAND.format(F2="-20000:5000:4"), str(tmp_path)],
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert "interpreter teardown ran" not in done.stdout
    assert done.stdout.rstrip().endswith(f"wrote {tmp_path / 'paper-runup-sweep.json'}")
    assert len(read_table(tmp_path / "paper-runup-sweep.csv")) == 12
    bad = subprocess.run([sys.executable, "-c", COMMAND.format(F2="1:2"), str(tmp_path / "bad")],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and "--grid 'F2_after=1:2'" in bad.stderr, bad.stderr
    assert "interpreter teardown ran" not in bad.stdout


CHAIN = """
import json, sys
import tswm_runtime.sweeps.chain
imported = [name for name in {single!r} if name in sys.modules]
from tswm_runtime.cli import main
assert main(['sweep', 'mov', '--grid', 'voltage=0.9,1.0', '--no-progress']) == 0
print(json.dumps([imported, [name for name in {single!r} if name in sys.modules]]))
"""
SINGLE_STAGE = ("tswm_runtime.hybrid.batch", "tswm_runtime.sweeps.rows")


def test_a_chain_sweep_loads_no_single_stage_batch_kernel():
    """Importing the chain sweep, and `tswm sweep mov` run to its end, leave the single-stage batch kernel
    (hybrid/batch.py) and the scene sweep's rows (sweeps/rows.py, which loads it) unimported."""
    done = subprocess.run([sys.executable, "-c", CHAIN.format(single=SINGLE_STAGE)], capture_output=True, text=True,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.splitlines()[-1]) == [[], []]
