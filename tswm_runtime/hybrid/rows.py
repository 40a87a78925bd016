"""The quantities of every output row in one numba pass.

``fill_rows`` evaluates the module's ``outputs`` (a1, S1, S2, F1, F2) at each output row
with the row's own mode and parameter vector (the latches in force there), compiled once
with an explicit signature like the integrators and cached; calling the model's
functions row by row from Python cost about 3 us a row.
"""
import numpy as np

from tswm_runtime.integration import cache_guard
from tswm_runtime.integration.borrow import borrowed
from tswm_runtime.integration.signatures import MATRIX, VECTOR, GuardsFunction
from numba import types

ROWS_SIG = types.none(GuardsFunction, VECTOR, MATRIX, types.int64[::1], MATRIX, types.int64, MATRIX)


@cache_guard.compile_cached(ROWS_SIG, error_model="numpy", nogil=True)
def fill_rows(outputs, t, y, mode, p, n_states, out):
    """out[r] = outputs(mode[r], t[r], y[r, :n_states], p[r]) for every row r."""
    t, y, mode, p, out = borrowed((t, y, mode, p, out))  # the row views cost no reference counting
    state = np.empty(n_states)
    for r in range(t.size):
        state[:] = y[r, :n_states]
        outputs(mode[r], t[r], state, p[r], out[r])
