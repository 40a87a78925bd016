"""Sweep chunks on a dask.distributed cluster, with checks a user can trust (docs/cluster.md).

* The model travels with the work: each chunk task carries the generated module's source
  (``ModelPackage``), verified by its sha256 on the worker and loaded there from a temporary
  file (or from the worker's own ``generated/`` module when it is the same file), so
  scene files and ``.py`` modules need no shared file system.
* Before any work, every worker answers a handshake (``handshake``): tswm's version, the
  runtime digest, the model digest it loads, numba, its threads and what it would compile. A
  worker that differs is named with what differs and the sweep refuses to run (``ClusterError``);
  each chunk also returns its worker's stamp, so a worker that joins later cannot mix in rows.
* A worker with kernels to compile says so on the client, once per worker, with its estimate.
* No workers: a notice within a few seconds, a status line every STATUS_EVERY_S seconds, and
  after ``wait_for_workers`` seconds a ``ClusterError``. Losing the scheduler, or every worker
  for that long, is a ``ClusterError`` too; the caller says how many chunks are safe.
* Each chunk runs with numba's threads set to its worker's nthreads, one chunk at a time per
  worker process (numba's thread pool is shared by the process).
"""
from __future__ import annotations

import functools
import hashlib
import logging
import tempfile
import threading
import time
from concurrent.futures import CancelledError
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from tswm_runtime.jit import coldstart
from tswm_runtime.sweeps import chunks

LOG = logging.getLogger("tswm_runtime.sweep")
POLL_S = 0.5
STATUS_EVERY_S = 10.0
FIRST_NOTICE_S = 2.0
KERNEL_GROUPS = ("integrate", "batch")   # and the run's method's step
MODEL_DIR = "tswm-models"   # under the worker's temporary directory: one folder per model digest
_lock = threading.Lock()    # one chunk at a time per worker process
_loaded: dict[str, ModuleType] = {}


class ClusterError(RuntimeError):
    """The cluster cannot finish the sweep (scheduler or workers lost, a mismatched worker);
    the message names the problem."""


@dataclass(frozen=True)
class ModelPackage:
    """A generated module as it travels to the workers: its source and digests."""

    scene: str
    stem: str
    source: bytes
    sha256: str        # of source, checked on arrival
    model_digest: str  # sha256 of the module file (chunks.model_digest), part of every chunk key


def package(module: ModuleType) -> ModelPackage:
    source = Path(module.__file__).read_bytes()
    return ModelPackage(module.SCENE, Path(module.__file__).stem, source, hashlib.sha256(source).hexdigest(),
                        chunks.model_digest(module))


def _model_file(pack: ModelPackage) -> tuple[Path, str]:
    """(file, module name) this worker loads ``pack`` from: its own generated module when that
    is the same file (its numba cache stays in use), else the shipped source written to
    a temporary file named by the source's digest."""
    if hashlib.sha256(pack.source).hexdigest() != pack.sha256:
        raise ClusterError(f"the model source of scene {pack.scene!r} arrived damaged (sha256 differs)")
    import generated

    own = Path(generated.__file__).with_name(f"{pack.stem}.py")
    if own.is_file() and chunks.file_digest(own) == pack.model_digest:
        return own, f"generated.{pack.stem}"
    folder = Path(tempfile.gettempdir()) / MODEL_DIR / pack.sha256[:16]
    path = folder / f"{pack.stem}.py"
    if not path.is_file() or path.read_bytes() != pack.source:
        from tswm_common.files import write_atomic

        folder.mkdir(parents=True, exist_ok=True)
        write_atomic(path, pack.source)
    return path, f"tswm_model_{pack.stem}"


def installed(pack: ModelPackage) -> ModuleType:
    """The model of ``pack`` loaded in this worker process (once per digest)."""
    if pack.sha256 not in _loaded:
        import importlib

        from tswm_runtime.model.contract import check_module, load_module

        path, name = _model_file(pack)
        _loaded[pack.sha256] = (check_module(importlib.import_module(name)) if name.startswith("generated.")
                                else load_module(path))
    return _loaded[pack.sha256]


