"""The mode machine called from Python: ``integrate`` builds its arguments from plain values.

``integrate_at`` is ``machine.integrate_hybrid`` with its seven functions (the method's step,
the model's rhs, jac, guards, observe, impact, the step method auto switches to) given as addresses (``jit.addresses``;
``model_functions`` turns them back into the Functions, here and in ``batch.run_batch``):
numba unboxes a function-typed argument through Python, 1-2 us each and several times that
right after other code has run, an address in nanoseconds. The machine itself is called
through its addresses too, so its compiled code is not linked into this small kernel (as
``batch.run_batch`` calls it), and through its numba-ABI one, so that its exceptions (a
MemoryError from its work arrays) reach Python.
"""
import numpy as np
from numba import types

from tswm_runtime.hybrid.machine import HYBRID_SIG, integrate_hybrid
from tswm_runtime.jit import cache_guard
from tswm_runtime.integration import segment
from tswm_runtime.jit.addresses import function_at, guards_at, jac_at, rhs_at
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import GUARDS_SIG, JAC_SIG, RHS_SIG, address, jit_address
from tswm_runtime.jit.structures import (INDEX_WIDTH, JUMP_WIDTH, EventLog, Functions, Outputs, Record, Settings,
                                         Start, StepLog, Tolerances)

_machine_at = function_at(types.FunctionType(HYBRID_SIG), raises=True)
_attempt_at = function_at(segment.AttemptFunction)

#: What ``functions`` gives: nine addresses.
ADDRESSES = types.UniTuple(types.int64, 9)
#: integrate_hybrid's signature with its functions replaced by their addresses.
ENTRY_SIG = HYBRID_SIG.return_type(ADDRESSES, *HYBRID_SIG.args[1:])


@njit(cache=True, error_model="numpy")
def model_functions(functions):
    """The Functions (the method's step, the model's rhs, jac, guards, observe, impact, the
    stiff step) at the last seven of the addresses ``functions``."""
    _, _, attempt, rhs, jac, guards, observe, impact, stiff = functions
    return Functions(_attempt_at(attempt), rhs_at(rhs), jac_at(jac), guards_at(guards), guards_at(observe),
                     guards_at(impact), _attempt_at(stiff))


@cache_guard.compile_cached(ENTRY_SIG, error_model="numpy", nogil=True)
def integrate_at(functions, tables, start, settings, record):
    """``integrate_hybrid`` with its functions at the addresses ``functions`` (see ``functions``)."""
    integrate = _machine_at(functions[0], functions[1])
    return integrate(model_functions(functions), tables, start, settings, record)


def functions(method: int, model) -> tuple:
    """The addresses ``integrate_at`` takes: the mode machine (C wrapper and numba ABI),
    ``method``'s step, the model's rhs, jac, guards, observe and impact (DOPRI5 calls jac
    only to confirm an equilibrium before holding it, ``steady``), and the step method auto
    switches to (``segment.method_steps``). Remembered per method and model functions."""
    key = (method, model.rhs, model.jac, model.guards, model.observe, model.impact)
    known = _FUNCTIONS.get(key)
    if known is None:
        attempt, stiff = segment.method_steps(method)  # compiled, or loaded from the cache, on first use
        known = (address(integrate_hybrid, HYBRID_SIG), jit_address(integrate_hybrid, HYBRID_SIG),
                 getattr(attempt, "address", attempt),  # jit off: the function itself
                 address(model.rhs, RHS_SIG), address(model.jac, JAC_SIG), address(model.guards, GUARDS_SIG),
                 address(model.observe, GUARDS_SIG), address(model.impact, GUARDS_SIG),
                 getattr(stiff, "address", stiff))
        if len(_FUNCTIONS) >= 256:
            _FUNCTIONS.clear()
        _FUNCTIONS[key] = known
    return known


_FUNCTIONS: dict = {}


def _call(kernel, args, counters):
    return kernel(*args)


def step_log(steps: int, segments: int, width: int, n_params: int) -> StepLog:
    """An empty StepLog (``integration.steplog``) for ``steps`` steps and ``segments`` segments of a
    run with ``width`` states and integrals and ``n_params`` parameters (latches included)."""
    return StepLog(np.empty((steps, 4)), np.empty((steps, 2), np.int64), np.empty((steps, width)),
                   np.empty((steps, width)), np.empty((steps, width + 1, 4)), np.empty(segments, np.int64),
                   np.empty((segments, n_params)), np.zeros(2, np.int64))


def integrate(method, model, p, tables, y0, t_end, *, rtol, atol, t_out, max_events, quad=None, t0=0.0,
              mode0=-1, hmin=0.0, hmax=np.inf, max_steps=100_000, steps=(0, 0), call=_call):
    """integrate_hybrid with keyword arguments: builds the structures and work arrays from
    plain values and returns (status, t_stop, n_events, last mode, need, first mode,
    Outputs, EventLog, mon, counters, StepLog). model: the generated module; p is written
    (latches). atol: a number or one per state. steps: the StepLog's capacity (steps, segments);
    its count says how many there were (more than the capacity: the log is incomplete).
    call(kernel, args, counters) runs the kernel (e.g. in a thread, watching counters)."""
    y0 = np.ascontiguousarray(y0, dtype=np.float64)
    quad = np.empty(0) if quad is None else np.ascontiguousarray(quad, dtype=np.float64)
    width = y0.size + quad.size
    t_out = np.ascontiguousarray(t_out, dtype=np.float64)
    out = Outputs(t_out, np.full((t_out.size, width), np.nan), np.full(t_out.size, -1, np.int64),
                  np.empty((t_out.size, p.size)))
    log = EventLog(np.empty(max_events), np.empty((max_events, INDEX_WIDTH), np.int64), np.empty((max_events, width)),
                   np.zeros((max_events, JUMP_WIDTH)))
    mon, counters = np.zeros((len(model.OBSERVABLES), 3)), np.zeros(segment.N_COUNTERS, np.int64)
    atol = (np.full(y0.size, atol, dtype=np.float64) if np.ndim(atol) == 0
            else np.array(np.broadcast_to(np.asarray(atol, np.float64), y0.shape)))
    settings = Settings(method, float(t_end), Tolerances(float(rtol), atol, float(hmin), float(hmax)), int(max_steps))
    step_record = step_log(*steps, width, p.size)
    args = (functions(method, model), tables, Start(float(t0), y0, quad, int(mode0), p), settings,
            Record(out, log, mon, counters, step_record))
    result = call(integrate_at, args, counters)
    return (*result, out, log, mon, counters, step_record)
