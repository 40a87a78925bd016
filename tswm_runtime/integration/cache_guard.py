"""Eager, cached compilation that notices edits in the kernel modules it inlines.

numba keys a function's on-disk cache on its own source file only (dependencies are
not tracked, as numba's caching docs say), while the compiled integrators inline
dopri5, rosenbrock, events and segment. ``compile_cached`` stores a sha256 over all
kernel sources beside the function's cache and flushes that cache when it differs,
so an edited kernel can never run as stale machine code.
"""
from __future__ import annotations

import contextlib
import hashlib
import warnings
from pathlib import Path

from numba import njit
from numba.core import caching

from tswm_runtime.common.files import write_atomic

KERNEL_SOURCES = ("integration/structures.py", "integration/control.py", "integration/dopri5.py",
                  "integration/rosenbrock.py", "integration/events.py", "integration/segment.py",
                  "integration/painleve.py", "integration/steady.py", "hybrid/machine.py", "hybrid/batch.py", "hybrid/rows.py")


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


def kernel_digest() -> str:
    """sha256 over the kernel sources of this package."""
    h = hashlib.sha256()
    here = Path(__file__).parents[1]   # tswm_runtime/
    for name in KERNEL_SOURCES:
        h.update(name.encode() + (here / name).read_bytes())
    return h.hexdigest()


def _purge_kernel_caches() -> None:
    """Delete numba's cache files of every function in the kernel sources: a kernel links its
    callees' cached machine code, and numba would keep a callee whose own file did not change
    but whose callee (in another file) did."""
    here = Path(__file__).parents[1]
    for name in KERNEL_SOURCES:
        source = here / name
        for cached in (source.parent / "__pycache__").glob(f"{source.stem}.*.nb[ic]"):
            try:
                cached.unlink()
            except OSError:  # gone already (another process), or read-only: numba recompiles anyway
                pass


def compile_cached(signature, **options):
    """Like ``njit(signature, cache=True, **options)``, with the kernel check above."""
    def decorate(py_func):
        dispatcher = njit(cache=True, **options)(py_func)
        cache = dispatcher._cache  # numba has no public accessor; cache_path and flush() are public
        marker = Path(cache.cache_path) / f"{py_func.__module__}.{py_func.__qualname__}.kernel-sha256"
        digest = kernel_digest()
        known = marker.read_text() if marker.exists() else ""
        if known != digest:
            cache.flush()
            _purge_kernel_caches()
            try:
                write_atomic(marker, digest)
            except OSError:  # a read-only cache directory: numba then compiles in memory anyway
                pass
        dispatcher.compile(signature)
        dispatcher.disable_compile()
        return dispatcher
    return decorate
