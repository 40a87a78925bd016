"""One segment of the mode machine, a kernel of its own: the step loop (``segment.run``) and the
Painleve approach (``painleve.approach``), about half of the mode machine's compile.

``machine.integrate_hybrid`` calls ``run_segment`` through its addresses (``jit.addresses``; a
``segment.SegmentFunction`` argument, as it calls the method's step), so its code is not linked
into the machine: the two kernels are compiled and cached apart, and ``tswm paper`` compiles
this one in its second process while the first compiles the machine (docs/first-run.md). This
module imports no part of the machine; its signature is ``segment.SEGMENT_SIG``.
"""
from tswm_runtime.integration import painleve
from tswm_runtime.integration import segment
from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.structures import EventSettings, Segment, Settings, State


@cache_guard.compile_cached(segment.SEGMENT_SIG, error_model="numpy", nogil=True)
def run_segment(fns, settings, seg, state, record, i, scratch):
    """One segment in seg.mode from ``state`` (``segment.run``), handed over to the Painleve
    approach where D (guard seg.ev.singular, -1: no hand-over) heads for 0 or where steps in t
    shrank to nothing near it. Returns (status as segment's (APPROACH: back from the approach,
    on in t), t, guard, next output row, next step, whether the next segment may hand over again)."""
    counters = record.counters
    steps = counters[segment.N_STEPS] + counters[segment.N_REJECTED]
    k_singular = seg.ev.singular
    budget = Settings(settings.method, settings.t_end, settings.tol, max(settings.max_steps - steps, 0))
    seg_status, t_new, k, i, h = segment.run(fns, budget, seg, state, record, i, scratch)
    stalled = seg_status == segment.STEP_TOO_SMALL or seg_status == segment.NOT_FINITE
    if k_singular >= 0 and stalled and counters[segment.N_STEPS] > 0:
        seg_status = segment.APPROACH  # steps in t shrank to nothing: try Sundman's time
    if seg_status != segment.APPROACH:
        return seg_status, t_new, k, i, h, True
    ev = EventSettings(seg.ev.directions, 0.0, 0.0, True, k_singular, False)
    left = max(settings.max_steps - counters[segment.N_STEPS] - counters[segment.N_REJECTED], 0)
    budget = Settings(settings.method, settings.t_end, settings.tol, left)
    outcome, t_new, i = painleve.approach(fns, budget, Segment(seg.mode, seg.p, ev),
                                          State(t_new, state.y, state.quad, h), record, i)
    if outcome == painleve.ZERO:
        return segment.EVENT, t_new, k_singular, i, h, True
    if outcome == painleve.END:
        return segment.REACHED_END, t_new, k, i, h, True
    if outcome == painleve.OTHER or outcome == painleve.CLEAR:
        # go on in t (OTHER: locate that guard there first, without handing over again)
        return segment.APPROACH, t_new, k, i, h, outcome == painleve.CLEAR
    return outcome, t_new, k, i, h, True
