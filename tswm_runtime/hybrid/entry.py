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

A run's arrays (the Outputs, EventLog, maxima, counters, StepLog and the summary) are views of
two blocks, one of floats and one of integers (``block_sizes``, ``record_views``): Python
allocates two arrays instead of fifteen (about 0.6 us each) and the kernel unboxes two;
``RunArrays`` builds the views in Python only when something reads them. The counters and the
step log's count lead the integer block, the summary and the maxima the float block, so a
caller reads them with one slice each (``HEAD``).
"""
from collections import namedtuple
from functools import cached_property

import numpy as np
from numba import types

from tswm_runtime.common.memo import remember, remembered
from tswm_runtime.hybrid.addressed import ADDRESSES, model_functions, segment_function
from tswm_runtime.hybrid.machine import HYBRID_SIG, INVALID_INPUT, integrate_hybrid
from tswm_runtime.jit import cache_guard
from tswm_runtime.integration import segment
from tswm_runtime.jit.addresses import function_at
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import GUARDS_SIG, JAC_SIG, RHS_SIG, VECTOR, address, jit_address
from tswm_runtime.jit.structures import (INDEX_WIDTH, INTS, JUMP_WIDTH, MODE_TABLES, SETTINGS, START, EventLog,
                                         Outputs, Record, Settings, Start, StepLog, Tolerances)

#: The sizes of a run's arrays: the width of a state row (states and their integral), the
#: parameters (latches included), the observables (rows of the maxima), the step log's steps and
#: segments, the event log's events.
Sizes = namedtuple("Sizes", "width params observables steps segments events")
SIZES = types.NamedUniTuple(types.int64, 6, Sizes)
#: The integer block starts with the counters (``segment.N_COUNTERS``) and the step log's count
#: (steps, segments); the float block with the summary (2 x width) and the maxima (observables x 3).
N_COUNTERS = segment.N_COUNTERS

_machine_at = function_at(types.FunctionType(HYBRID_SIG), raises=True)
#: integrate_hybrid's signature with its functions replaced by their addresses, its Record by the
#: output times, the Sizes and the two blocks.
ENTRY_SIG = HYBRID_SIG.return_type(ADDRESSES, MODE_TABLES, START, SETTINGS, VECTOR, SIZES, VECTOR, INTS)


@njit(error_model="numpy")
def block_sizes(sizes, points):
    """(floats, integers) in the two blocks of a run of ``sizes`` (Sizes) writing ``points`` rows."""
    w, n_p, n_obs, n_steps, n_seg, n_ev = sizes
    floats = (2 * w + 3 * n_obs + n_steps * (4 + 2 * w + 4 * (w + 1)) + n_seg * n_p
              + n_ev * (1 + w + JUMP_WIDTH) + points * (w + n_p))
    return floats, N_COUNTERS + 2 + 2 * n_steps + n_seg + INDEX_WIDTH * n_ev + points


@njit(error_model="numpy", refcounted=True)
def record_views(floats, ints, t_out, sizes):
    """(summary, Record) as views of the blocks ``floats`` and ``ints`` (``block_sizes``); the
    Outputs at the times ``t_out``. Compiled in ``integrate_at``, run as Python by ``RunArrays``."""
    w, n_p, n_obs, n_steps, n_seg, n_ev = sizes
    n_out = t_out.size
    at = 2 * w + 3 * n_obs
    summary, mon = floats[:2 * w], floats[2 * w:at].reshape((n_obs, 3))
    f = floats[at:at + 4 * n_steps].reshape((n_steps, 4))
    at += 4 * n_steps
    y_a = floats[at:at + n_steps * w].reshape((n_steps, w))
    at += n_steps * w
    y_hi = floats[at:at + n_steps * w].reshape((n_steps, w))
    at += n_steps * w
    q = floats[at:at + n_steps * (w + 1) * 4].reshape((n_steps, w + 1, 4))
    at += n_steps * (w + 1) * 4
    seg_p = floats[at:at + n_seg * n_p].reshape((n_seg, n_p))
    at += n_seg * n_p
    log_t = floats[at:at + n_ev]
    at += n_ev
    log_state = floats[at:at + n_ev * w].reshape((n_ev, w))
    at += n_ev * w
    log_jump = floats[at:at + n_ev * JUMP_WIDTH].reshape((n_ev, JUMP_WIDTH))
    at += n_ev * JUMP_WIDTH
    out_y = floats[at:at + n_out * w].reshape((n_out, w))
    at += n_out * w
    out_p = floats[at:at + n_out * n_p].reshape((n_out, n_p))
    at = N_COUNTERS + 2
    counters, count = ints[:N_COUNTERS], ints[N_COUNTERS:at]
    index = ints[at:at + 2 * n_steps].reshape((n_steps, 2))
    at += 2 * n_steps
    seg_mode = ints[at:at + n_seg]
    at += n_seg
    log_index = ints[at:at + INDEX_WIDTH * n_ev].reshape((n_ev, INDEX_WIDTH))
    at += INDEX_WIDTH * n_ev
    out_mode = ints[at:at + n_out]
    steps = StepLog(f, index, y_a, y_hi, q, seg_mode, seg_p, count)
    return summary, Record(Outputs(t_out, out_y, out_mode, out_p), EventLog(log_t, log_index, log_state, log_jump),
                           mon, counters, steps)


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
def integrate_at(functions, tables, start, settings, t_out, sizes, floats, ints):
    """``integrate_hybrid`` with its functions at the addresses ``functions`` (see ``functions``)
    and its Record in the blocks ``floats`` and ``ints`` (``record_views``: the maxima and counters
    zeroed, the output rows NaN), then, unless its input was invalid, ``summarize``."""
    summary, record = record_views(floats, ints, t_out, sizes)
    record.mon[:] = 0.0
    record.counters[:] = 0
    record.out.y[:] = np.nan
    integrate = _machine_at(functions[0], functions[1])
    outcome = integrate(model_functions(functions), segment_function(functions), tables, start, settings, record)
    if outcome[0] != INVALID_INPUT:  # the sizes agree
        summarize(start, record, summary)
    return outcome


class RunArrays:
    """A run's two blocks; its arrays (``record_views``) as views, built on first access."""

    def __init__(self, floats: np.ndarray, ints: np.ndarray, t_out: np.ndarray, sizes: Sizes):
        self.floats, self.ints, self.t_out, self.sizes = floats, ints, t_out, sizes

    @cached_property
    def views(self) -> tuple:
        """(summary, Record)."""
        return getattr(record_views, "py_func", record_views)(self.floats, self.ints, self.t_out, self.sizes)

    @property
    def record(self) -> Record:
        return self.views[1]


