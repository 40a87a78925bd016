"""Borrowed views (tswm_runtime.jit.borrow): the same memory, without an owner."""
from collections import namedtuple

import numpy as np
import pytest
from numba import njit, types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from tswm_runtime.jit.borrow import borrowed

Pair = namedtuple("Pair", "scale values")


@intrinsic
def _has_owner(typingctx, array):
    """True if the array's meminfo (what numba counts references on) is not NULL."""
    def codegen(context, builder, signature, args):
        view = context.make_array(array)(context, builder, value=args[0])
        return builder.not_(cgutils.is_null(builder, view.meminfo))
    return types.boolean(array), codegen


@njit
def _write_through(a, pair):
    b, p = borrowed((a, pair))
    b[0] = 1.0
    p.values[1] = p.scale * b[0]
    return b.sum() + p.values.sum(), _has_owner(a), _has_owner(b), _has_owner(p.values), _has_owner(b[1:])


def test_a_borrowed_view_has_no_owner_and_writes_to_the_borrowed_memory():
    a, values = np.zeros(3), np.zeros(2)
    total, a_owned, b_owned, values_owned, slice_owned = _write_through(a, Pair(5.0, values))
    assert a[0] == 1.0 and values[1] == 5.0 and total == 6.0
    assert a_owned and not (b_owned or values_owned or slice_owned)


@njit
def _borrow_a_list(x):
    return borrowed(x)


def test_only_arrays_numbers_and_tuples_of_them_are_borrowed():
    with pytest.raises(TypingError, match="borrowed: arrays, numbers"):
        _borrow_a_list([1.0, 2.0])
