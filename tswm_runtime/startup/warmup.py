"""A cold numba cache costs no wait (the promise: the first result within 15 s): the command
runs interpreted while a background process compiles the kernels into the cache.

Compiling the integration kernels takes about 40 s on 2 cores; the same kernels run by the
Python interpreter (numba's ``DISABLE_JIT``, the very same source) finish a typical scene in
tens of milliseconds of work. So a CLI command that finds a kernel it needs missing from
numba's disk cache (``coldstart.cold``) runs this once interpreted, and starts
``python -m tswm_runtime.startup.warmup`` detached, at low priority, to compile them; later
commands load them from the cache. ``TSWM_COLD_START`` chooses:

* ``background`` (default): as above;
* ``foreground``: compile first, then run (the only way before; the tests' setting);
* ``interpret``: run interpreted and compile nothing (a read-only cache, a one-off).

A background compile holds an exclusive lock (a file in the temporary directory, named after
numba's cache directory), so concurrent commands start at most one; its messages go to the
log beside the lock. The Python API (``simulate()``, ``sweep()``) always compiles: a script
that calls it in a loop wants the compiled kernels.
"""
from __future__ import annotations

import argparse
import hashlib
import logging
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from tswm_runtime.jit import coldstart

try:
    import fcntl   # the background compile's lock; without it (Windows) commands compile first
except ImportError:  # pragma: no cover - POSIX machines have it
    fcntl = None

ENV = "TSWM_COLD_START"
MODES = ("background", "foreground", "interpret")
METHOD_GROUPS = ("dopri5", "rosenbrock23", "rodas4")
PROBE_CASES = 8   # a sweep times this many cases interpreted to choose between interpreting and compiling


#: What interpreted kernels raise where compiled ones (error_model "numpy") give inf or nan: x / 0.0
#: on Python floats, math.exp overflow, math.sqrt of a negative number. A command that meets one
#: reruns compiled (``rerun_compiled``).
PYTHON_ONLY_ERRORS = (ArithmeticError, ValueError)


class ColdStartError(ValueError):
    """TSWM_COLD_START has a value that is not one of MODES."""


def mode() -> str:
    value = os.environ.get(ENV, "background").strip().lower() or "background"
    if value not in MODES:
        raise ColdStartError(f"{ENV}={os.environ[ENV]!r}: expected one of {', '.join(MODES)}")
    return value


@dataclass(frozen=True)
class ColdStart:
    """What a command found missing from numba's cache, and how it runs without it."""
    groups: tuple[str, ...]   # keys of coldstart.GROUPS
    model: object             # the scene spec, if its module is cold, else None
    mode: str                 # "background" or "interpret"

    @property
    def model_name(self) -> str | None:
        return None if self.model is None else coldstart.model_name(self.model)


def interpret_if_cold(groups, spec) -> ColdStart | None:
    """Before any kernel module is imported: if one of ``groups`` or the model ``spec`` is not in
    numba's cache and TSWM_COLD_START is not ``foreground``, switch numba's jit off for this
    process (the kernels are then imported as Python) and return what is cold; else announce
    the compile as before (``coldstart.say``) and return None."""
    how = mode()
    if how == "background" and fcntl is None:
        how = "foreground"
    parts = coldstart.check(groups, spec)
    if parts is None:
        return None
    if how == "foreground":
        coldstart.say(*parts)
        return None
    import numba
    import numpy as np

    numba.config.DISABLE_JIT = True   # read by numba.njit when each kernel module is imported
    np.seterr(all="ignore")           # IEEE results without warnings, as the compiled kernels give
    return ColdStart(tuple(parts[0]), spec if parts[1] is not None else None, how)


