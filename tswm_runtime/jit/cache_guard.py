"""Eager, cached compilation that notices edits in the kernel modules it inlines; ``njit``
for the kernels' helpers, which are compiled as code to link (``linking``).

numba keys a function's on-disk cache on its own source file only (dependencies are
not tracked, as numba's caching docs say), while the compiled integrators inline
dopri5, rosenbrock, events and segment. ``compile_cached`` keeps a sha256 over all
kernel sources in each directory of kernel caches and purges those caches when it
differs, so an edited kernel can never run as stale machine code.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import warnings
from pathlib import Path

import numba
from numba import types
from numba.core import caching, compiler
from numba.core.cpu import CPUContext
from numba.core.runtime import rtsys
from numba.core.registry import CPUDispatcher
from numba.core.typing import templates as typing_templates

from tswm_common.files import write_atomic
from tswm_runtime.jit.linking import HelperCompiler

KERNEL_SOURCES = ("jit/cache_guard.py", "jit/borrow.py", "jit/structures.py", "integration/control.py",
                  "integration/dopri5.py", "integration/rosenbrock.py", "integration/events.py", "integration/segment.py",
                  "integration/single.py", "integration/painleve.py", "integration/steplog.py", "integration/steady.py",
                  "hybrid/machine.py", "hybrid/segments.py", "hybrid/addressed.py", "hybrid/impact.py", "hybrid/batch.py",
                  "hybrid/rows.py", "hybrid/entry.py",
                  "jit/addresses.py", "jit/linking.py", "jit/arrays.py", "chains/rules.py", "chains/backlash.py",
                  "chains/kernel.py", "chains/answers.py")


class CacheIOWarning(UserWarning):
    """numba's on-disk cache could not be read or written; the function runs compiled in memory."""


@contextlib.contextmanager
def _tolerate_cache_io_errors(self):
    """numba's cache is an optimisation: a cache directory deleted or unwritable while a function
    compiles (another process cleaning it, a read-only tree) costs the cache, never the run."""
    try:
        yield
    except OSError as error:
        warnings.warn(f"numba cache {getattr(error, 'filename', '') or ''}: {error.strerror or error}; "
                      "compiled in memory only", CacheIOWarning, stacklevel=3)


caching.Cache._guard_against_spurious_io_errors = _tolerate_cache_io_errors   # load and save both go through it


_refreshing_load = caching.Cache.load_overload


def _load_without_refresh(self, sig, target_context):
    """numba's ``Cache.load_overload`` without its ``target_context.refresh()``, on the CPU target.

    The refresh imports and installs every lowering registry numba has (its numpy, random,
    typed containers, and through ``numba.np.linalg`` scipy.linalg): about as much CPU as
    importing numba itself, spent by every process that only loads cached machine code. Loading
    needs only the runtime's symbols (``rtsys.initialize``); a compile still refreshes (numba's
    compiler does it first), and other targets keep numba's own load."""
    if not isinstance(target_context, CPUContext):
        return _refreshing_load(self, sig, target_context)
    rtsys.initialize(target_context)
    with self._guard_against_spurious_io_errors():
        return self._load_overload(sig, target_context)


caching.Cache.load_overload = _load_without_refresh


def kernel_digest() -> str:
    """sha256 over the kernel sources of this package."""
    h = hashlib.sha256()
    here = Path(__file__).parents[1]   # tswm_runtime/
    for name in KERNEL_SOURCES:
        h.update(name.encode() + (here / name).read_bytes())
    return h.hexdigest()


MARKER = "tswm-kernels.sha256"   # in each directory of kernel caches: the digest they were compiled from


def cache_directory(source: Path) -> Path | None:
    """numba's cache directory for the functions defined in ``source``: the first of numba's
    cache locators that accepts the file (NUMBA_CACHE_DIR, else __pycache__ beside it, ...)."""
    for locator_class in caching.CacheImpl._locator_classes:   # numba has no public accessor
        locator = locator_class.from_function(cache_directory, str(source))
        if locator is not None:
            return Path(locator.get_cache_path())
    return None


@functools.lru_cache(maxsize=1)
def check_kernel_caches() -> None:
    """Once per process, before the first kernel compiles: in every directory holding kernel
    caches whose marker is not the kernel digest, delete the caches of every function in the
    kernel sources (a kernel links its callees' cached machine code, and numba would keep a
    callee whose own file did not change but whose callee, in another file, did), then write
    the marker. A directory with the right marker is left alone: compiling a kernel for the
    first time, or under another NUMBA_CACHE_DIR, purges nothing."""
    digest = kernel_digest()
    here = Path(__file__).parents[1]
    directories: dict[Path, list[str]] = {}
    for name in KERNEL_SOURCES:
        directory = cache_directory(here / name)
        if directory is not None:
            directories.setdefault(directory, []).append(Path(name).stem)
    for directory, stems in directories.items():
        marker = directory / MARKER
        if marker.exists() and marker.read_text() == digest:
            continue
        for stem in stems:
            for cached in directory.glob(f"{stem}.*.nb[ic]"):
                with contextlib.suppress(OSError):  # gone already (another process), or read-only
                    cached.unlink()
        with contextlib.suppress(OSError):  # a read-only cache directory: numba compiles in memory anyway
            write_atomic(marker, digest)


