"""Compiled functions handed to a kernel as addresses (tswm_runtime.jit.addresses)."""
import numpy as np
import pytest
from numba import njit, types
from numba.core.errors import TypingError

from tswm_runtime.jit.addresses import function_at, guards_at
from tswm_runtime.jit.signatures import GUARDS_SIG, address, jit_address

HALF_SIG = types.float64(types.float64)


@njit(GUARDS_SIG)
def _fill(mode, t, y, p, g):
    g[0] = mode + t * y[0] + p[0]
    g[1] = -1.0


@njit
def _call_at(where, y, p, g):
    guards_at(where)(2, 3.0, y, p, g)


def test_a_function_called_at_its_address_computes_what_the_function_computes():
    g = np.zeros(2)
    _call_at(address(_fill, GUARDS_SIG), np.array([4.0]), np.array([5.0]), g)
    assert list(g) == [2 + 3.0 * 4.0 + 5.0, -1.0]


def test_an_address_that_is_no_integer_is_a_typing_error_naming_function_at():
    @njit
    def wrong(where):
        return guards_at(where)

    with pytest.raises(TypingError, match="function_at: an integer address, not float64"):
        wrong(1.5)


@njit(HALF_SIG)
def _half(x):
    if x < 0.0:
        raise ValueError("x < 0")
    return 0.5 * x


_half_at = function_at(types.FunctionType(HALF_SIG), raises=True)


@njit
def _call_half(where, where_jit, x):
    return _half_at(where, where_jit)(x)


def test_a_function_given_its_numba_address_passes_its_exception_on():
    """The C wrapper alone would print the error and return 0.0: no silent result."""
    where, where_jit = address(_half, HALF_SIG), jit_address(_half, HALF_SIG)
    assert _call_half(where, where_jit, 3.0) == 1.5
    with pytest.raises(ValueError, match="x < 0"):
        _call_half(where, where_jit, -1.0)
