"""Compiled functions handed to a kernel as plain addresses.

numba unboxes a function-typed argument (``signatures.RhsFunction``, ...) by calling back
into its typing machinery from Python, twice per argument: 1-2 us each, several times that
right after other code has run (issue 13). The mode machine takes seven such arguments. An
int64 unboxes in nanoseconds. ``signatures.address`` gives the address of a function's
compiled C wrapper (what numba calls through a first-class function value made from a
compile result); ``function_at(fn_type)`` makes an intrinsic that turns such an address back
into a value of ``fn_type`` inside a kernel. The caller vouches that the address belongs to a
function compiled for exactly that signature and that the function outlives the call (a
model module's function, a kernel).
"""
import numba
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from tswm_runtime.integration.signatures import GuardsFunction, JacFunction, RhsFunction


def function_at(fn_type: types.FunctionType):
    """An intrinsic ``at(address) -> fn_type``: the compiled function at an int64 address. While
    numba's jit is off (an interpreted run) addresses are the functions themselves: the identity."""
    if numba.config.DISABLE_JIT:
        return lambda function: function

    @intrinsic
    def at(typingctx, address):
        if not isinstance(address, types.Integer):
            raise TypingError(f"function_at: an integer address, not {address}")

        def codegen(context, builder, signature, args):
            value = cgutils.create_struct_proxy(fn_type)(context, builder)
            pointer = context.get_value_type(types.voidptr)
            value.c_addr = builder.inttoptr(args[0], pointer)
            value.py_addr = cgutils.get_null_value(pointer)
            value.jit_addr = cgutils.get_null_value(pointer)  # null: calls go through c_addr
            return value._getvalue()

        return fn_type(address), codegen

    return at


rhs_at = function_at(RhsFunction)
jac_at = function_at(JacFunction)
guards_at = function_at(GuardsFunction)
