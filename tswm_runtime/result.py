"""The result of a simulation, in the spirit of scipy's OdeResult, and its status messages."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from tswm_runtime import hybrid
from tswm_runtime.modes import event_name

STATUS_NAMES = {
    hybrid.FINISHED: "finished", hybrid.SLIDING: "sliding", hybrid.INCONSISTENT: "inconsistent",
    hybrid.UNDECLARED: "undeclared-mode", hybrid.CHATTERING: "chattering",
    hybrid.TOO_MANY_EVENTS: "too-many-events", hybrid.STEP_TOO_SMALL: "step-too-small",
    hybrid.MAX_STEPS: "max-steps", hybrid.NOT_FINITE: "not-finite",
    hybrid.INVALID_INPUT: "invalid-input",
}
NEEDED_MODE = {hybrid.NEED_STICK: "stick", hybrid.NEED_FORWARD: "forward",
               hybrid.NEED_BACKWARD: "backward"}


@dataclass(frozen=True)
class Event:
    """A mode change: time, the guard that fired, from-mode, to-mode (None: the run stopped)."""

    t: float
    guard: str
    from_mode: str
    to_mode: str | None
    x1: float
    v1: float

    @property
    def kind(self) -> str:
        return event_name(self.guard)


@dataclass(frozen=True)
class Phase:
    """A time interval spent in one mode."""

    mode: str
    regime: str
    t_start: float
    t_end: float


@dataclass
class Result:
    """t, x1, v1, a1, x2, v2, S1, S2, F1, F2 and mode per output point; events, maxima, KD."""

    scene: str
    params: dict
    settings: dict
    t: np.ndarray
    x1: np.ndarray
    v1: np.ndarray
    a1: np.ndarray
    x2: np.ndarray
    v2: np.ndarray
    S1: np.ndarray
    S2: np.ndarray
    F1: np.ndarray
    F2: np.ndarray
    mode: np.ndarray              # mode index per output point
    mode_names: tuple[str, ...]
    events: list[Event]
    phases: list[Phase]
    S1_max: float                 # the value of S1 where |S1| is largest, and its time (+-inf: unbounded,
                                  # status inconsistent: no finite reaction exists there)
    t_S1_max: float
    S2_max: float
    t_S2_max: float
    KD1: float | None             # eq. (10), when the scene gives Ft1, Ft2
    KD2: float | None
    status: str
    message: str
    t_stop: float
    n_steps: int
    n_rejected: int
    nfev: int
    njev: int
    extras: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.status == "finished"

    @property
    def regime_sequence(self) -> str:
        """The phases as text: 'stick [0, 0.1) -> tractive [0.1, 1]'."""
        return " -> ".join(f"{ph.regime} [{ph.t_start:.6g}, {ph.t_end:.6g}]" for ph in self.phases)

    @classmethod
    def build(cls, module: ModuleType, p: np.ndarray, p_rows: np.ndarray, run: dict, t, x1, v1, mode,
              events, mon, counters, *, hybrid_status: int, t_stop: float, first_mode: int,
              message: str) -> Result:
        """Evaluate the laws and reactions at the output points, each with the mode and
        the latched laws in force there (``p_rows``), and assemble the result."""
        n = len(module.STATES)
        a1, S1, S2, F1, F2 = (np.empty(t.size) for _ in range(5))
        for r in range(t.size):
            y, pr = np.array([x1[r], v1[r]][2 - n:]), p_rows[r]
            a1[r] = module.accel(mode[r], t[r], y, pr)
            S1[r], S2[r] = module.reactions(mode[r], t[r], y, pr)
            F1[r], F2[r] = module.drive_force(t[r], y, pr), module.load_force(t[r], y, pr)
        slope = math.tan(_value(module, p, "gamma"))
        KD1 = KD2 = None
        if module.HAS_LOAD_FACTORS:
            KD1, KD2 = module.load_factors(mon[0, 1], mon[1, 1], p)
        return cls(
            scene=module.SCENE, params=dict(zip(module.PARAM_NAMES, p.tolist())), settings=dict(run),
            t=t, x1=x1, v1=v1, a1=a1, x2=x1 * slope, v2=v1 * slope, S1=S1, S2=S2, F1=F1, F2=F2,
            mode=mode, mode_names=tuple(module.MODES), events=events,
            phases=_phases(module, first_mode, events, t_stop),
            S1_max=float(mon[0, 1]), t_S1_max=float(mon[0, 2]), S2_max=float(mon[1, 1]),
            t_S2_max=float(mon[1, 2]), KD1=KD1, KD2=KD2, status=STATUS_NAMES[hybrid_status],
            message=message, t_stop=float(t_stop), n_steps=int(counters[0]), n_rejected=int(counters[1]),
            nfev=int(counters[2]), njev=int(counters[3]),
            extras={name: float(v) for name, v in zip(getattr(module, "LATCH_NAMES", ()),
                                                      p[len(module.PARAM_NAMES):]) if not name.endswith("_piece")})


def _value(module: ModuleType, p: np.ndarray, name: str) -> float:
    """A parameter's value, free (from p) or fixed."""
    free = dict(zip(module.PARAM_NAMES, p))
    return float(free[name] if name in free else module.FIXED[name])


