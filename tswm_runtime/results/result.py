"""The result of a simulation, in the spirit of scipy's OdeResult, and its status messages."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property
from types import ModuleType
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from tswm_runtime.common.words import plural
from tswm_runtime.hybrid import machine as hybrid
from tswm_runtime.jit.structures import EventLog
from tswm_runtime.model.modes import event_guard, event_name
from tswm_runtime.results.rows import MAX_LOGGED_STEPS, Rows, state_names, states

if TYPE_CHECKING:  # the kernels load on importing entry: simulate announces that first
    from tswm_runtime.hybrid.entry import RunArrays

class Status(IntEnum):
    """The mode machine's status codes (hybrid.FINISHED, ...), for Python."""

    FINISHED = hybrid.FINISHED
    SLIDING = hybrid.SLIDING
    INCONSISTENT = hybrid.INCONSISTENT
    UNDECLARED_MODE = hybrid.UNDECLARED
    CHATTERING = hybrid.CHATTERING
    TOO_MANY_EVENTS = hybrid.TOO_MANY_EVENTS
    INDETERMINATE = hybrid.INDETERMINATE
    STEP_TOO_SMALL = hybrid.STEP_TOO_SMALL
    MAX_STEPS = hybrid.MAX_STEPS
    NOT_FINITE = hybrid.NOT_FINITE
    INVALID_INPUT = hybrid.INVALID_INPUT

    @property
    def label(self) -> str:
        """The status as results and tables name it: 'step-too-small', ..."""
        return self.name.lower().replace("_", "-")


STATUS_NAMES = {int(status): status.label for status in Status}
# (name, SI unit) of the per-point series of a Result, in table order.
SERIES = (("t", "s"), ("x1", "m"), ("v1", "m/s"), ("a1", "m/s^2"), ("x2", "m"), ("v2", "m/s"),
          ("S1", "N"), ("S2", "N"), ("F1", "N"), ("F2", "N"))
GAP_SERIES = (("gap", "m"), ("gap_rate", "m/s"))   # with a clearance only
STEM_SERIES = (("x3", "m"), ("v3", "m/s"))          # with lost motion only: the stem's travel and speed
UNITS = dict((*SERIES, *GAP_SERIES, *STEM_SERIES))
# Why a run meets inf or NaN: the loader bounds every value (docs/scene-format.md) so that the
# equations hold in double arithmetic; what is left is a law that overflows.
NOT_FINITE_CAUSE = ("a law that overflows (a force growing without bound, an exp of a large argument, a "
                    "division by a vanishing quantity: an edited module?) or parameter values far outside "
                    "the scene file's bounds (|F| <= 1e12 N, 1e-9 <= m <= 1e9 kg; docs/scene-format.md)")
NEEDED_MODE = {hybrid.NEED_STICK: "stick", hybrid.NEED_FORWARD: "forward",
               hybrid.NEED_BACKWARD: "backward"}


@dataclass(frozen=True)
class Jump:
    """What an impact did: the normal and tangential impulse on body 2 (a pickup: P_n on the
    stem, -P_n on body 2, P_t = 0), the kinetic energy lost (>= 0), and v1 before it (the
    event's state is the one after)."""

    P_n: float
    P_t: float
    energy_lost: float
    v1_before: float


@dataclass(frozen=True)
class Event:
    """A mode change: time, the guard that fired, from-mode, to-mode (None: the run stopped);
    x1, v1 just after it; for an impact, its Jump."""

    t: float
    guard: str
    from_mode: str
    to_mode: str | None
    x1: float
    v1: float
    jump: Jump | None = None
    state: dict = field(default_factory=dict)   # every state after the event, by name

    @property
    def kind(self) -> str:
        return event_name(self.guard)

    def to_dict(self) -> dict:
        """t, guard, kind, from_mode, to_mode (None: the run stopped there), x1, v1; an impact's
        P_n, P_t, energy_lost, v1_before."""
        jump = vars(self.jump) if self.jump else {}
        return {"t": self.t, "guard": self.guard, "kind": self.kind, "from_mode": self.from_mode,
                "to_mode": self.to_mode, "x1": self.x1, "v1": self.v1, **jump}


