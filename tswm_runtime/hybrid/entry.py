"""The mode machine called from Python: ``integrate`` builds its arguments from plain values.

``integrate_at`` is ``machine.integrate_hybrid`` with its seven functions (the method's step,
the model's rhs, jac, guards, observe, impact, the step method auto switches to) and its segment
kernel (``segments.run_segment``) given as addresses (``jit.addresses``; ``addressed`` turns them
back into functions, here and in ``batch.run_batch``):
numba unboxes a function-typed argument through Python, 1-2 us each and several times that
right after other code has run, an address in nanoseconds. The machine itself is called
through its addresses too, so its compiled code is not linked into this small kernel (as
``batch.run_batch`` calls it), and through its numba-ABI one, so that its exceptions (a
MemoryError from its work arrays) reach Python. After the run ``integrate_at`` also writes the
run's summary (``summarize``: the largest |state| and the state where it stopped), so that a
caller reading only those needs no numpy pass over the step log.
"""
import numpy as np
from numba import types

from tswm_runtime.hybrid.addressed import ADDRESSES, model_functions, segment_function
from tswm_runtime.hybrid.machine import HYBRID_SIG, INVALID_INPUT, integrate_hybrid
from tswm_runtime.hybrid.segments import run_segment
from tswm_runtime.jit import cache_guard
from tswm_runtime.integration import segment
from tswm_runtime.jit.addresses import function_at
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import GUARDS_SIG, JAC_SIG, RHS_SIG, VECTOR, address, jit_address
from tswm_runtime.jit.structures import (INDEX_WIDTH, JUMP_WIDTH, EventLog, Outputs, Record, Settings, Start,
                                         StepLog, Tolerances)

_machine_at = function_at(types.FunctionType(HYBRID_SIG), raises=True)
#: integrate_hybrid's signature with its functions replaced by their addresses, and the summary.
ENTRY_SIG = HYBRID_SIG.return_type(ADDRESSES, *HYBRID_SIG.args[2:], VECTOR)


@njit(error_model="numpy")
def summarize(start, record, summary):
    """Fill ``summary`` (size 2 w for w states and integrals; size 0: nothing to fill): [:w] the
    largest |value| of each over the ends of the steps kept, or over the rows written when the run
    wrote rows (NaN propagates; 0 for none), [w:] where the run stopped: the end of its last step
    kept (the left limit at an event), or the start if it took none."""
    steps, out = record.steps, record.out
    w = steps.y_hi.shape[1]
    if summary.size != 2 * w:
        return
    summary[:] = 0.0
    n = min(steps.count[0], steps.f.shape[0])
    rows = out.y if out.t.size else steps.y_hi
    for i in range(out.t.size if out.t.size else n):
        if out.t.size and out.mode[i] < 0:
            continue
        for j in range(w):
            a = abs(rows[i, j])
            if summary[j] == summary[j] and not a <= summary[j]:  # a larger value or NaN; a NaN stays
                summary[j] = a
    if n:
        copy_into(summary[w:], steps.y_hi[n - 1])
    else:
        copy_into(summary[w:w + start.y.size], start.y)
        copy_into(summary[w + start.y.size:], start.quad)


@cache_guard.compile_cached(ENTRY_SIG, error_model="numpy", nogil=True)
def integrate_at(functions, tables, start, settings, record, summary):
    """``integrate_hybrid`` with its functions at the addresses ``functions`` (see ``functions``),
    then, unless its input was invalid, ``summarize`` into ``summary``."""
    integrate = _machine_at(functions[0], functions[1])
    outcome = integrate(model_functions(functions), segment_function(functions), tables, start, settings, record)
    if outcome[0] != INVALID_INPUT:  # the sizes agree
        summarize(start, record, summary)
    return outcome


