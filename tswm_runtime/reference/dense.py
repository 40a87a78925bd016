"""The paper gear's state at many times: events from ``quadrature``, DOP853 between them.

The quadrature reference gives each phase (mode, load, start and end time, start speed) to
about 25 digits but costs a Newton inversion per sample; between its events the motion is
smooth, so scipy's DOP853 at rtol 1e-13 on the hand-written force balance of ``paper_gear``
(v1' = a1, x1' = v1), restarted at each of the quadrature's events from its speed there,
samples it densely. ``check`` compares the two at a few times, so a caller can state how
far the reference itself is from the quadrature. Imports nothing of tswm outside this room.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from tswm_runtime.reference import paper_gear as gear
from tswm_runtime.reference import quadrature as q

DOP853 = dict(method="DOP853", rtol=1e-13, atol=1e-16, dense_output=True)
SENSITIVITY_STEP = 1e-7  # relative step of the one-sided difference dS/dv1


def _flank_direction(mode):
    """(flank +1 a / -1 b, direction +1 fwd / -1 bwd) of a sliding mode name such as 'fwd_a'."""
    return (1 if mode.endswith("_a") else -1), (1 if mode.startswith("fwd") else -1)


class PaperGear:
    """The paper gear (mass m2) from rest or speed v0 under a load schedule [(t_k, F2_k)]
    (``quadrature.solve``'s), up to t_end: ``sample(t)`` gives v1, x1, S1, S2 at sorted times t."""

    def __init__(self, m2, schedule, v0, t_end):
        self.m2 = m2
        self.trajectory = q.solve(q.paper_wedge(m2), schedule, v0, t_end)
        if self.trajectory.status != "finished":
            raise ValueError(f"the reference stops early: {self.trajectory.status} at {self.trajectory.t_stop}")
        self.events = [float(e.t) for e in self.trajectory.events]
        self.pieces, x = [], 0.0
        for ph in self.trajectory.phases:
            t_a, t_b, v_a = float(ph.t_start), float(ph.t_end), float(ph.v_start)
            sol = None
            if ph.mode != "stick" and t_b > t_a:
                f, s = _flank_direction(ph.mode)
                F2 = float(ph.F2)
                sol = solve_ivp(lambda _t, y: [gear.accel(y[0], f, F2, m2, direction=s), y[0]],
                                (t_a, t_b), [v_a, x], **DOP853)
                if sol.status != 0:
                    raise RuntimeError(f"DOP853 failed in {ph.mode} from {t_a}: {sol.message}")
                x = float(sol.y[1, -1])
            self.pieces.append((ph, t_a, t_b, sol, x if sol is None else None))

    def sample(self, t):
        """{'v1', 'x1', 'S1', 'S2', 'dS1/dv1', 'dS2/dv1'}: arrays at the sorted times t (each time from the
        phase it ends or lies in); dSk/dv1 is the reactions' sensitivity to v1 (0 in stick)."""
        t = np.asarray(t, dtype=float)
        out = {k: np.full(t.size, np.nan) for k in ("v1", "x1", "S1", "S2", "dS1/dv1", "dS2/dv1")}
        lo = 0
        for ph, t_a, t_b, sol, x_rest in self.pieces:
            hi = np.searchsorted(t, t_b, side="right")
            idx = np.arange(lo, hi)
            lo = hi
            if idx.size == 0:
                continue
            F2 = float(ph.F2)
            if sol is None:  # stick: at rest, the reactions from statics
                out["v1"][idx], out["x1"][idx] = 0.0, x_rest
                out["S1"][idx], out["S2"][idx] = gear.kloss(0.0), F2
                out["dS1/dv1"][idx], out["dS2/dv1"][idx] = 0.0, 0.0
                continue
            v, x = sol.sol(t[idx])
            out["v1"][idx], out["x1"][idx] = v, x
            f, s = _flank_direction(ph.mode)
            S = np.array([gear.reactions(vi, f, F2, self.m2, direction=s) for vi in v])
            dv = SENSITIVITY_STEP * np.maximum(1.0, np.abs(v)) * s  # away from v1 = 0, where rho has a kink
            dS = np.array([gear.reactions(vi, f, F2, self.m2, direction=s) for vi in v + dv]) - S
            out["S1"][idx], out["S2"][idx] = S[:, 0], S[:, 1]
            out["dS1/dv1"][idx], out["dS2/dv1"][idx] = dS[:, 0] / dv, dS[:, 1] / dv
        return out

    def check(self, n=7):
        """Largest |v1_dense - v1_quadrature| / max|v1| over n times in each sliding phase."""
        worst, scale = 0.0, 0.0
        for ph, t_a, t_b, sol, _ in self.pieces:
            if sol is None:
                continue
            for t in np.linspace(t_a, t_b, n + 2)[1:-1]:
                v = float(self.trajectory.v_at(t))
                scale = max(scale, abs(v))
                worst = max(worst, abs(float(sol.sol(t)[0]) - v))
        return worst / scale if scale else 0.0


QUANTITIES = ("x1", "v1", "S1", "S2")
FIRST_STEPS = 5e-3  # s after a segment boundary (t0, an event) whose samples count as "first steps"
AT_EVENT = 1e-9  # s: margin about an event time within which S1, S2 are left out (see worst_ratios)


def worst_ratios(result, reference, rtol):
    """Worst sample error of a run, per quantity and kind of sample, in units of the tolerance.

    Measure: |y(t_i) - y_ref(t_i)| / (rtol * Y): the error of the row at t_i relative to the state's
    scale Y = max_t |y_ref| over the run, divided by rtol. S1 and S2 are functions of v1 whose slope
    grows without bound as v1 -> 0 (rho ~ |v1|^0.535), so their scale is Y_S + |dS/dv1(t_i)| Y_v1:
    what a v1 error at the tolerance makes of them (the ratio is then about v1's near v1 = 0).
    ``result``: any object with t, x1, v1, S1, S2 and events (each with t), such as a ``Result``;
    ``reference``: a ``PaperGear``. Returns
    {(quantity, kind): ratio} with kind 'ordinary' or 'first' (within FIRST_STEPS after t0 or any of
    the reference's events). S1 and S2 jump at events: samples between the run's and the reference's
    time of an event (widened by AT_EVENT) are left out of them, their error is the event time's."""
    t = np.asarray(result.t, dtype=float)
    ref = reference.sample(t)
    boundaries = np.array([t[0], *reference.events])
    since = t[:, None] - boundaries[None, :]
    first = np.any((since >= 0.0) & (since < FIRST_STEPS), axis=1)
    run_events = [e.t for e in result.events]
    if len(run_events) != len(reference.events):
        raise ValueError(f"events differ: run {run_events}, reference {reference.events}")
    near_event = np.zeros(t.size, dtype=bool)
    for t_run, t_ref in zip(run_events, reference.events):
        near_event |= (t >= min(t_run, t_ref) - AT_EVENT) & (t <= max(t_run, t_ref) + AT_EVENT)
    out = {}
    v_scale = np.max(np.abs(ref["v1"]))
    for name in QUANTITIES:
        scale = np.max(np.abs(ref[name]))
        if name in ("S1", "S2"):
            scale = scale + np.abs(ref[f"d{name}/dv1"]) * v_scale
        err = np.abs(np.asarray(getattr(result, name), dtype=float) - ref[name]) / (rtol * scale)
        if name in ("S1", "S2"):
            err = np.where(near_event, 0.0, err)
        for kind, mask in (("ordinary", ~first), ("first", first)):
            out[name, kind] = float(np.max(err[mask], initial=0.0))
    return out