@dataclass(frozen=True)
class Phase:
    """A time interval spent in one mode."""

    mode: str
    regime: str
    t_start: float
    t_end: float


def _series(name: str, doc: str) -> property:
    """A per-point series of the Result, evaluated from the run's steps on first access of any of
    them (``results.rows``) and kept; empty if the scene has no such state."""
    return property(lambda self: self.rows.values().get(name, _EMPTY), doc=doc)


_EMPTY = np.empty(0)
_EMPTY.setflags(write=False)


class RunRecord(NamedTuple):
    """What a run leaves for the parts of its Result built on first access: the module, the
    parameter vector (latches set), the run's arrays (``entry.RunArrays``: the running maxima
    ``mon``, the EventLog ``log``) and its number of events, the first and last mode, the status
    code and the mode needed, the states at the start, and for a run that met inf or NaN its first
    non-finite value and last values (``status_message``)."""

    module: ModuleType
    p: np.ndarray
    arrays: RunArrays
    n_events: int
    first_mode: int
    last_mode: int
    code: int
    need: int
    start: np.ndarray
    found: tuple | None = None
    last_values: tuple | None = None

    @property
    def mon(self) -> np.ndarray:
        """The observables' running maxima, one row each: (|value|, value, t)."""
        return self.arrays.record.mon

    @property
    def log(self) -> EventLog:
        return self.arrays.record.log


#: The parts of a Result built from its RunRecord on first access (``Result.__getstate__`` builds them).
LAZY = ("params", "model", "mode_names", "events", "phases", "KD1", "KD2", "message", "extras")


