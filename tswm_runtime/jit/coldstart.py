"""Say so before numba compiles: which kernels are missing from numba's disk cache, and how long
compiling them takes: with an empty cache, a message within 1 s that says what is being
compiled and about how long.

The integrators (``integrate_hybrid``, ``integrate_at``, ``fill_rows``; for sweeps
``run_batch``) and a generated model's entry functions (``rhs``, ``jac``, ``guards``,
``observe``, ``outputs``) are compiled eagerly, with explicit signatures, when their modules
are imported; a method's step (``segment.attempt_function``) at its first run. Before that, ``announce`` asks numba's own cache machinery whether each
of them would load from disk, without compiling anything:

* numba keeps one index file per function (``<file stem>.<qualname>-<first line>.pyXY.nbi``,
  listing the compiled signatures) and one object file per signature (``.nbc``), in the
  directory its cache locator picks (``NUMBA_CACHE_DIR``, else ``__pycache__`` beside the
  source, else a user-wide directory). ``numba.core.caching.FunctionCache`` is built here
  for a stand-in function with the same file, name and first line (found by scanning the
  source, no import), so the directory, file name and freshness test are numba's: the index is used
  only if it was written by this numba version for the source file's current content, and
  an entry only if it was compiled for this CPU (``codegen.magic_tuple()``) and its object
  file exists.
* ``cache_guard.compile_cached`` additionally purges the kernel caches of a directory whose
  marker (``tswm-kernels.sha256``) differs from the digest of the kernel sources: such a
  kernel is cold too.

If anything is cold the message goes to the ``tswm_runtime.compile`` logger at WARNING
(without logging configuration Python prints it to stderr as it is; silence it with
``logging.getLogger("tswm_runtime.compile").setLevel(logging.ERROR)``), once per process and
group, e.g.::

    tswm: compiling the integration kernels (the hybrid mode machine, output rows) and the
    model `paper` into numba's cache: about 40 s (measured on 2 cores), once; later runs load
    it from there

The seconds come from ``compile_times.json``, measured with an empty ``NUMBA_CACHE_DIR``
on 2 cores by ``tools/measure_compile_times.py``. If numba's internals cannot be read (a
numba that moved them), a timer says the same after WATCHDOG_S instead.
"""
from __future__ import annotations

import importlib.util
import io
import json
import logging
import os
import pickle
import sys
import threading
import types
from functools import lru_cache
from pathlib import Path

import numba

from tswm_runtime.jit.cache_guard import MARKER

LOG = logging.getLogger("tswm_runtime.compile")
RUNTIME = Path(__file__).parents[1]  # tswm_runtime/
TIMES_FILE = Path(__file__).with_name("compile_times.json")
WATCHDOG_S = 0.5

# group -> (what the message calls it, [(source under tswm_runtime/, function, guarded by cache_guard)]):
# the functions compiled eagerly when the group's modules are imported, or (a method's step, named
# as simulate.METHODS names the method) at its first run; the kernel check purges all of them.
GROUPS = {
    "integrate": ("the integration kernels (the hybrid mode machine, output rows)",
                  [("integration/segment.py", "no_jacobian", True),
                   ("hybrid/machine.py", "integrate_hybrid", True),
                   ("hybrid/segments.py", "run_segment", True),
                   ("hybrid/entry.py", "integrate_at", True),
                   ("hybrid/rows.py", "fill_rows", True),
                   ("integration/steplog.py", "states_at", True)]),
    "batch": ("the parallel sweep kernel", [("hybrid/batch.py", "run_batch", True)]),
    "dopri5": ("the dopri5 step", [("integration/segment.py", "dopri5_attempt", True)]),
    "rosenbrock23": ("the rosenbrock23 step", [("integration/segment.py", "rosenbrock23_attempt", True)]),
    "rodas4": ("the rodas4 step", [("integration/segment.py", "rodas4_attempt", True)]),
    "chain": ("the drive-train kernel (a chain's whole run, its answers)", [("chains/kernel.py", "run_chain_at", True),
                                                                          ("chains/answers.py", "answer_run", True)]),
    "chain-batch": ("the drive-train sweep kernel", [("chains/batch.py", "run_chain_batch", True)]),
}
#: The step groups each method (``simulate.METHODS``) compiles: auto switches between dopri5's and rodas4's
#: steps (``segment.AUTO_STIFF``).
STEP_GROUPS = {"dopri5": ("dopri5",), "rosenbrock23": ("rosenbrock23",), "rodas4": ("rodas4",),
               "auto": ("dopri5", "rodas4")}

_announced: set = set()
_lock = threading.Lock()


@lru_cache(maxsize=64)
def _lines(source: Path, stamp: tuple) -> tuple[str, ...]:
    return tuple(source.read_text(encoding="utf-8").splitlines())


