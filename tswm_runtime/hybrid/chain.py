"""A rigid chain of wedge stages run by the generic mode machine, one mode at a time.

A chain module (derivation/chain/codegen.py) has one coordinate q0 and a sliding mode per direction
and combination of the stages' flanks. The compiled mode machine (``machine.integrate_hybrid``,
through ``entry.integrate``) integrates one mode and stops at the first chain event, because the
chain's guards are given kinds at which it stops without choosing a mode itself: D (G_D: the
Painleve approach locates D = 0), the stages' jam factor and each stage's normal force (G_JAM: it
stops in the mode where one reaches 0) and v0 (G_V1 in a model without a stick mode: it stops at
rest). The next mode is decided here, in Python, for all stages at once by the complementarity
logic the derivation uses (tswm_common/chain_decision.py), with the module's numbers at the event:
a flank change, breakaway or rest; no mode or several (a Painleve-type case) stop the run with the
reason. So a chain needs no kernel of its own: the one compiled for every scene runs it.

A resting chain stays at rest: its forces depend on q0 (springs) and v0 (a motor's table), which
rest with it. While sliding, every stage force is affine in the bodies' forces; each phase keeps
the stage forces at its ends and at the output points inside it. Without a motor the bodies'
forces are affine in q0, which is monotone in a sliding phase, so a stage force's extreme lies
at a phase end and the maxima taken from these samples are exact.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tswm_common.chain_decision import STUCK, Candidate, Decision, Statics, decide_numbers
from tswm_runtime.hybrid import entry
from tswm_runtime.hybrid import machine as hybrid
from tswm_runtime.jit.structures import ModeTables

RESTING = -1                 # the mode index of the resting chain (no mode of the module)
STATUS = {hybrid.STEP_TOO_SMALL: "step-too-small", hybrid.MAX_STEPS: "max-steps", hybrid.NOT_FINITE: "not-finite",
          hybrid.INVALID_INPUT: "invalid-input"}
MAX_SAME_TIME = 8            # decisions at one instant before the run stops (chattering)


def tables(module) -> ModeTables:
    """The machine's tables for a chain module: sliding modes only, its guards' kinds."""
    kinds = {"D": hybrid.G_D, "jam": hybrid.G_JAM, "v0": hybrid.G_V1}
    guard_kind = np.array([kinds.get(g, hybrid.G_JAM) for g in module.GUARDS], np.int64)   # N_k: G_JAM
    n_modes, n_guards = len(module.MODES), len(module.GUARDS)
    return ModeTables(np.full(n_modes, hybrid.M_SLIDING, np.int64), np.zeros(n_modes, np.int64),
                      np.array(module.MODE_DIRECTION, np.int64), np.ones(n_modes, np.int64),
                      np.array(module.GUARD_DIRECTIONS, np.int64).reshape(n_modes, n_guards), guard_kind,
                      np.full(n_guards, -1, np.int64), np.zeros(n_guards, np.int64))


@dataclass
class Phase:
    """A stretch of the run in one mode (RESTING: at rest), with the stage forces sampled in it."""

    mode: int
    t_start: float
    t_end: float
    forces: list = field(default_factory=list)   # (t, stage_forces) at its ends and output points (sliding)


@dataclass
class ChainEvent:
    """What happened at time t: the guard that fired (or "start"), the decision and its reason."""

    t: float
    guard: str
    from_mode: int
    to_mode: int | None          # None: the run stops here
    decision: Decision


@dataclass
class ChainRun:
    status: str                  # "finished" or why the run stopped
    message: str
    t_stop: float
    phases: list[Phase]
    events: list[ChainEvent]
    t: np.ndarray                # output times, and the states there (NaN after a stop)
    y: np.ndarray
    n_steps: int


def _candidates(module, t: float, y: np.ndarray, directions) -> list[Candidate]:
    g = np.empty(len(module.GUARDS))
    out = []
    n = module.STAGES
    for m, direction in enumerate(module.MODE_DIRECTION):
        if direction in directions:
            module.guards(m, t, y, np.empty(0), g)
            out.append(Candidate(module.MODES[m], direction, float(module.accel(m, t, y, np.empty(0))), float(g[0]),
                                 tuple(float(x) for x in g[2:2 + n])))
    return out


def decide(module, t: float, y: np.ndarray) -> Decision:
    """The chain's mode at (t, y): every candidate in the direction of v0 (both at rest), and rest."""
    v = y[1]
    directions = (1, -1) if v == 0 else ((1,) if v > 0 else (-1,))
    statics = Statics(module.PSI, module.LEVER_IN, module.LEVER_OUT,
                      tuple(float(f) for f in module.body_forces(t, y, np.empty(0))))
    return decide_numbers(_candidates(module, t, y, directions), v, statics)