def functions(method: int, model) -> tuple:
    """The addresses ``integrate_at`` takes: the mode machine (C wrapper and numba ABI),
    ``method``'s step, the model's rhs, jac, guards, observe and impact (DOPRI5 calls jac
    only to confirm an equilibrium before holding it, ``steady``), the step method auto
    switches to (``segment.method_steps``) and the segment kernel (C wrapper and numba ABI).
    Remembered per method and model functions."""
    key = (method, model.rhs, model.jac, model.guards, model.observe, model.impact)
    known = _FUNCTIONS.get(key)
    if known is None:
        # imported here, not with this module: integrate_at compiles without the segment kernel (``tswm
        # paper`` compiles the two in its two processes at once)
        from tswm_runtime.hybrid.segments import run_segment

        attempt, stiff = segment.method_steps(method)  # compiled, or loaded from the cache, on first use
        known = (address(integrate_hybrid, HYBRID_SIG), jit_address(integrate_hybrid, HYBRID_SIG),
                 getattr(attempt, "address", attempt),  # jit off: the function itself
                 address(model.rhs, RHS_SIG), address(model.jac, JAC_SIG), address(model.guards, GUARDS_SIG),
                 address(model.observe, GUARDS_SIG), address(model.impact, GUARDS_SIG),
                 getattr(stiff, "address", stiff),
                 address(run_segment, segment.SEGMENT_SIG), jit_address(run_segment, segment.SEGMENT_SIG))
        remember(_FUNCTIONS, key, known)
    return known