def _first_line(source: Path, name: str) -> int | None:
    """co_firstlineno of the top-level function ``name`` in ``source``: its first decorator's
    line (numba's cache file names carry it), or None if there is no such function. A line scan
    (``def name(`` at the margin, then up over one-line decorators; ast.parse of the kernel
    files cost ~80 ms on every start); a decorator spread over lines makes it a false "cold"."""
    st = source.stat()
    lines = _lines(source, (st.st_mtime_ns, st.st_size))
    for i, line in enumerate(lines):
        if line.startswith(f"def {name}("):
            while i > 0 and lines[i - 1].startswith("@"):
                i -= 1
            return i + 1
    return None


def _stand_in(source: Path, name: str, module: str, line: int) -> types.FunctionType:
    """A function numba's cache sees as ``module.name`` defined at ``source:line`` (never run)."""
    code = compile("\n" * (line - 1) + f"def {name}(): pass\n", str(source), "exec")
    function = types.FunctionType(next(c for c in code.co_consts if isinstance(c, types.CodeType)),
                                  {"__name__": module})
    function.__module__, function.__qualname__ = module, name
    return function


@lru_cache(maxsize=1)
def _magic_tuple():
    from numba.core.registry import cpu_target

    return cpu_target.target_context.codegen().magic_tuple()


def is_cached(source: Path, name: str, module: str, guarded: bool = False, digest: str | None = None) -> bool:
    """Whether numba would load ``module.name`` (in ``source``) from its disk cache instead of
    compiling it. guarded: compiled by cache_guard.compile_cached, which also needs its kernel
    marker to equal ``digest``."""
    from numba.core import caching

    line = _first_line(source, name)
    if line is None:
        return False
    cache = caching.FunctionCache(_stand_in(source, name, module, line))
    if guarded:
        marker = Path(cache.cache_path) / MARKER
        if not marker.exists() or marker.read_text() != digest:
            return False
    index = cache._cache_file  # numba has no public accessor for the index; see the module docstring
    magic = _magic_tuple()
    return any(key[1] == magic and os.path.exists(index._data_path(data))
               for key, data in _index_entries(index).items())


class _IndexReader(pickle.Unpickler):
    """Unpickles numba's cache index without importing a module that is not imported yet: its
    classes (the kernels' named tuples in a signature) come back as stand-ins. numba's own
    ``_load_index`` imports them, and with them the kernel modules, compiled, before
    ``warmup.interpret_if_cold`` could turn the jit off: compiled kernels then met an interpreted
    model (TypeError: No matching definition for argument type(s) pyobject, ...)."""

    def find_class(self, module, name):
        if module in sys.modules or module.partition(".")[0] in ("numba", "numpy", "llvmlite"):
            return super().find_class(module, name)
        return type(name, (), {"__module__": module})


def _index_entries(index) -> dict:
    """numba's ``IndexDataCacheFile._load_index`` (key -> data file name; empty when the index is
    missing, of another numba version or stale) through ``_IndexReader``."""
    try:
        with open(index._index_path, "rb") as handle:
            version = pickle.load(handle)
            data = handle.read()
    except FileNotFoundError:
        return {}
    if version != index._version:
        return {}
    stamp, overloads = _IndexReader(io.BytesIO(data)).load()
    return overloads if stamp == index._source_stamp else {}


def _runtime_module(relative: str) -> str:
    return "tswm_runtime." + relative.removesuffix(".py").replace("/", ".")


def cold_groups(groups) -> list[str]:
    """The groups (keys of GROUPS) with a kernel that numba would compile."""
    from tswm_runtime.jit.cache_guard import kernel_digest

    digest = kernel_digest()
    return [g for g in groups
            if not all(is_cached(RUNTIME / rel, name, _runtime_module(rel), guarded, digest)
                       for rel, name, guarded in GROUPS[g][1])]


def model_source(model) -> tuple[Path, str] | None:
    """(source file, module name) of a shipped scene name or a generated module's .py path,
    found without importing it; None if it is already imported or cannot be found."""
    if isinstance(model, types.ModuleType):
        return None
    path = Path(str(model))
    if path.suffix == ".py":
        name = f"tswm_model_{path.stem}"  # as contract.load_module names it
        return (path.resolve(), name) if name not in sys.modules and path.exists() else None
    name = f"generated.{str(model).replace('-', '_')}"
    if name in sys.modules:
        return None
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    return (Path(spec.origin), name) if spec and spec.origin else None