class _Helper(CPUDispatcher):
    """A dispatcher for the kernels' helpers (measured: each compile of a helper costs a typing
    and a lowering of it; its code is optimized where it is linked, ``linking``).

    It types the constants it is called with from compiled code as their plain types (int64,
    not Literal[int](3)): numba's own compiles a callee once per literal value, and once more
    for a variable that starts as a constant (typing widens it later). And, unless told
    otherwise, it builds no CPython or C wrapper (``no_cpython_wrapper``, ``no_cfunc_wrapper``:
    a sixth of the cold compile): such a helper is callable from compiled code only, and
    calling it from Python raises TypeError (numba would crash).

    Unless told otherwise (``njit(refcounted=True)``), a helper is compiled without numba's reference
    counting (NRT): its arrays are its callers' (borrowed, ``borrow``), and counting them, at
    every argument, tuple member and variable's end, was a third of the LLVM IR numba printed for
    the segment kernel (docs/first-run.md). ``add_overload`` holds such a helper to what makes that
    safe: it returns no array (its caller would release one it never counted) and takes none
    from a compiled function (one it could never release).
    """

    def add_overload(self, cres):
        if not self.targetoptions["_nrt"] and hasattr(cres.type_annotation, "calltypes"):   # not: loaded from the cache
            _check_uncounted(self.py_func.__qualname__, cres.signature.return_type, cres.type_annotation)
        super().add_overload(cres)

    def get_call_template(self, args, kws):
        return super().get_call_template(tuple(map(types.unliteral, args)),
                                         {k: types.unliteral(v) for k, v in kws.items()})

    def __call__(self, *args, **kws):
        if self.targetoptions["no_cpython_wrapper"]:
            raise TypeError(f"{self.py_func.__qualname__} is a helper of compiled code (cache_guard.njit); "
                            "pass no_cpython_wrapper=False to call it from Python")
        return super().__call__(*args, **kws)


def _holds_arrays(typ) -> bool:
    if isinstance(typ, types.BaseTuple):
        return any(_holds_arrays(member) for member in typ.types)
    return isinstance(typ, types.ArrayCompatible) or (isinstance(typ, types.Optional) and _holds_arrays(typ.type))


def _check_uncounted(name, return_type, annotation) -> None:
    """TypeError unless a helper compiled without reference counting returns no array and
    receives none from a compiled function (numba's own, or another helper)."""
    why = f"returns {return_type}" if _holds_arrays(return_type) else None
    for expr, call in annotation.calltypes.items():
        callee = annotation.typemap[expr.func.name] if getattr(expr, "op", None) == "call" else None
        template = getattr(callee, "template", None) or next(iter(getattr(callee, "templates", ())), None)
        compiled = isinstance(callee, types.Dispatcher) or (
            isinstance(template, type) and issubclass(template, (typing_templates._OverloadFunctionTemplate,
                                                                 typing_templates._OverloadMethodTemplate)))
        if why is None and compiled and _holds_arrays(call.return_type):
            why = f"takes {call.return_type} from {callee} (line {expr.loc.line})"
    if why is not None:
        raise TypeError(f"{name} {why}: a helper that handles arrays it owns needs numba's reference counting, "
                        "cache_guard.njit(refcounted=True)")


def njit(*, cache=False, refcounted=False, **options):
    """``numba.njit(**options)`` with the dispatcher above, for the kernels' helpers; ``options``
    may turn the wrappers back on (no_cfunc_wrapper=False for a first-class function). A helper
    is code for its callers to link (``linking.HelperLibrary``: optimized and compiled to machine
    code in the kernel that calls it, once) and is not cached on its own: it lives in its
    kernels' cache. ``cache=True`` is for a function that is entered by address (a method's
    step): compiled in full on its own and cached. ``refcounted=True`` for a helper that makes
    arrays (np.empty, a copy, an array expression), returns any, or calls a numba.njit function
    that makes them (which compiles with its first caller's setting): compiled with numba's
    reference counting (``_Helper``; without it numba refuses to compile an allocation). The function itself
    while numba's jit is off, as numba.njit does."""
    def decorate(py_func):
        if numba.config.DISABLE_JIT:   # an interpreted run (startup.warmup)
            return py_func
        dispatcher = _Helper(py_func=py_func, locals={},
                             pipeline_class=compiler.Compiler if cache else HelperCompiler,
                             targetoptions={"nopython": True, "boundscheck": None, "no_cpython_wrapper": True,
                                            "no_cfunc_wrapper": True, "_nrt": refcounted, **options})
        if cache:
            dispatcher.enable_caching()
        return dispatcher
    return decorate


def compile_cached(signature, **options):
    """Like ``numba.njit(signature, cache=True, **options)``, with the kernel check above; the
    function itself while numba's jit is off (an interpreted run, startup.warmup)."""
    def decorate(py_func):
        if numba.config.DISABLE_JIT:
            return py_func
        check_kernel_caches()
        dispatcher = numba.njit(cache=True, **options)(py_func)
        dispatcher.compile(signature)
        dispatcher.disable_compile()
        return dispatcher
    return decorate


def entry_point(kernel):
    """The compiled code of a kernel that ``compile_cached`` compiled for exactly one signature.
    Calling it skips the dispatcher, which types every argument on every call to pick the
    overload (about 40 us for the mode machine's arguments when they still held functions, about
    10 us for a chain run's 30-odd record arrays); that is safe only for a caller that builds every
    argument with the signature's exact types (``entry.integrate``, ``simulate``, ``chains.run``).
    The dispatcher itself if there is no single one (or the function, while numba's jit is off)."""
    entry = _ENTRY_POINTS.get(id(kernel))
    if entry is None:
        try:
            (signature,) = kernel.signatures
            entry = kernel.overloads[signature].entry_point
        except (AttributeError, KeyError, ValueError):
            entry = kernel
        _ENTRY_POINTS[id(kernel)] = entry
    return entry


_ENTRY_POINTS: dict = {}