def _chosen(module, decision: Decision, current: int) -> int | None:
    """The mode a decision gives: RESTING, a sliding mode, None (no mode or several: stop). Where
    modes agree in a_0 (critical: the stages they differ in carry no force) the one that is not
    the current mode is taken: the event was the current mode's normal force leaving 0."""
    if decision.outcome == "unique":
        return RESTING if decision.modes[0] == STUCK else module.MODES.index(decision.modes[0])
    if decision.outcome == "critical":
        others = [module.MODES.index(name) for name in decision.modes if module.MODES.index(name) != current]
        return others[0]
    return None


def _forces(module, mode: int, t: float, y: np.ndarray) -> np.ndarray:
    out = np.empty(3 * module.STAGES)
    module.stage_forces(mode, t, y, np.empty(0), out)
    return out


def run_chain(module, *, t_end: float, v0: float, rtol: float, atol: float, t_out: np.ndarray,
              method: int = 0, max_steps: int = 100_000, max_events: int = 1000) -> ChainRun:
    """Integrate the chain from q0 = 0, v0 to t_end through its mode changes."""
    p = np.empty(0)
    modes = tables(module)
    t, y = 0.0, np.array([0.0, float(v0)])
    rows = np.full((t_out.size, 2), np.nan)
    phases, events, steps, same = [], [], 0, 0
    decision = decide(module, t, y)
    mode = _chosen(module, decision, RESTING)
    events.append(ChainEvent(t, "start", RESTING, mode, decision))
    status, message = "finished", ""
    while True:
        if mode is None:
            status = "indeterminate" if decision.outcome == "several" else "inconsistent"
            message = decision.reason
            break
        if mode == RESTING:
            phases.append(Phase(RESTING, t, t_end))
            rows[t_out >= t] = (y[0], 0.0)
            t = t_end
            break
        if len(events) >= max_events:
            status, message = "too-many-events", f"{max_events} events"
            break
        first = int(np.searchsorted(t_out, t))
        phase = Phase(mode, t, t, [(t, _forces(module, mode, t, y))])
        code, t_stop, n_ev, _, _, _, out, log, _, counters, _ = entry.integrate(
            method, module, p, modes, y, t_end, rtol=rtol, atol=atol, t_out=t_out[first:], max_events=1, t0=t,
            mode0=mode, max_steps=max(max_steps - steps, 1))
        steps += int(counters[0] + counters[1])
        done = out.mode >= 0
        rows[first:][done] = out.y[done]
        phase.forces += [(t_i, _forces(module, mode, t_i, y_i)) for t_i, y_i in zip(out.t[done], out.y[done])]
        same = same + 1 if t_stop == t else 0
        t = t_stop
        if n_ev == 0:
            phase.t_end = t
            phases.append(phase)
            if code != hybrid.FINISHED:
                status, message = STATUS.get(code, f"status {code}"), f"the integrator stopped at t = {t:.9g} s"
            break
        y = log.state[0, :2].copy()
        guard = module.GUARDS[log.index[0, 0]]
        phase.t_end = t
        phase.forces.append((t, _forces(module, mode, t, y)))
        phases.append(phase)
        if guard in ("D", "jam"):
            status = "inconsistent"
            message = (f"{guard} reached 0 in mode {module.MODES[mode]} at t = {t:.9g} s: no contact force keeps "
                       "the stages together (a Painleve-type inconsistency), not integrated through")
            events.append(ChainEvent(t, guard, mode, None, Decision("none", (), None, message)))
            break
        if guard == "v0":
            y[1] = 0.0
        decision = decide(module, t, y)
        new = _chosen(module, decision, mode)
        events.append(ChainEvent(t, guard, mode, new, decision))
        if same >= MAX_SAME_TIME:
            status, message = "chattering", f"{MAX_SAME_TIME} decisions at t = {t:.9g} s"
            break
        mode = new
    return ChainRun(status, message, t, phases, events, t_out, rows, steps)