def model_entries(source: Path) -> list[str]:
    """The functions of a generated module compiled eagerly on import: ``@njit(<X>_SIG, ...)``
    (rhs, jac, guards, observe, outputs, ...: whatever the template gives a signature)."""
    st = source.stat()
    lines = _lines(source, (st.st_mtime_ns, st.st_size))
    names = []
    for i, line in enumerate(lines[:-1]):
        head = line.removeprefix("@njit(").split(",")[0]
        if line.startswith("@njit(") and head.endswith("_SIG") and head.isidentifier():
            j = i + 1
            while j < len(lines) and lines[j].startswith("@"):
                j += 1
            if j < len(lines) and lines[j].startswith("def "):
                names.append(lines[j][4:].split("(")[0])
    return names


def model_cold(source: Path, module: str) -> bool:
    """Whether an entry function of the generated module at ``source`` is not in numba's cache."""
    return not all(is_cached(source, name, module) for name in model_entries(source))


@lru_cache(maxsize=1)
def measured() -> dict:
    """The measured compile times (compile_times.json): {"seconds": {part: s}, ...}."""
    try:
        return json.loads(TIMES_FILE.read_text())
    except (OSError, ValueError):
        return {"seconds": {}}


def estimate(groups, model: str | None) -> float:
    """Seconds to compile ``groups`` and ``model`` (a scene name; unknown: the slowest model measured)."""
    seconds = measured()["seconds"]
    total = sum(seconds.get(g, 0.0) for g in groups)
    if model is not None:
        models = {k[6:]: v for k, v in seconds.items() if k.startswith("model:")}
        total += models.get(model, max(models.values(), default=0.0))
    return total


def describe(groups, model: str | None) -> str:
    """What the groups and the model are, in words: "the integration kernels (...) and the model `paper`"."""
    parts = [GROUPS[g][0] for g in groups] + ([f"the model `{model}`"] if model else [])
    return ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + parts[-1]


def about(seconds: float) -> str:
    """A compile time as a message says it: to 5 s, at least 5."""
    return f"{max(5 * round(seconds / 5), 5):.0f}"


def message(groups, model: str | None, seconds: float) -> str:
    return (f"tswm: compiling {describe(groups, model)} into numba's cache: about {about(seconds)} s (measured on "
            "2 cores), once; later runs load it from there")


def model_name(model) -> str:
    """The scene name a message uses for a scene name or a generated module's .py path."""
    return Path(str(model)).stem.replace("_", "-") if str(model).endswith(".py") else str(model)


def cache_directory_of_kernels() -> Path | None:
    """numba's cache directory for the mode machine (the largest kernel)."""
    from tswm_runtime.jit.cache_guard import cache_directory

    return cache_directory(RUNTIME / "hybrid" / "machine.py")


def check(groups=(), model=None) -> tuple[list[str], str | None] | None:
    """(the groups of ``groups`` (keys of GROUPS) that numba would compile on import, the scene
    name of the generated module ``model`` if it would be compiled, else None), or None if
    nothing would be; a module object counts as compiled. Each group and model is checked once
    per process (later calls leave it out) and never while numba's jit is off (``warmup``: the
    command runs interpreted). If numba's internals cannot be read, a timer announces instead
    (``_watchdog``) and the result is None. Imports none of the kernels' modules."""
    if numba.config.DISABLE_JIT:
        return None
    with _lock:
        groups = [g for g in groups if g not in _announced]
        source = model_source(model) if model is not None and ("model", str(model)) not in _announced else None
        if not groups and source is None:
            return None
        _announced.update(groups)
        if source is not None:
            _announced.add(("model", str(model)))
        try:
            cold = cold_groups(groups)
            model_is_cold = source is not None and model_cold(*source)
        except Exception:  # noqa: BLE001 - numba's internals moved: fall back to a timer
            _watchdog(groups, model if source is not None else None)
            return None
    name = model_name(model) if model_is_cold else None
    return (cold, name) if cold or name is not None else None


def say(cold: list[str], name: str | None) -> str:
    """Log (and return) the compile message for what ``check`` found cold."""
    text = message(cold, name, estimate(cold, name))
    LOG.warning(text)
    return text


def announce(groups=(), model=None) -> str | None:
    """Log the compile message if any of ``groups`` or the generated module ``model`` would be
    compiled on import (``check``); returns the message, or None. Call it before importing the
    kernels' modules."""
    parts = check(groups, model)
    return None if parts is None else say(*parts)


def _watchdog(groups, model) -> None:
    """Announce after WATCHDOG_S unless the importing thread finished by then (see ``done``)."""
    text = message(groups or ["integrate"], None if model is None else str(model),
                   estimate(groups, None if model is None else str(model))) + " (if not cached)"
    timer = threading.Timer(WATCHDOG_S, LOG.warning, (text,))
    timer.daemon = True
    _timers.append(timer)
    timer.start()


_timers: list = []


def done() -> None:
    """The kernels (or the model) are imported: cancel a pending fallback timer."""
    while _timers:
        _timers.pop().cancel()
