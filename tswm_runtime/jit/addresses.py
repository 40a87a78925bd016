"""Compiled functions handed to a kernel as plain addresses.

numba unboxes a function-typed argument (``signatures.RhsFunction``, ...) by calling back
into its typing machinery from Python, twice per argument: 1-2 us each, several times that
right after other code has run (measured). The mode machine takes seven such arguments. An
int64 unboxes in nanoseconds. ``signatures.address`` gives the address of a function's
compiled C wrapper (what numba calls through a first-class function value made from a
compile result); ``function_at(fn_type)`` makes an intrinsic that turns such an address back
into a value of ``fn_type`` inside a kernel. The C wrapper cannot pass an exception on: it
prints it and returns zeros. A callee that can raise (the mode machine: a MemoryError from
its work arrays) is therefore also given its numba-ABI address (``signatures.jit_address``;
``function_at(fn_type, raises=True)`` takes both), through which numba's own calls pass
exceptions on. The caller vouches that the addresses belong to a function compiled for exactly
that signature and that the function outlives the call: ``signatures.compiled`` keeps every
function it was asked for.
"""
import numba
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from tswm_runtime.jit.signatures import GuardsFunction, JacFunction, RhsFunction


def function_at(fn_type: types.FunctionType, raises: bool = False):
    """An intrinsic ``at(address) -> fn_type``: the compiled function at an int64 address (its C
    wrapper); with ``raises``, ``at(address, jit_address)``, called through the numba-ABI address
    so that its exceptions reach the caller. While numba's jit is off (an interpreted run)
    addresses are the functions themselves: the identity."""
    if numba.config.DISABLE_JIT:
        return lambda function, jit_address=None: function

    def codegen(context, builder, signature, args):
        value = cgutils.create_struct_proxy(fn_type)(context, builder)
        pointer = context.get_value_type(types.voidptr)
        value.c_addr = builder.inttoptr(args[0], pointer)
        value.py_addr = cgutils.get_null_value(pointer)
        # numba calls through jit_addr when it is not null, else through c_addr
        value.jit_addr = builder.inttoptr(args[1], pointer) if raises else cgutils.get_null_value(pointer)
        return value._getvalue()

    def check(*addresses):
        for address in addresses:
            if not isinstance(address, types.Integer):
                raise TypingError(f"function_at: an integer address, not {address}")

    if raises:
        @intrinsic
        def at_raising(typingctx, address, jit_address):
            check(address, jit_address)
            return fn_type(address, jit_address), codegen

        return at_raising

    @intrinsic
    def at(typingctx, address):
        check(address)
        return fn_type(address), codegen

    return at


rhs_at = function_at(RhsFunction)
jac_at = function_at(JacFunction)
guards_at = function_at(GuardsFunction)
