"""Compiled functions handed to a kernel as addresses (tswm_runtime.integration.addresses)."""
import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from tswm_runtime.integration.addresses import guards_at
from tswm_runtime.integration.signatures import GUARDS_SIG, address


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