def functions(method: int, model) -> tuple:
    """The addresses ``integrate_at`` takes: the mode machine (C wrapper and numba ABI),
    ``method``'s step, the model's rhs, jac, guards, observe and impact (DOPRI5 calls jac
    only to confirm an equilibrium before holding it, ``steady``), the step method auto
    switches to (``segment.method_steps``) and the segment kernel (C wrapper and numba ABI).
    Remembered per method and model functions."""
    key = (method, model.rhs, model.jac, model.guards, model.observe, model.impact)
    known = _FUNCTIONS.get(key)
    if known is None:
        attempt, stiff = segment.method_steps(method)  # compiled, or loaded from the cache, on first use
        known = (address(integrate_hybrid, HYBRID_SIG), jit_address(integrate_hybrid, HYBRID_SIG),
                 getattr(attempt, "address", attempt),  # jit off: the function itself
                 address(model.rhs, RHS_SIG), address(model.jac, JAC_SIG), address(model.guards, GUARDS_SIG),
                 address(model.observe, GUARDS_SIG), address(model.impact, GUARDS_SIG),
                 getattr(stiff, "address", stiff),
                 address(run_segment, segment.SEGMENT_SIG), jit_address(run_segment, segment.SEGMENT_SIG))
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


def _outputs(t_out: np.ndarray, width: int, n_params: int) -> Outputs:
    """Outputs at the times t_out; for none, one shared set of empty arrays per shape (nothing is
    written to an array of size 0)."""
    if t_out.size:
        return Outputs(t_out, np.full((t_out.size, width), np.nan), np.full(t_out.size, -1, np.int64),
                       np.empty((t_out.size, n_params)))
    known = _NO_OUTPUTS.get((width, n_params))
    if known is None:
        known = _NO_OUTPUTS[(width, n_params)] = Outputs(t_out, np.empty((0, width)), np.empty(0, np.int64),
                                                          np.empty((0, n_params)))
    return known


_NO_OUTPUTS: dict = {}


def _settings(method: int, n: int, *, t_end, rtol, atol, hmin, hmax, max_steps) -> Settings:
    """The Settings of a run of n states (atol: a number or one per state); for a number remembered
    per value (the kernel never writes them; building them cost ~4 us a call)."""
    if not isinstance(atol, (float, int)):
        atol = np.array(np.broadcast_to(np.asarray(atol, np.float64), (n,)))
        return Settings(method, float(t_end), Tolerances(float(rtol), atol, float(hmin), float(hmax)), int(max_steps))
    key = (method, n, t_end, rtol, atol, hmin, hmax, max_steps)
    known = _SETTINGS.get(key)
    if known is None:
        atol = np.full(n, atol, dtype=np.float64)
        known = Settings(method, float(t_end), Tolerances(float(rtol), atol, float(hmin), float(hmax)), int(max_steps))
        if len(_SETTINGS) >= 256:
            _SETTINGS.clear()
        _SETTINGS[key] = known
    return known


_SETTINGS: dict = {}


def integrate(method, model, p, tables, y0, t_end, *, rtol, atol, t_out, max_events, quad=None, t0=0.0,
              mode0=-1, hmin=0.0, hmax=np.inf, max_steps=100_000, steps=(0, 0), summary=None, call=_call):
    """integrate_hybrid with keyword arguments: builds the structures and work arrays from
    plain values and returns (status, t_stop, n_events, last mode, need, first mode,
    Outputs, EventLog, mon, counters, StepLog). model: the generated module; p is written
    (latches). atol: a number or one per state. steps: the StepLog's capacity (steps, segments);
    its count says how many there were (more than the capacity: the log is incomplete).
    summary: None, or an array of 2 x (states and integrals) that the run fills (``summarize``).
    call(kernel, args, counters) runs the kernel (e.g. in a thread, watching counters)."""
    y0 = np.ascontiguousarray(y0, dtype=np.float64)
    quad = _NO_VALUES if quad is None else np.ascontiguousarray(quad, dtype=np.float64)
    width = y0.size + quad.size
    out = _outputs(np.ascontiguousarray(t_out, dtype=np.float64), width, p.size)
    log = EventLog(np.empty(max_events), np.empty((max_events, INDEX_WIDTH), np.int64), np.empty((max_events, width)),
                   np.zeros((max_events, JUMP_WIDTH)))
    mon, counters = np.zeros((len(model.OBSERVABLES), 3)), np.zeros(segment.N_COUNTERS, np.int64)
    settings = _settings(method, y0.size, t_end=t_end, rtol=rtol, atol=atol, hmin=hmin, hmax=hmax, max_steps=max_steps)
    step_record = step_log(*steps, width, p.size)
    args = (functions(method, model), tables, Start(float(t0), y0, quad, int(mode0), p), settings,
            Record(out, log, mon, counters, step_record), _NO_VALUES if summary is None else summary)
    result = call(integrate_at, args, counters)
    return (*result, out, log, mon, counters, step_record)


_NO_VALUES = np.empty(0)