@functools.lru_cache(maxsize=1)
def _runtime() -> tuple[str, str]:
    from tswm_runtime.common import provenance

    return provenance.TSWM_VERSION, chunks.runtime_digest()


def expected(pack: ModelPackage) -> dict:
    """What a chunk's rows depend on besides its rows and settings, as this process has it:
    tswm's version, the runtime digest, the model file's sha256."""
    version, runtime = _runtime()
    return {"tswm": version, "runtime digest": runtime, "model digest": pack.model_digest}


def stamp(pack: ModelPackage) -> dict:
    """``expected`` as a worker has it: the model digest of the file it loads."""
    return {**expected(pack), "model digest": chunks.file_digest(_model_file(pack)[0])}


def handshake(pack: ModelPackage, groups: tuple[str, ...], dask_worker=None) -> dict:
    """Run on a worker (``Client.run`` passes it as ``dask_worker``) before any chunk, compiling
    nothing: its stamp, numba, threads and which of the kernel ``groups`` (coldstart.GROUPS) and
    the model it would compile, with coldstart's estimate."""
    import numba   # without numba (or tswm_runtime) the handshake fails to load: ``differences`` says so

    path, name = _model_file(pack)
    cold = coldstart.cold_groups(groups)
    model = pack.scene if coldstart.model_cold(path, name) else None
    return {**stamp(pack), "numba": numba.__version__, "nthreads": dask_worker.state.nthreads,
            "compiles": coldstart.describe(cold, model) if cold or model else "",
            "seconds": coldstart.estimate(cold, model)}


def differences(here: dict, there: dict) -> list[str]:
    """What a worker's handshake answer says differently from this process's."""
    if isinstance(there, BaseException):
        return [f"cannot run tswm's handshake ({type(there).__name__}: {there}); does the worker's Python have "
                "tswm_runtime, numba and their dependencies installed?"]
    return [f"{key} {there.get(key)} (here {value})" for key, value in here.items() if there.get(key) != value]


def chunk_task(pack: ModelPackage, P, run: dict):
    """One chunk on a worker: (the worker's stamp, address and numba threads, the rows), with
    numba's threads set to the worker's nthreads."""
    import numba
    from distributed import get_worker

    from tswm_runtime.sweeps.rows import case_table

    module = installed(pack)
    worker = get_worker()
    with _lock:
        numba.set_num_threads(max(1, min(worker.state.nthreads, numba.config.NUMBA_NUM_THREADS)))
        table = case_table(module, P, run)
        threads = numba.get_num_threads()
    return {**stamp(pack), "worker": worker.address, "numba threads": threads}, table


