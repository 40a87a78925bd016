"""The quantities of every output row in one numba pass.

``fill_rows`` evaluates the module's ``outputs`` (a1, S1, S2, F1, F2) at each output row
with the row's own mode and parameter vector (the latches in force there), compiled once
with an explicit signature like the integrators and cached; calling the model's
functions row by row from Python cost about 3 us a row. ``outputs`` comes as its address
(``jit.addresses``): unboxing a function-typed argument goes through Python.
"""
import numpy as np

from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.addresses import guards_at
from tswm_runtime.jit.borrow import borrowed
from tswm_runtime.jit.signatures import MATRIX, VECTOR
from numba import types

ROWS_SIG = types.none(types.int64, VECTOR, MATRIX, types.int64[::1], MATRIX, types.int64, MATRIX)


@cache_guard.compile_cached(ROWS_SIG, error_model="numpy", nogil=True)
def fill_rows(outputs, t, y, mode, p, n_states, out):
    """out[:, r] = outputs(mode[r], t[r], y[r, :n_states], p[r]) for every row r: one quantity
    per row of ``out``, so that each is a contiguous array without a copy. ``outputs``: the
    address of the model's outputs (``signatures.address(module.outputs, GUARDS_SIG)``)."""
    outputs = guards_at(outputs)
    t, y, mode, p, out = borrowed((t, y, mode, p, out))  # the row views cost no reference counting
    state, values = np.empty(n_states), np.empty(out.shape[0])
    for r in range(t.size):
        copy_into(state, y[r, :n_states])
        outputs(mode[r], t[r], state, p[r], values)
        for k in range(values.size):
            out[k, r] = values[k]
