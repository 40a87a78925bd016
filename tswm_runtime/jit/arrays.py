"""Array copies for the kernels, written as loops instead of numba's slice assignment.

``a[:] = b`` with an array ``b`` makes numba compile, for every pair of dimensions it meets,
a function that formats the shape-mismatch message (str, join, f-strings) and link it into
the kernel, whose LLVM optimization then grows with it. Measured on the integration kernels
(``import tswm_runtime.hybrid.entry, tswm_runtime.hybrid.rows`` with an empty cache, numba
0.68.1): 107.6 s of CPU with slice assignments, 56.5 s without the message (load 8.5 and 5.6
on 2 cores); LLVM's time for ``integrate_hybrid`` alone 44.9 s and 15.4 s. Element stores
compile no such function. ``tests/test_compile_cost.py`` keeps slice assignments of arrays
out of the kernel sources.
"""
from tswm_runtime.jit.cache_guard import njit


@njit(error_model="numpy")
def copy_into(dst, src):
    """dst[i] = src[i] for every i of the vector dst (src at least as long, not overlapping it; no
    shape check)."""
    for i in range(dst.size):
        dst[i] = src[i]


@njit(error_model="numpy")
def copy_rows(dst, src):
    """dst[r, i] = src[r, i] for every row r and column i of the matrix dst (as ``copy_into``)."""
    for r in range(dst.shape[0]):
        copy_into(dst[r], src[r])