_FUNCTIONS: dict = {}


def _call(kernel, args, counters):
    return kernel(*args)


def settings(method: int, n: int, *, t_end, rtol, atol, hmin=0.0, hmax=np.inf, max_steps=100_000) -> Settings:
    """The Settings of a run of n states (atol: a number or one per state); for a number remembered
    per value (the kernel never writes them; building them cost ~4 us a call)."""
    if not isinstance(atol, (float, int)):
        atol = np.array(np.broadcast_to(np.asarray(atol, np.float64), (n,)))
        return Settings(method, float(t_end), Tolerances(float(rtol), atol, float(hmin), float(hmax)), int(max_steps))
    return remembered(_SETTINGS, (method, n, t_end, rtol, atol, hmin, hmax, max_steps), lambda: Settings(
        method, float(t_end), Tolerances(float(rtol), np.full(n, atol, dtype=np.float64), float(hmin), float(hmax)),
        int(max_steps)))


_SETTINGS: dict = {}


def run(method: int, model, tables, start: Start, run_settings: Settings, t_out: np.ndarray, sizes: Sizes,
        call=_call) -> tuple:
    """``integrate_at`` on new blocks for ``sizes``: (its outcome, RunArrays). ``start.p`` is
    written (latches); ``t_out``: float64, contiguous. call(kernel, args, ints) runs the kernel
    (e.g. in a thread, watching the counters at the head of ints)."""
    n_floats, n_ints = _block_sizes(sizes, t_out.size)
    floats, ints = np.empty(n_floats), np.empty(n_ints, np.int64)
    outcome = call(integrate_at, (functions(method, model), tables, start, run_settings, t_out, sizes, floats, ints),
                   ints)
    return outcome, RunArrays(floats, ints, t_out, sizes)


def _block_sizes(sizes: Sizes, points: int) -> tuple[int, int]:
    """``block_sizes``, remembered per sizes and points."""
    return remembered(_BLOCK_SIZES, (sizes, points),
                      lambda: getattr(block_sizes, "py_func", block_sizes)(sizes, points))


_BLOCK_SIZES: dict = {}


def integrate(method, model, p, tables, y0, t_end, *, rtol, atol, t_out, max_events, quad=None, t0=0.0,
              mode0=-1, hmin=0.0, hmax=np.inf, max_steps=100_000, steps=(0, 0)):
    """integrate_hybrid with keyword arguments (``run``): returns (status, t_stop, n_events, last
    mode, need, first mode, Outputs, EventLog, mon, counters, StepLog). model: the generated module;
    p is written (latches). atol: a number or one per state. steps: the StepLog's capacity (steps,
    segments); its count says how many there were (more than the capacity: the log is incomplete)."""
    y0 = np.ascontiguousarray(y0, dtype=np.float64)
    quad = _NO_VALUES if quad is None else np.ascontiguousarray(quad, dtype=np.float64)
    run_settings = settings(method, y0.size, t_end=t_end, rtol=rtol, atol=atol, hmin=hmin, hmax=hmax,
                            max_steps=max_steps)
    sizes = Sizes(y0.size + quad.size, p.size, len(model.OBSERVABLES), *steps, max_events)
    outcome, arrays = run(method, model, tables, Start(float(t0), y0, quad, int(mode0), p), run_settings,
                          np.ascontiguousarray(t_out, dtype=np.float64), sizes)
    return (*outcome, *arrays.record)


_NO_VALUES = np.empty(0)