def _phases(module: ModuleType, first: int, events: list[Event], t_stop: float) -> list[Phase]:
    """Consecutive modes from the event log; events that keep the mode do not split a phase."""
    if first < 0:
        return []
    starts = [(0.0, module.MODES[first])]
    for e in events:
        if e.to_mode is not None and e.to_mode != starts[-1][1]:
            starts.append((e.t, e.to_mode))
    ends = [s for s, _ in starts[1:]] + [t_stop]
    regime = dict(zip(module.MODES, module.MODE_REGIME))
    return [Phase(m, regime[m], s, e) for (s, m), e in zip(starts, ends)]


def _inconsistent(module: ModuleType, t_stop: float, y_stop: np.ndarray, last: int, events: list[Event],
                  p: np.ndarray) -> str:
    """Where and why no finite contact force exists: the mode, D's formula and value."""
    name = module.MODES[last]
    g = np.empty(len(module.GUARDS))
    module.guards(last, t_stop, np.ascontiguousarray(y_stop, dtype=np.float64), p, g)
    value = {k: g[module.GUARDS.index(k)] for k in ("D", "jam") if k in module.GUARDS}
    formula = module.MODE_D[last] or "(none: the mode has no contact denominator)"
    reached = events and events[-1].guard in ("D", "jam") and events[-1].to_mode is None
    how = ("D fell to 0 in finite time (a1 -> -inf like the square root of the time left)" if reached
           else "the mode the state needs has D <= 0")
    jam = f" and the jam factor cos(gamma + f s rho) = {value['jam']:.6g}" if "jam" in value else ""
    masses = ", ".join(f"{k} = {_value(module, p, k):.6g}" for k in ("m1", "m2", "gamma"))
    return (f"inconsistent at t = {t_stop:.9g} s in mode {name}: {how}; D = {formula} = "
            f"{value.get('D', math.nan):.6g}{jam}, so no finite contact force satisfies the constraint "
            f"(a Painleve-type case): the reactions are unbounded there; with {masses} (SI) "
            f"lower m2 or the friction, or raise m1")


def status_message(module: ModuleType, status: int, t_stop: float, y_stop: np.ndarray, last: int,
                   need: int, events: list[Event], p: np.ndarray) -> str:
    """A sentence saying how the run ended, naming what to change when it failed."""
    declared = [m for m, d in zip(module.MODES, getattr(module, "MODE_DECLARED", [True] * len(module.MODES))) if d]
    at = f"t = {t_stop:.9g} s"
    if status == hybrid.FINISHED:
        return f"reached t_end = {t_stop:.9g} s with {len(events)} mode changes"
    if status == hybrid.UNDECLARED and need == hybrid.NEED_FLANK:
        return (f"the contact force on the scene's only flank vanishes at {at} (phi = 0): body 2 "
                f"would lift off, which a one-sided scene cannot model; add the other flank to "
                f"[wedge] flanks")
    if status == hybrid.UNDECLARED:
        wanted = NEEDED_MODE[need]
        cause = {"stick": "v1 reached 0", "backward": "the load drives the worm backward",
                 "forward": "the drive moves the worm forward"}[wanted]
        literal = (" (the printed equations model forward sliding only: use the consistent scene)"
                   if module.EQUATIONS == "literal" else "")
        return (f"the scene declares the modes {', '.join(declared)} only; {cause} at {at}; "
                f"add '{wanted}' to [modes] include{literal}")
    if status == hybrid.SLIDING:
        return (f"at {at} both flanks push the state onto phi = 0 (Filippov sliding: the printed "
                f"equations jump across phi = 0); the scene excludes it: add 'sliding' to [modes] "
                f"include to follow the sliding motion")
    if status == hybrid.INCONSISTENT:
        return _inconsistent(module, t_stop, y_stop, last, events, p)
    if status == hybrid.CHATTERING:
        return f"{hybrid.MAX_SAME_TIME} mode changes at {at} without time advancing (chattering); stopped"
    if status == hybrid.TOO_MANY_EVENTS:
        return f"the event log is full ({len(events)} events) at {at}; raise max_events"
    if status == hybrid.MAX_STEPS:
        return f"max_steps step attempts used up at {at}; raise max_steps or loosen rtol"
    if status == hybrid.STEP_TOO_SMALL:
        return f"the step size fell below the resolution of t at {at} (a singularity?)"
    if status == hybrid.NOT_FINITE:
        return f"a non-finite state, derivative or guard at {at}"
    return "invalid input to the integrator"