@dataclass
class Result:
    """The status, maxima, final state and counts, computed by the run; events, phases, KD, the
    message, parameters and model facts, built from the run's record on first access; t, x1, v1, a1,
    x2, v2, S1, S2, F1, F2 and mode per output point and ``sol(t)``, evaluated from the run's steps
    when first read."""

    scene: str
    settings: dict
    rows: Rows = field(repr=False, compare=False)   # the per-point series, evaluated on first access
    final_state: dict                               # the states (and x1) at t_stop, their left limit at an event
    S1_max: float                 # the value of S1 where |S1| is largest, and its time (+-inf: unbounded,
                                  # status inconsistent where D reached 0 or at the start; a stop at an
                                  # event or impact keeps the finite peaks reached before it; NaN: a run
                                  # that stopped at its start, undeclared or indeterminate, integrated nothing)
    t_S1_max: float
    S2_max: float
    t_S2_max: float
    status: str
    t_stop: float
    n_steps: int
    n_rejected: int
    nfev: int
    njev: int
    n_switches: int = 0  # method "auto": switches between dopri5 and rosenbrock23
    record: RunRecord | None = field(default=None, repr=False, compare=False)  # None once pickled

    @cached_property
    def params(self) -> dict:
        """The free parameters of the run by name (SI)."""
        return dict(zip(self.record.module.PARAM_NAMES, self.record.p.tolist()))

    @cached_property
    def model(self) -> dict:
        """equations, states, param_units, fixed_params, mode_regime of the scene's module."""
        module = self.record.module
        return {"equations": module.EQUATIONS, "states": tuple(module.STATES),
                "param_units": dict(zip(module.PARAM_NAMES, module.PARAM_UNITS)),
                "fixed_params": dict(module.FIXED), "mode_regime": tuple(module.MODE_REGIME)}

    @cached_property
    def mode_names(self) -> tuple[str, ...]:
        return tuple(self.record.module.MODES)

    @cached_property
    def events(self) -> list[Event]:
        """The run's events in order, from its EventLog."""
        record = self.record
        return _events(record.module, record.log, record.n_events)

    @cached_property
    def phases(self) -> list[Phase]:
        return _phases(self.record.module, self.record.first_mode, self.events, self.t_stop)

    @cached_property
    def KD1(self) -> float | None:
        """eq. (10), when the scene gives Ft1, Ft2."""
        return self._load_factors()[0]

    @cached_property
    def KD2(self) -> float | None:
        return self._load_factors()[1]

    def _load_factors(self) -> tuple:
        module, mon = self.record.module, self.record.mon
        return module.load_factors(mon[0, 1], mon[1, 1], self.record.p) if module.HAS_LOAD_FACTORS else (None, None)

    @cached_property
    def message(self) -> str:
        """How the run ended (``status_message``)."""
        r = self.record
        n = len(r.module.STATES)
        y_stop = r.log.state[r.n_events - 1, :n].copy() if r.n_events else r.start
        return status_message(r.module, r.code, self.t_stop, y_stop, r.last_mode, r.need, self.events, r.p,
                              found=r.found, last_values=r.last_values)

    @cached_property
    def extras(self) -> dict:
        """The latched values (a torque switch's trip time, ...) by name; piece indices left out."""
        module, p = self.record.module, self.record.p
        return {name: float(v) for name, v in zip(getattr(module, "LATCH_NAMES", ()), p[len(module.PARAM_NAMES):])
                if not name.endswith("_piece")}

    def __getstate__(self) -> dict:
        """For pickling: every lazy part built, the record (which holds the module) left behind."""
        for name in LAZY:
            getattr(self, name)
        return {**self.__dict__, "record": None}

    t = _series("t", "output times [s] up to t_stop")
    x1 = _series("x1", "x1 [m] per output point")
    v1 = _series("v1", "v1 [m/s] per output point")
    a1 = _series("a1", "a1 [m/s^2] per output point, in the mode in force there")
    x2 = _series("x2", "x2 [m] per output point")
    v2 = _series("v2", "v2 [m/s] per output point")
    S1 = _series("S1", "S1 [N] per output point")
    S2 = _series("S2", "S2 [N] per output point")
    F1 = _series("F1", "F1 [N] per output point")
    F2 = _series("F2", "F2 [N] per output point")
    mode = _series("mode", "mode index per output point")
    gap = _series("gap", "normal gap from flank a [m] per output point (with a clearance)")
    gap_rate = _series("gap_rate", "the gap's rate [m/s] per output point (with a clearance)")
    x3 = _series("x3", "the stem's travel from rest [m] per output point (lost motion)")
    v3 = _series("v3", "the stem's speed [m/s] per output point (lost motion)")

    @property
    def series(self) -> tuple[tuple[str, str], ...]:
        """(name, SI unit) of this result's per-point series: SERIES, the gap's with a clearance, the
        stem's with lost motion."""
        states = self.model.get("states", ())
        return SERIES + (GAP_SERIES if "gap" in states else ()) + (STEM_SERIES if "x3" in states else ())

    @property
    def event_a1(self) -> np.ndarray:
        """a1 just after each event, in the mode entered and with the latches in force after it (NaN
        where the run stopped)."""
        values, module = self.rows.values(), self.rows.module
        t, p_rows, p = values["t"], values["p"], self.rows.p
        out = np.full(len(self.events), np.nan)
        for e, event in enumerate(self.events):
            if event.to_mode is not None:
                after = np.searchsorted(t, event.t, side="right")
                ye = np.array([event.state[name] for name in module.STATES], dtype=np.float64)
                out[e] = module.accel(module.MODES.index(event.to_mode), event.t, ye,
                                      p_rows[after] if after < t.size else p)
        return out

    @property
    def impacts(self) -> list[Event]:
        """The events that were impacts (gap closed on a flank, or body 2 struck the stem)."""
        return [e for e in self.events if e.jump is not None]

    @property
    def impact_energy(self) -> float:
        """Kinetic energy lost in all impacts [J]."""
        return float(sum(e.jump.energy_lost for e in self.impacts))

    @property
    def success(self) -> bool:
        return self.status == "finished"

    @property
    def regime_sequence(self) -> str:
        """The phases as text: 'stick [0, 0.1) -> tractive [0.1, 1]'."""
        return " -> ".join(f"{ph.regime} [{ph.t_start:.6g}, {ph.t_end:.6g}]" for ph in self.phases)

    def to_dict(self) -> dict:
        """The run's scalars: scene, status, message, parameters (SI, with units), settings,
        maxima, KD, phases, events, counts (plain Python values; +-inf stays a float)."""
        return {
            "scene": self.scene, "equations": self.model.get("equations"), "status": self.status,
            "success": self.success, "message": self.message, "t_stop": self.t_stop,
            "params": dict(self.params), "param_units": dict(self.model.get("param_units", {})),
            "fixed_params": dict(self.model.get("fixed_params", {})), "settings": dict(self.settings),
            "maxima": {"S1": {"value": self.S1_max, "t": self.t_S1_max, "unit": "N"},
                       "S2": {"value": self.S2_max, "t": self.t_S2_max, "unit": "N"}},
            "KD1": self.KD1, "KD2": self.KD2, "regime_sequence": self.regime_sequence,
            "phases": [{"mode": ph.mode, "regime": ph.regime, "t_start": ph.t_start, "t_end": ph.t_end}
                       for ph in self.phases],
            "events": [e.to_dict() for e in self.events],
            "counts": {"n_steps": self.n_steps, "n_rejected": self.n_rejected, "nfev": self.nfev,
                       "njev": self.njev, "n_switches": self.n_switches, "n_events": len(self.events),
                       "n_points": self.rows.size},
            "extras": dict(self.extras), "units": dict(self.series),
        }

    def to_dataframe(self):
        """The output points as a pandas DataFrame: one column per series (SI; units in
        ``df.attrs["units"]``), mode and regime names; the scalars in ``df.attrs``."""
        import pandas as pd

        regime = self.model.get("mode_regime", self.mode_names)
        df = pd.DataFrame({name: getattr(self, name) for name, _ in self.series})
        df["mode"] = [self.mode_names[m] for m in self.mode]
        df["regime"] = [regime[m] for m in self.mode]
        df.attrs.update(self.to_dict())
        return df

    @property
    def sol_names(self) -> tuple[str, ...]:
        """The states ``sol`` gives, in its order: x1, v1, then the scene's others (gap, gap_rate, x3, v3)."""
        names = state_names(self.rows.module, self.rows.steps.y_a.shape[1])
        return ("x1", "v1", *(name for name in names if name not in ("x1", "v1")))

    def sol(self, t, side: str = "left") -> np.ndarray:
        """Every state at times t, one row each in the order of ``sol_names`` (x1, v1 first; shape
        (len(sol_names), len(t)), like solve_ivp's ``sol``): from the interpolant of the step that
        covers each time (the integrator's own dense output, the held equilibrium, the Painleve
        approach's in Sundman time), so as accurate as the run's steps at any t, whatever the output
        points. NaN outside [0, t_stop]. At an event's time its left limit (side "left", as the
        rows), or its right one ("right": after an impact's jump). ValueError for a run of more than
        MAX_LOGGED_STEPS steps (``results.rows``), which keeps no steps."""
        if side not in ("left", "right"):
            raise ValueError(f"side = {side!r}: must be 'left' or 'right'")
        if self.rows.written is not None:
            raise ValueError(f"sol: this run took {self.n_steps:,} steps, more than the {MAX_LOGGED_STEPS:,} "
                             f"kept for sol; its rows were written at the output points instead (raise points, "
                             f"or run shorter spans)")
        module = self.rows.module
        y, _ = states(self.rows.steps, len(module.STATES), np.atleast_1d(np.asarray(t, dtype=np.float64)).ravel(),
                      0 if side == "left" else 1)
        order = dict(zip(state_names(module, y.shape[1]), range(y.shape[1])))
        return y[:, [order[name] for name in self.sol_names]].T.copy()

    @classmethod
    def build(cls, record: RunRecord, run: dict, rows: Rows, final_state: dict, maxima: list, counts: list,
              t_stop: float) -> Result:
        """Assemble the result: what a caller reads at once from the run (``final_state``: the states and
        x1 at t_stop; ``maxima``: (|value|, value, t) of S1 and S2 in a row, as in record.mon; ``counts``:
        steps, rejected, rhs and jac calls, switches), the rest from ``record`` on first access."""
        return cls(record.module.SCENE, dict(run), rows, final_state, maxima[1], maxima[2], maxima[4], maxima[5],
                   STATUS_NAMES[record.code], t_stop, *counts, record)


