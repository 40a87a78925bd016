"""The mode machine's functions from the addresses ``entry.functions`` gives (``jit.addresses``),
for the kernels that take them: ``entry.integrate_at`` and ``batch.run_batch``.

It imports neither the segment kernel (``segments``) nor ``entry``, so that ``batch.run_batch``
compiles without them (``tswm paper`` compiles the segment kernel in its second process meanwhile).
"""
from numba import types

from tswm_runtime.integration import segment
from tswm_runtime.jit.addresses import function_at, guards_at, jac_at, rhs_at
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.structures import Functions

#: What ``entry.functions`` gives: eleven addresses (the mode machine's two, the Functions' seven,
#: the segment kernel's two).
ADDRESSES = types.UniTuple(types.int64, 11)

_attempt_at = function_at(segment.AttemptFunction)
_segment_at = function_at(segment.SegmentFunction, raises=True)


@njit(error_model="numpy")
def model_functions(functions):
    """The Functions (the method's step, the model's rhs, jac, guards, observe, impact, the
    stiff step) at the third to the ninth of the addresses ``functions``."""
    _, _, attempt, rhs, jac, guards, observe, impact, stiff, _, _ = functions
    return Functions(_attempt_at(attempt), rhs_at(rhs), jac_at(jac), guards_at(guards), guards_at(observe),
                     guards_at(impact), _attempt_at(stiff))


@njit(error_model="numpy")
def segment_function(functions):
    """The segment kernel (``segments.run_segment``) at the last two of the addresses ``functions``
    (called through its numba ABI: its MemoryError reaches the caller)."""
    return _segment_at(functions[9], functions[10])
