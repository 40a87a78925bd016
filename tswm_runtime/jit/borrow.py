"""Borrowed views: arrays without an owner, so that handing them on costs no reference counting.

numba counts the references to every array: an atomic increment and decrement, a few ns
each. Around a call through a function pointer (the model's rhs, the method's step) the
pairs cannot be pruned, so a step loop that hands its work arrays to such calls spent
about 40 % of its time counting (measured with perf). ``borrowed(x)`` gives ``x`` (an array,
or a tuple or named tuple of arrays and scalars) with every array's owner (meminfo) set
to NULL: counting it is a null test. The views must not outlive what they borrow from, so
a function borrows only its own arguments, which its caller keeps alive for the call.
"""
import numba
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic


def _strip(context, builder, typ, value):
    """``value`` of numba type ``typ`` with the owners of its arrays set to NULL."""
    if isinstance(typ, types.Array):
        view = context.make_array(typ)(context, builder, value=value)
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()
    if isinstance(typ, types.BaseTuple):
        for k, member in enumerate(typ.types):
            value = builder.insert_value(value, _strip(context, builder, member, builder.extract_value(value, k)), k)
        return value
    return value


def _allowed(typ) -> bool:
    if isinstance(typ, types.BaseTuple):
        return all(_allowed(member) for member in typ.types)
    return isinstance(typ, (types.Array, types.Number, types.Boolean, types.NoneType))


if numba.config.DISABLE_JIT:   # an interpreted run (startup.warmup): nothing is counted
    def borrowed(x):
        return x
else:
    @intrinsic
    def borrowed(typingctx, x):
        """``x`` with its arrays' owners dropped (module docstring)."""
        if not _allowed(x):
            raise TypingError(f"borrowed: arrays, numbers and (named) tuples of them only, not {x}")
        return x(x), lambda context, builder, signature, args: _strip(context, builder, x, args[0])
