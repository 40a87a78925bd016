"""Numba signatures of the model contract that the integrators call.

A generated model module compiles its three functions eagerly with exactly these
signatures and ``cache=True``::

    @njit(RHS_SIG, cache=True)
    def rhs(mode, t, y, p, dy): ...       # dy[:] = f_mode(t, y; p)

    @njit(JAC_SIG, cache=True)
    def jac(mode, t, y, p, J, dfdt): ...  # J[i, j] = d f_i / d y_j,  dfdt[i] = d f_i / d t

    @njit(GUARDS_SIG, cache=True)
    def guards(mode, t, y, p, g): ...     # g[k] = k-th event function of `mode`

Arguments: ``mode`` int64 (the discrete mode), ``t`` float64, ``y`` the state
float64[::1] (length n), ``p`` the free-parameter vector float64[::1]; the last
arguments are outputs the function fills in place and nothing is returned.

The integrators take these functions as arguments typed ``RhsFunction``,
``JacFunction`` and ``GuardsFunction`` (numba first-class function types). A
function argument with such an explicit type is an indirect call through a
function pointer, so the integrator is compiled once, cached on disk and reused
for every model; a jitted function passed without a signature would instead be
typed as its own ``Dispatcher`` and force a recompilation per model and process
(numba issue 9237). Measured costs: ``tools/bench_calling_convention.py``.
"""
from numba import config, types
from numba.core.types.function_type import CompileResultWAP

#: A C-contiguous float64 vector: states, parameters, derivatives, guard values.
VECTOR = types.float64[::1]
#: A C-contiguous float64 matrix: the Jacobian.
MATRIX = types.float64[:, ::1]

#: rhs(mode, t, y, p, dy) -> None
RHS_SIG = types.none(types.int64, types.float64, VECTOR, VECTOR, VECTOR)
#: jac(mode, t, y, p, J, dfdt) -> None
JAC_SIG = types.none(types.int64, types.float64, VECTOR, VECTOR, MATRIX, VECTOR)
#: guards(mode, t, y, p, g) -> None
GUARDS_SIG = types.none(types.int64, types.float64, VECTOR, VECTOR, VECTOR)

RhsFunction = types.FunctionType(RHS_SIG)
JacFunction = types.FunctionType(JAC_SIG)
GuardsFunction = types.FunctionType(GUARDS_SIG)


_ADDRESSES: dict = {}


def compiled(function, signature):
    """A jitted function as numba's first-class function value for ``signature``, looked up
    once: passing the dispatcher itself costs ~20 us a call to find its compiled code. Keyed
    by identity (both are long-lived: a module's function, a signature constant): hashing a
    numba signature walks its types, ~10 us a call. While numba's jit is off (an interpreted
    run, startup.warmup) the function itself."""
    if config.DISABLE_JIT:
        return function
    key = (id(function), id(signature))
    if key not in _ADDRESSES:
        _ADDRESSES[key] = (function, signature, CompileResultWAP(function.get_compile_result(signature)))
    return _ADDRESSES[key][2]


def address(function, signature):
    """The address of ``function``'s compiled code for ``signature`` (its C wrapper), for a kernel
    to call through ``addresses.function_at``; the function itself while numba's jit is off."""
    value = compiled(function, signature)
    return value if config.DISABLE_JIT else value.address


def jit_address(function, signature):
    """The address of ``function``'s compiled code for ``signature`` in numba's own calling
    convention, which passes exceptions on (``addresses.function_at(..., raises=True)``); None
    while numba's jit is off."""
    if config.DISABLE_JIT:
        return None
    result = compiled(function, signature).cres
    return result.library.get_pointer_to_function(result.fndesc.llvm_func_name)