class Watch:
    """The client's view of the cluster while chunks run: waits for workers with a visible
    status, handshakes each new worker once (refusing a mismatched one), says when one compiles."""

    def __init__(self, client, pack: ModelPackage, method: str, wait_for_workers: float, notice):
        self.client, self.pack, self.wait, self.notice = client, pack, wait_for_workers, notice
        self.groups = (*KERNEL_GROUPS, *coldstart.STEP_GROUPS.get(method, (method,)))
        self.here = expected(pack)
        self.known: set[str] = set()
        self.empty_since: float | None = None
        self.last_status = 0.0

    def workers(self) -> dict:
        try:   # asked each time: Client.scheduler_info falls back to a cache without workers
            return self.client.sync(self.client.scheduler.identity, n_workers=-1)["workers"]
        except Exception as error:  # noqa: BLE001 - any failure to ask the scheduler is its loss
            raise ClusterError(f"lost the dask scheduler at {self.client.scheduler.address} "
                               f"({type(error).__name__}: {error})") from None

    def check(self) -> int:
        """Look at the cluster once: the number of workers (raises ClusterError when the scheduler
        is gone, a worker differs, or there were no workers for longer than ``wait``)."""
        if self.client.status != "running":
            raise ClusterError(f"lost the dask scheduler at {self.client.scheduler.address} (the connection "
                               f"closed; the client is {self.client.status})")
        workers = self.workers()
        new = sorted(set(workers) - self.known)
        if new:
            self._handshake(new, workers)
        if workers:
            if self.empty_since is not None and self.known:
                self.notice(f"{len(workers)} worker(s) connected; running")
            self.empty_since = None
            return len(workers)
        now = time.monotonic()
        if self.empty_since is None:
            self.empty_since, self.last_status = now, now
            lost = " (all workers were lost)" if self.known else ""
            self.notice(f"the dask scheduler at {self.client.scheduler.address} has no workers{lost}; waiting "
                        f"for one (giving up after {self.wait:g} s: --wait-for-workers)")
        elif now - self.last_status >= STATUS_EVERY_S:
            self.last_status = now
            self.notice(f"still no workers after {now - self.empty_since:.0f} s")
        if now - self.empty_since > self.wait:
            raise ClusterError(f"the dask scheduler at {self.client.scheduler.address} had no workers for "
                               f"{self.wait:g} s (--wait-for-workers)")
        return 0

    def _handshake(self, addresses: list[str], workers: dict) -> None:
        answers = self.client.run(handshake, self.pack, self.groups, workers=addresses, on_error="return")
        bad = []
        for address in addresses:
            answer = answers.get(address, ClusterError("the worker left before answering"))
            name = workers[address].get("name", address)
            label = address if str(name) == address else f"{name} ({address})"
            wrong = differences(self.here, answer)
            if wrong:
                bad.append(f"worker {label}: " + "; ".join(wrong))
            elif answer["compiles"]:
                self.notice(f"worker {label} is compiling {answer['compiles']} first: about "
                            f"{coldstart.about(answer['seconds'])} s, once (its numba cache keeps them)")
        self.known.update(addresses)
        if bad:
            raise ClusterError("refusing to mix results from workers that differ from this tswm:\n  "
                               + "\n  ".join(bad))

    def verify(self, worker_stamp: dict) -> None:
        """Refuse a chunk computed by a worker whose stamp differs from this process's."""
        wrong = differences(self.here, worker_stamp)
        if wrong:
            raise ClusterError(f"refusing a chunk from worker {worker_stamp.get('worker')}: " + "; ".join(wrong))


def run_chunks(client, module: ModuleType, P, run: dict, bounds, todo, finish, *, wait_for_workers: float,
               notice=None, bar=None) -> None:
    """Compute the chunks ``todo`` (indices into ``bounds``, row ranges of P) on the dask
    ``client``; ``finish(i, table)`` stores each as it arrives; ``notice(text)`` tells the user
    about the cluster (default: the ``tswm_runtime.sweep`` logger)."""
    if not todo:
        return
    watch = Watch(client, package(module), run["method"], wait_for_workers, notice or LOG.warning)
    deadline = time.monotonic() + FIRST_NOTICE_S
    while watch.check() == 0 and time.monotonic() < deadline:   # a few seconds for workers to appear
        time.sleep(POLL_S)
    futures = {client.submit(chunk_task, watch.pack, P[bounds[i][0]:bounds[i][1]], run, pure=False): i
               for i in todo}
    pending = set(futures)
    try:
        while pending:
            for future, (worker_stamp, table) in _arrived(watch, pending, futures):
                watch.verify(worker_stamp)
                finish(futures[future], table)
                if bar:
                    bar.update()
            if pending:
                watch.check()
    except BaseException:
        if client.status == "running":
            client.cancel(list(pending))
        raise


def _arrived(watch: Watch, pending: set, futures: dict) -> list:
    """The futures that finished within POLL_S, with their results, removed from ``pending``;
    a failed or cancelled chunk, or a lost connection, raises ClusterError."""
    from distributed import wait

    try:
        try:
            done, _ = wait(list(pending), timeout=POLL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            return []
        arrived = []
        for future in done:
            pending.discard(future)
            if future.status == "cancelled":
                watch.check()   # the scheduler is gone: raises
                raise ClusterError(f"the cluster cancelled chunk {futures[future]}")
            if future.status == "error":
                error = future.exception()
                raise ClusterError(f"chunk {futures[future]} failed on the cluster: {type(error).__name__}: {error}")
            arrived.append((future, future.result()))
        return arrived
    except (OSError, CancelledError) as error:   # distributed's CommClosedError, FuturesCancelledError
        watch.check()
        raise ClusterError(f"lost contact with the cluster ({type(error).__name__}: {error})") from None