def _events(module: ModuleType, log: EventLog, n_events: int) -> list[Event]:
    """The first ``n_events`` entries of an EventLog as Events."""
    n = len(module.STATES)
    at = 0 if module.STATES[0] == "x1" else n   # x1: state 0, or the integral of v1
    events = []
    for e in range(n_events):
        guard, from_mode, to_mode, piece = log.index[e].tolist()
        state = log.state[e].tolist()
        jump = log.jump[e].tolist()
        events.append(Event(float(log.t[e]), event_guard(module.GUARDS[guard], piece), module.MODES[from_mode],
                            module.MODES[to_mode] if to_mode >= 0 else None, state[at], state[n - 1],
                            None if math.isnan(jump[0]) else Jump(*jump), dict(zip(module.STATES, state[:n]))))
    return events


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
    if events and events[-1].jump is not None and events[-1].to_mode is None and events[-1].guard == "stem_gap":
        return (f"inconsistent at t = {t_stop:.9g} s: body 2 strikes the stem and the wedge jams: with the "
                f"friction angle there, the pickup impulse through the sliding wedge cannot stop the approach "
                f"(d(v3 - v2)/dP <= 0: the impulse counterpart of D <= 0), so no impulse satisfies Coulomb's "
                f"law; lower the friction or change the masses")
    if events and events[-1].jump is not None and events[-1].to_mode is None:
        flank = events[-1].guard[-1]
        return (f"inconsistent at t = {t_stop:.9g} s: the impact on flank {flank} jams: with the friction angle "
                f"there, the sliding impulse (friction against the slip) cannot stop the flanks' approach "
                f"(W_nn - mu sigma W_nt <= 0 in the flank's frame: the impact counterpart of D <= 0), so no "
                f"impulse satisfies Coulomb's law; the maxima of S1 and S2 are the finite peaks "
                f"reached before the impact; lower the friction or change the masses")
    name = module.MODES[last]
    g = np.empty(len(module.GUARDS))
    module.guards(last, t_stop, np.ascontiguousarray(y_stop, dtype=np.float64), p, g)
    value = {k: g[module.GUARDS.index(k)] for k in ("D", "jam") if k in module.GUARDS}
    formula = module.MODE_D[last] or "(none: the mode has no contact denominator)"
    reached = events and events[-1].guard in ("D", "jam") and events[-1].to_mode is None
    how = ("D fell to 0 in finite time (a1 -> -inf like the square root of the time left); the contact "
           "forces grow without bound there, so their maxima are +-inf" if reached
           else "the mode the state needs has D <= 0" + ("; the maxima of S1 and S2 are the finite peaks "
                                                         "reached before the stop" if events else ""))
    jam = f" and the jam factor cos(gamma + f s rho) = {value['jam']:.6g}" if "jam" in value else ""
    masses = ", ".join(f"{k} = {_value(module, p, k):.6g}" for k in ("m1", "m2", "gamma"))
    return (f"inconsistent at t = {t_stop:.9g} s in mode {name}: {how}; D = {formula} = "
            f"{value.get('D', math.nan):.6g}{jam}, so no finite contact force satisfies the constraint "
            f"(a Painleve-type case): the reactions are unbounded there; with {masses} (SI) "
            f"lower m2 or the friction, or raise m1")