def lock_path() -> Path:
    """The background compile's lock: one per numba cache directory."""
    directory = coldstart.cache_directory_of_kernels()
    digest = hashlib.sha256(str(directory).encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / f"tswm-warmup-{digest}.lock"


def running() -> bool:
    """Whether a background compile holds the lock now (never without fcntl: none is started)."""
    if fcntl is None:
        return False
    try:
        with open(lock_path(), "a") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    return False


def wait() -> None:
    """Return once no background compile holds the lock (at once without fcntl: none is started)."""
    if fcntl is None:
        return
    with open(lock_path(), "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)


def _to_compile(cold: ColdStart, method: str | None) -> tuple[list[str], float]:
    """The groups to compile for ``cold`` and ``method``'s step, and the measured seconds for them."""
    groups = [*cold.groups, *coldstart.STEP_GROUPS.get(method, ())]
    return groups, coldstart.estimate(groups, cold.model_name)


def begin(cold: ColdStart, method: str | None) -> str:
    """Say how this command runs, and start the background compile of what it found cold plus
    ``method``'s step (the other method's is left for its first run). Returns the message."""
    groups, seconds = _to_compile(cold, method)
    head = (f"tswm: {coldstart.describe(cold.groups, cold.model_name)} not in numba's cache yet: this run is "
            "interpreted (no compile wait; slower per step)")
    log = lock_path().with_suffix(".log")
    if cold.mode == "interpret":
        text = f"{head}; {ENV}=interpret: nothing is compiled"
    elif running():
        text = f"{head}; a background compile is already under way (log: {log})"
    else:
        try:
            _spawn(groups, cold.model, log)
        except OSError as error:  # an unwritable temporary directory: no background compile, the run goes on
            text = (f"{head}; the background compile could not start ({log}: {error.strerror or error}): "
                    "later runs will be interpreted too")
        else:
            text = (f"{head}, while a background process compiles them for later runs: about "
                    f"{coldstart.about(seconds)} s (measured on 2 cores), once (log: {log}; {ENV}=foreground "
                    "compiles before running instead)")
    coldstart.LOG.warning(text)
    return text


def interpreting_is_quicker(cold: ColdStart, module, P, overrides: dict, method: str | None) -> bool:
    """For a sweep: whether its cases, interpreted, take less time than compiling first (the
    estimate) and running them compiled. Times up to PROBE_CASES cases interpreted (after one
    untimed case: the first call sets up its columns); says so if compiling wins."""
    import time

    from tswm_runtime.simulation.simulate import settings
    from tswm_runtime.sweeps.rows import case_table

    n = P.shape[0]
    if cold.mode == "interpret" or n <= PROBE_CASES:
        return True
    run = settings(module, overrides)
    try:
        case_table(module, P[:1], run)
        start = time.perf_counter()
        case_table(module, P[1:1 + PROBE_CASES], run)
    except PYTHON_ONLY_ERRORS as error:
        coldstart.LOG.warning(f"tswm: the interpreted probe stopped on {type(error).__name__}: {error}: compiling")
        return False
    interpreted = (time.perf_counter() - start) / PROBE_CASES * n
    compiling = _to_compile(cold, method)[1]
    if interpreted <= compiling:
        return True
    coldstart.LOG.warning(f"tswm: {P.shape[0]} cases interpreted would take about {interpreted:.3g} s, more "
                          f"than compiling first (about {coldstart.about(compiling)} s): compiling")
    return False


def rerun_compiled(argv: list[str], error: Exception | None = None) -> int:
    """Run the CLI command ``argv`` again in a new process that compiles first (this one has
    imported its kernels as Python), after a background compile under way has finished; its exit
    status. ``error``: why (an exception the interpreted kernels raised, see PYTHON_ONLY_ERRORS)."""
    if error is not None:
        coldstart.LOG.warning(f"tswm: the interpreted run stopped on {type(error).__name__}: {error} (Python "
                              "arithmetic; compiled code gives inf or nan there): running it compiled")
    if running():
        coldstart.LOG.warning("tswm: waiting for the background compile to finish")
        wait()
    sys.stdout.flush()
    sys.stderr.flush()
    return subprocess.call([sys.executable, "-m", "tswm_runtime.cli", *argv], env={**os.environ, ENV: "foreground"})


def _spawn(groups, spec, log: Path) -> None:
    argv = [sys.executable, "-m", "tswm_runtime.startup.warmup", *groups]
    if spec is not None:
        argv += ["--model", str(Path(spec).resolve()) if str(spec).endswith(".py") else str(spec)]
    env = {**os.environ, ENV: "foreground"}
    with open(log, "w") as handle:
        subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=handle, stderr=handle, env=env, start_new_session=True)


def compile_into_cache(groups, spec) -> None:
    """Import (so compile, or load) the kernels of ``groups`` and the model ``spec``."""
    from tswm_runtime.simulation.simulate import METHODS
    from tswm_runtime.integration import segment
    from tswm_runtime.model.contract import load_module
    import tswm_runtime.hybrid.segments  # noqa: F401  (the segment kernel: entry imports it at its first run only)

    if "batch" in groups:
        import tswm_runtime.hybrid.batch  # noqa: F401
    if "chain" in groups:
        import tswm_runtime.chains.answers  # noqa: F401  (with it the chain kernel)
    if "chain-batch" in groups:
        import tswm_runtime.chains.batch  # noqa: F401
    for method in METHOD_GROUPS:
        if method in groups:
            segment.attempt_function(METHODS[method])
    if spec is not None:
        load_module(spec)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tswm_runtime.startup.warmup",
                                     description="compile tswm's kernels into numba's cache (started by the CLI)")
    parser.add_argument("groups", nargs="*", choices=list(coldstart.GROUPS))
    parser.add_argument("--model", help="a scene name or a generated module's .py path")
    args = parser.parse_args(argv)
    logging.basicConfig(format="%(message)s")
    with open(lock_path(), "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print("another background compile holds the lock; nothing to do")
            return 0
        os.nice(10)
        compile_into_cache(args.groups, args.model)
        print("compiled")
    return 0


if __name__ == "__main__":
    sys.exit(main())
