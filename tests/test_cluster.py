"""Sweeps on a real local dask cluster (``dask scheduler`` and ``dask worker`` processes from the
venv): the table equals the in-process one, a killed worker changes nothing, a killed scheduler
ends with exit 1 and a resume that gives the same table, a cluster without workers gives up
when told, a worker of another tswm is named and refused, the model file travels with the work."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np
import pandas as pd
import pytest

from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module
from tswm_runtime.sweeps import cluster
from tswm_runtime.sweeps.sweep import grid_cases, parse_grid, read_table, sweep

pytestmark = pytest.mark.heavy   # each test starts a dask cluster: CI runs them after the default set

pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
GRID = ["--grid", "F2=-15000:-1000:8", "--grid", "m2=150:250:5"]   # 40 cases
SETTINGS = {"t_end": 0.5}
# Worker preload scripts (dask may run a preload more than once: each is idempotent).
SLOW = ("import time\nfrom tswm_runtime.sweeps import rows\n_real = rows.__dict__.setdefault('unslowed', rows.case_table)\n\n\n"
        "def case_table(module, P, run):\n    time.sleep(0.4)\n    return _real(module, P, run)\n\n\n"
        "rows.case_table = case_table\n")
NO_TSWM = "import sys\nsys.modules['tswm_runtime'] = None   # import tswm_runtime raises ModuleNotFoundError\n"
OTHER_VERSION = "from tswm_runtime.common import provenance\nprovenance.TSWM_VERSION = '0.0.0-other'\n"
# dask's own diagnostics off in the test cluster: the workers' statistical profiler samples every 10 ms
# (CPU spent while a worker idles through a test), nothing here reads it.
QUIET = {"DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False"}


class Cluster:
    """A scheduler and workers as processes of this test; everything is killed at the end."""

    def __init__(self, directory: Path):
        self.directory, self.processes = directory, []
        self.env = {**os.environ, "PYTHONPATH": str(ROOT), **QUIET}
        info = directory / "scheduler.json"
        self.scheduler = self._start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                      "--scheduler-file", str(info)], "scheduler")
        self.address = json.loads(self._wait_for_file(info).read_text())["address"]

    def _start(self, argv, log, env=None):
        with open(self.directory / f"{log}.log", "wb") as out:
            process = subprocess.Popen([str(BIN / "dask"), *argv], stdout=out, stderr=subprocess.STDOUT,
                                       env=env or self.env, cwd=self.directory)
        self.processes.append(process)
        return process

    @staticmethod
    def _wait_for_file(path: Path, timeout=60) -> Path:
        end = time.monotonic() + timeout
        while not (path.exists() and path.stat().st_size):
            assert time.monotonic() < end, f"{path} did not appear"
            time.sleep(0.1)
        time.sleep(0.2)
        return path

    def worker(self, name: str, preload: str | None = None, env: dict | None = None):
        """A worker with one thread and no nanny (a kill is final), started and connected."""
        argv = ["worker", self.address, "--name", name, "--nthreads", "1", "--no-nanny", "--no-dashboard"]
        if preload is not None:
            script = self.directory / f"preload_{name}.py"
            script.write_text(preload)
            argv += ["--preload", str(script)]
        process = self._start(argv, name, {**self.env, **(env or {})})
        from distributed import Client

        with Client(self.address, timeout=30) as client:
            end = time.monotonic() + 120
            while name not in {w["name"] for w in client.scheduler_info(n_workers=-1)["workers"].values()}:
                assert process.poll() is None, (self.directory / f"{name}.log").read_text()
                assert time.monotonic() < end, f"worker {name} did not connect"
                time.sleep(0.2)
        return process

    def close(self):
        for process in reversed(self.processes):
            if process.poll() is None:
                process.kill()
            process.wait(timeout=30)


@pytest.fixture
def dask_cluster(tmp_path):
    made = Cluster(tmp_path)
    yield made
    made.close()


@pytest.fixture(scope="module")
def reference():
    """The same sweep in this process, without dask."""
    module = load_module("paper")
    return sweep(module, grid_cases(module, parse_grid(GRID[1::2], module)), SETTINGS).table


def argv(directory: Path, *extra: str) -> list[str]:
    return ["sweep", "paper", *GRID, "--t-end", "0.5", "--chunk-size", "4", "-o", str(directory), *extra]


def cli(args: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "tswm_runtime.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})


def wait_for_chunks(directory: Path, count: int, process: subprocess.Popen, timeout=120) -> None:
    end = time.monotonic() + timeout
    while len(list((directory / "chunks").glob("chunk-*.parquet"))) < count:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < end, "no chunk arrived"
        time.sleep(0.05)


def test_cluster_table_equals_local_and_progress_counts_chunks(dask_cluster, reference, tmp_path, capsys):
    dask_cluster.worker("w1")
    dask_cluster.worker("w2")
    out = tmp_path / "out"
    assert main(argv(out, "--scheduler", dask_cluster.address)) == 0
    captured = capsys.readouterr()
    assert "10/10" in captured.err and "computed 10" in captured.out   # the bar counts the cluster's chunks
    pd.testing.assert_frame_equal(read_table(out / "paper-sweep.parquet"), reference)


def test_killed_worker_is_rescheduled_with_identical_table(dask_cluster, reference, tmp_path):
    dask_cluster.worker("slow1", SLOW)
    victim = dask_cluster.worker("slow2", SLOW)
    out = tmp_path / "out"
    run = cli(argv(out, "--scheduler", dask_cluster.address, "--no-progress"))
    wait_for_chunks(out, 2, run)
    victim.send_signal(signal.SIGKILL)
    stdout, stderr = run.communicate(timeout=300)
    assert run.returncode == 0, stderr
    assert victim.wait() == -signal.SIGKILL
    pd.testing.assert_frame_equal(read_table(out / "paper-sweep.parquet"), reference)


def test_killed_scheduler_exits_1_with_resume_and_rerun_gives_same_table(dask_cluster, reference, tmp_path, capsys):
    dask_cluster.worker("slow1", SLOW)
    out = tmp_path / "out"
    args = argv(out, "--scheduler", dask_cluster.address, "--no-progress")
    run = cli(args)
    wait_for_chunks(out, 2, run)
    dask_cluster.scheduler.send_signal(signal.SIGKILL)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 1, stderr
    safe = len(list((out / "chunks").glob("chunk-*.parquet")))
    assert "cluster problem: lost the dask scheduler" in stderr, stderr
    assert f"{safe} of 10 chunks are complete in {out / 'chunks'}" in stderr
    assert "resume with: tswm sweep paper --grid F2=-15000:-1000:8" in stderr and "Traceback" not in stderr
    assert not (out / "paper-sweep.parquet").exists()
    capsys.readouterr()
    assert main([a for a in args if a not in ("--scheduler", dask_cluster.address)]) == 0   # resumed here
    stdout, stderr = capsys.readouterr()
    assert f"resuming: {safe} of 10 chunks are already complete" in stderr and f"reused {safe}" in stdout
    pd.testing.assert_frame_equal(read_table(out / "paper-sweep.parquet"), reference)


def test_no_workers_gives_a_notice_and_gives_up(dask_cluster, tmp_path, capsys):
    start = time.monotonic()
    assert main(argv(tmp_path / "out", "--scheduler", dask_cluster.address, "--wait-for-workers", "3",
                     "--no-progress")) == 1
    err = capsys.readouterr().err
    assert f"the dask scheduler at {dask_cluster.address} has no workers; waiting" in err
    assert "had no workers for 3 s (--wait-for-workers)" in err and "0 of 10 chunks are complete" in err
    assert "resume with: tswm sweep paper" in err and "Traceback" not in err
    assert time.monotonic() - start < 60


def test_worker_of_another_version_is_named_and_refused(dask_cluster, tmp_path, capsys):
    dask_cluster.worker("good")
    dask_cluster.worker("odd", OTHER_VERSION)
    out = tmp_path / "out"
    assert main(argv(out, "--scheduler", dask_cluster.address, "--no-progress")) == 1
    err = capsys.readouterr().err
    assert "refusing to mix results" in err and "worker odd (tcp://" in err, err
    assert "tswm 0.0.0-other (here " in err and "worker good" not in err
    assert not list((out / "chunks").glob("chunk-*.parquet")) and not (out / "paper-sweep.parquet").exists()


def test_module_file_travels_to_a_worker_that_compiles_it_and_says_so(dask_cluster, reference, tmp_path, capsys):
    """A copy of the paper module under another name, in a folder the worker never reads; the
    worker has its own temporary directory and writes the shipped source there."""
    elsewhere = tmp_path / "client-only"
    elsewhere.mkdir()
    module_file = elsewhere / "gear_copy.py"
    module_file.write_bytes((ROOT / "generated" / "paper.py").read_bytes())
    worker_tmp = tmp_path / "worker-tmp"
    worker_tmp.mkdir()
    dask_cluster.worker("w1", env={"TMPDIR": str(worker_tmp)})
    out = tmp_path / "out"
    args = argv(out, "--scheduler", dask_cluster.address, "--no-progress")
    args[1] = str(module_file)
    assert main(args) == 0
    err = capsys.readouterr().err
    assert err.count("is compiling") == 1 and "worker w1 (tcp://" in err and "the model `paper`" in err, err
    sha = cluster.package(load_module(module_file)).sha256
    assert (worker_tmp / cluster.MODEL_DIR / sha[:16] / "gear_copy.py").read_bytes() == module_file.read_bytes()
    pd.testing.assert_frame_equal(read_table(out / "paper-sweep.parquet"), reference)


def test_chunk_uses_the_workers_threads(dask_cluster):
    """A worker given one thread runs its chunk on one numba thread; this process keeps all cores."""
    from distributed import Client

    dask_cluster.worker("w1")
    module = load_module("paper")
    P = grid_cases(module, parse_grid(["F2=-15000:-1000:3"], module))
    from tswm_runtime.simulation.simulate import settings

    with Client(dask_cluster.address, timeout=30) as client:
        stamp, table = client.submit(cluster.chunk_task, cluster.package(module), P, settings(module, SETTINGS),
                                     pure=False).result(timeout=120)
    assert stamp["numba threads"] == 1 and len(table) == 3
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS
    assert np.array_equal(table["F2"].to_numpy(), P[:, 1])


def test_worker_without_tswm_is_named_and_refused(dask_cluster, tmp_path, capsys):
    dask_cluster.worker("bare", NO_TSWM)
    assert main(argv(tmp_path / "out", "--scheduler", dask_cluster.address, "--no-progress")) == 1
    err = capsys.readouterr().err
    assert "worker bare (tcp://" in err and "cannot run tswm's handshake" in err and "tswm_runtime" in err, err