def _indeterminate(module: ModuleType, t_stop: float, y_stop: np.ndarray, mask: int, p: np.ndarray,
                   at_start: bool) -> str:
    """Why the state at rest (at the start, ``at_start``, or where v1 reached 0 or a law changed while
    sticking) has no mode or several: the modes whose contact conditions hold (``mask``, bit 1 << mode),
    with D where a mode has one."""
    held = [m for m in range(len(module.MODES)) if mask >> m & 1]
    where = (f"indeterminate at t = {t_stop:.9g} s (the start: nothing was integrated, so S1 and S2 have no "
             f"maxima; the state is the initial one)" if at_start else f"indeterminate at t = {t_stop:.9g} s")
    if not held:
        return (f"{where}: at rest, no mode meets the contact conditions (stick: both "
                f"friction cones hold; sliding: D > 0, contact force >= 0, a1 the way it slides; parting: free "
                f"flight opens the gap): the forces lie on a boundary between them within rounding; change a "
                f"force or the friction slightly")
    g = np.empty(len(module.GUARDS))
    described = []
    for m in held:
        module.guards(m, t_stop, np.ascontiguousarray(y_stop, dtype=np.float64), p, g)
        d = f" (D = {module.MODE_D[m]} = {g[module.GUARDS.index('D')]:.6g})" if module.MODE_D[m] else ""
        described.append(module.MODES[m] + d)
    return (f"{where}: at rest, the contact conditions hold in several modes: "
            f"{', '.join(described)}; a mode with D <= 0 is a Painleve-type solution (contact force >= 0 only "
            f"because D < 0), so rigid contact with friction does not say how the motion starts; lower m2 or "
            f"the friction, or raise m1")


