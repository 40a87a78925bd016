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

The torque switch and the valve's seat are latches in the parameter vector p (the module's
P_NAMES): their guards stop the machine like the others, and here the seat's contact flips, the
switch picks up (its delay starts), drops out (below setting - hysteresis) or trips (the motor is cut
for good); then the mode is decided again with the new forces. A resting chain stays at rest: its
forces depend on q0 (springs, the seat) and v0 (a motor's table), which rest with it, except when a
picked-up switch's delay ends while it rests: the motor is cut then and the chain decided again. While
it rests, the switch sees body 0's drive torque; a switch on a stage's force keeps its state (the
split of a resting chain's forces is statically undetermined).

While sliding, every stage force is affine in the bodies' forces; each phase keeps
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
    latches: np.ndarray                          # p in the phase: switch state, pick-up time, seated
    samples: list = field(default_factory=list)  # (t, y, stage_forces) at its ends and output points (sliding)


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
    trip: tuple | None = None    # (t, y, mode, stage forces before the cut) when the switch cut the motor


def latches(module, y: np.ndarray, voltage: float | None = None) -> np.ndarray:
    """p at the start: the switch armed, the seat pressed if the last body starts at or beyond it, the
    motor's voltage U / U_n (the scene's unless given)."""
    p = np.zeros(len(module.P_NAMES))
    p[module.P_SEATED] = float(module.HAS_SEAT and module.SPEED_FACTORS[-1] * y[0] >= module.SEAT)
    p[module.P_VOLTAGE] = getattr(module, "MOTOR_VOLTAGE", 1.0) if voltage is None else voltage
    return p


def _candidates(module, t: float, y: np.ndarray, p: np.ndarray, directions) -> list[Candidate]:
    g = np.empty(len(module.GUARDS))
    out = []
    n = module.STAGES
    for m, direction in enumerate(module.MODE_DIRECTION):
        if direction in directions:
            module.guards(m, t, y, p, g)
            out.append(Candidate(module.MODES[m], direction, float(module.accel(m, t, y, p)), float(g[0]),
                                 tuple(float(x) for x in g[2:2 + n])))
    return out


def decide(module, t: float, y: np.ndarray, p: np.ndarray) -> Decision:
    """The chain's mode at (t, y) under latches p: every candidate in the direction of v0 (both at rest),
    and rest (the valve's friction holding anything up to its magnitude)."""
    v = y[1]
    directions = (1, -1) if v == 0 else ((1,) if v > 0 else (-1,))
    statics = Statics(module.PSI, module.LEVER_IN, module.LEVER_OUT,
                      tuple(float(f) for f in module.body_forces(t, y, p, 0.0)), float(module.LOAD_FRICTION))
    return decide_numbers(_candidates(module, t, y, p, directions), v, statics)


def _switched(module, mode: int, t: float, y: np.ndarray, p: np.ndarray, guard: str) -> bool:
    """Apply the switch's logic at (t, y) in ``mode`` (a fired ``guard`` forces its transition); True when
    the motor has just been cut."""
    if module.SWITCH_ON < 0:
        return False
    g = np.full(len(module.GUARDS), np.nan)
    if mode == RESTING:
        drive = float(module.body_forces(t, y, p, 0.0)[0]) if module.SWITCH_ON == 0 else np.nan
        g[-2] = module.switch_gap(drive, p)
        g[-1] = module.delay_left(t, p)
    else:
        module.guards(mode, t, y, p, g)
    if p[module.P_SWITCH] != module.TRIPPED and (guard == "switch" or g[-2] < 0):
        p[module.P_SWITCH] = module.PICKED if p[module.P_SWITCH] == module.ARMED else module.ARMED
        p[module.P_PICK] = t
    if p[module.P_SWITCH] == module.PICKED and (guard == "delay" or module.delay_left(t, p) <= 0):
        p[module.P_SWITCH] = module.TRIPPED
        return True
    return False


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


def _forces(module, mode: int, t: float, y: np.ndarray, p: np.ndarray) -> np.ndarray:
    out = np.empty(3 * module.STAGES)
    module.stage_forces(mode, t, y, p, out)
    return out


def _cut(module, mode: int, t: float, y: np.ndarray, p: np.ndarray) -> dict:
    """What the chain carried just before the motor's cut (p still powered): mode, state, stage forces
    (None at rest: undetermined), body 0's drive torque."""
    direction = 0.0 if mode == RESTING else float(module.MODE_DIRECTION[mode])
    return {"t": t, "y": y.copy(), "mode": mode,
            "forces": None if mode == RESTING else _forces(module, mode, t, y, p),
            "drive": float(module.body_forces(t, y, p, direction)[0])}


def _settle(module, t: float, y: np.ndarray, p: np.ndarray, mode: int, guard: str) -> tuple[Decision, int | None, dict | None]:
    """The latches after ``guard`` fired in ``mode`` (the seat's contact flips; the switch moves), then the
    next mode; a switch that picks up with no delay, or sees its setting already where the chain
    starts or comes to rest, cuts the motor at once and the mode is decided again. Returns the decision,
    the mode and what the chain carried at a cut (None: no cut here)."""
    cut = None
    before = p.copy()
    if guard == "seat":
        p[module.P_SEATED] = 1.0 - p[module.P_SEATED]
    if guard in ("switch", "delay") and _switched(module, mode, t, y, p, guard):
        cut = _cut(module, mode, t, y, before)
    decision = decide(module, t, y, p)
    new = _chosen(module, decision, mode)
    if new is not None and (guard == "start" or new == RESTING):
        before = p.copy()
        if _switched(module, new, t, y, p, "check"):
            cut = _cut(module, new, t, y, before)
            decision = decide(module, t, y, p)
            new = _chosen(module, decision, new)
    return decision, new, cut


def run_chain(module, *, t_end: float, v0: float, rtol: float, atol: float, t_out: np.ndarray,
              method: int = 0, max_steps: int = 100_000, max_events: int = 1000,
              voltage: float | None = None) -> ChainRun:
    """Integrate the chain from q0 = 0, v0 to t_end through its mode changes and its switch's and seat's
    events; ``voltage`` (U / U_n) replaces the scene's motor voltage."""
    modes = tables(module)
    t, y = 0.0, np.array([0.0, float(v0)])
    p = latches(module, y, voltage)
    rows = np.full((t_out.size, 2), np.nan)
    phases, events, steps, same = [], [], 0, 0
    decision, mode, trip = _settle(module, t, y, p, RESTING, "start")
    events.append(ChainEvent(t, "start", RESTING, mode, decision))
    status, message = "finished", ""
    while True:
        if mode is None:
            status = "indeterminate" if decision.outcome == "several" else "inconsistent"
            message = decision.reason
            break
        if mode == RESTING:
            t_cut = p[module.P_PICK] + module.SWITCH_DELAY if p[module.P_SWITCH] == module.PICKED else math.inf
            phases.append(Phase(RESTING, t, min(t_cut, t_end), p.copy()))
            rows[t_out >= t] = (y[0], 0.0)
            if t_cut >= t_end:
                t = t_end
                break
            t = t_cut
            decision, mode, cut = _settle(module, t, y, p, RESTING, "delay")
            trip = trip or cut
            events.append(ChainEvent(t, "delay", RESTING, mode, decision))
            continue
        if len(events) >= max_events:
            status, message = "too-many-events", f"{max_events} events"
            break
        first = int(np.searchsorted(t_out, t))
        phase = Phase(mode, t, t, p.copy(), [(t, y.copy(), _forces(module, mode, t, y, p))])
        code, t_stop, n_ev, _, _, _, out, log, _, counters, _ = entry.integrate(
            method, module, p, modes, y, t_end, rtol=rtol, atol=atol, t_out=t_out[first:], max_events=1, t0=t,
            mode0=mode, max_steps=max(max_steps - steps, 1))
        steps += int(counters[0] + counters[1])
        done = out.mode >= 0
        rows[first:][done] = out.y[done]
        phase.samples += [(t_i, y_i.copy(), _forces(module, mode, t_i, y_i, p))
                          for t_i, y_i in zip(out.t[done], out.y[done])]
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
        phase.samples.append((t, y.copy(), _forces(module, mode, t, y, p)))
        phases.append(phase)
        if guard in ("D", "jam"):
            status = "inconsistent"
            message = (f"{guard} reached 0 in mode {module.MODES[mode]} at t = {t:.9g} s: no contact force keeps "
                       "the stages together (a Painleve-type inconsistency), not integrated through")
            events.append(ChainEvent(t, guard, mode, None, Decision("none", (), None, message)))
            break
        if guard == "v0":
            y[1] = 0.0
        decision, new, cut = _settle(module, t, y, p, mode, guard)
        trip = trip or cut
        events.append(ChainEvent(t, guard, mode, new, decision))
        if same >= MAX_SAME_TIME:
            status, message = "chattering", f"{MAX_SAME_TIME} decisions at t = {t:.9g} s"
            break
        mode = new
    return ChainRun(status, message, t, phases, events, t_out, rows, steps, trip)