def first_non_finite(t: np.ndarray, columns: dict[str, np.ndarray]) -> tuple[str, float, float] | None:
    """(name, time, value) of the earliest inf or NaN among ``columns`` (each sampled at ``t``), or None."""
    found = None
    for name, values in columns.items():
        if math.isfinite(np.add.reduce(values, axis=None)):   # inf and NaN propagate: all finite (2 us, not 10)
            continue
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size and (found is None or t[bad[0]] < found[1]):
            found = (name, float(t[bad[0]]), float(values[bad[0]]))
    return found


def _quantity(name: str, value: float) -> str:
    return f"{name} = {value:.6g} {UNITS.get(name, '')}".rstrip()


def _not_finite(t_stop: float, found: tuple[str, float, float] | None,
                last_values: tuple[float, dict] | None) -> str:
    """Which quantity became inf or NaN, when, and the likely cause. ``found``: the first non-finite
    value of the run; None: the integrator stopped because every step tried from t_stop met one;
    then ``last_values``: (time, values by name) at the last output point, for the scale reached."""
    if found is not None:
        name, t, value = found
        return f"{_quantity(name, value)} at t = {t:.9g} s: not finite; likely cause: {NOT_FINITE_CAUSE}"
    where = ""
    if last_values is not None:
        t, values = last_values
        where = f"; at t = {t:.9g} s " + ", ".join(_quantity(name, v) for name, v in values.items())
    return (f"a state's rate or a guard is not finite just after t = {t_stop:.9g} s (every step tried from "
            f"there met inf or NaN){where}; likely cause: {NOT_FINITE_CAUSE}")


def status_message(module: ModuleType, status: int, t_stop: float, y_stop: np.ndarray, last: int,
                   need: int, events: list[Event], p: np.ndarray, *,
                   found: tuple[str, float, float] | None = None, last_values: tuple[float, dict] | None = None) -> str:
    """A sentence saying how the run ended, naming what to change when it failed. For a run that
    ended not-finite, ``found``: its first non-finite value (``first_non_finite``), else
    ``last_values``: (time, values by name) at its last output point."""
    if status == hybrid.FINISHED:
        changes = sum(1 for e in events if e.to_mode != e.from_mode)
        others = len(events) - changes
        return (f"reached t_end = {t_stop:.9g} s with {plural(changes, 'mode change')}"
                + (f" and {plural(others, 'other event')}" if others else ""))
    declared = [m for m, d in zip(module.MODES, getattr(module, "MODE_DECLARED", [True] * len(module.MODES))) if d]
    at = f"t = {t_stop:.9g} s"
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
    if status == hybrid.INDETERMINATE:
        return _indeterminate(module, t_stop, y_stop, need, p, not events)
    if status == hybrid.CHATTERING:
        return f"{hybrid.MAX_SAME_TIME} mode changes at {at} without time advancing (chattering); stopped"
    if status == hybrid.TOO_MANY_EVENTS:
        return f"the event log is full ({plural(len(events), 'event')}) at {at}; raise max_events"
    if status == hybrid.MAX_STEPS:
        return f"max_steps step attempts used up at {at}; raise max_steps or loosen rtol"
    if status == hybrid.STEP_TOO_SMALL:
        return f"the step size fell below the resolution of t at {at} (a singularity?)"
    if status == hybrid.NOT_FINITE:
        return _not_finite(t_stop, found, last_values)
    return "invalid input to the integrator"
