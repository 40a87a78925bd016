"""Simulate a chain of wedge stages: settings checked, the chain run (``chains.run``), and per stage
its regimes, switch times and force maxima.

``simulate_chain(module)`` takes a chain module (``model.scenes.load_chain_model``); its run starts
at q0 = 0 with the scene's v0. A stage's regime in a phase is tractive or inverse-tractive on the
flank it loads, or resting; its forces while the chain rests are statically undetermined for two
stages or more (the decision gives their admissible intervals) and are not counted in the maxima.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from functools import cached_property
from types import ModuleType

import numpy as np

from tswm_runtime.chains.run import RESTING, ChainRun, clearance_stages, prepare, run_prepared
from tswm_runtime.common.memo import overrides_key, remember
from tswm_runtime.results.rows import output_times
from tswm_runtime.simulation.chain_values import chain_values
from tswm_runtime.simulation.drive_train import UNITS, drive_train_lines
from tswm_runtime.simulation.drive_train import answers as drive_train_answers
from tswm_runtime.simulation.simulate import (ATOL_RANGE, DEFAULT_MAX_EVENTS, DEFAULT_POINTS, MAX_EVENTS, MAX_POINTS,
                                              MAX_STEPS, RTOL_RANGE, _check, _finite)

FORCES = ("input", "output", "normal")     # per stage: on its input body, on its output body, normal force


@dataclass(frozen=True)
class StagePhase:
    regime: str                  # "tractive", "inverse-tractive" or "resting"
    flank: str                   # "a", "b", or "" at rest
    t_start: float
    t_end: float


@dataclass(frozen=True)
class Peak:
    value: float                 # signed, largest in magnitude
    t: float


@dataclass(frozen=True)
class StageSummary:
    kind: str
    phases: tuple[StagePhase, ...]
    switches: tuple[float, ...]  # times its regime or flank changes
    peaks: dict                  # FORCES -> Peak over the sliding phases (None: it never slid)


@dataclass(frozen=True)
class ChainResult:
    """One chain run; its per-stage summaries, the drive train's answers and the samples' table are
    built from the run on first access (a caller that reads the outcome alone never builds them)."""

    scene: str
    status: str
    message: str
    t_stop: float
    events: tuple[EventRow, ...]  # t, guard, from, to (None: stop), outcome, reason
    t: np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    n_steps: int
    run: ChainRun = field(repr=False, compare=False)
    module: ModuleType = field(repr=False, compare=False)
    voltage: float | None = None  # the run's U / U_n (None: the scene's)

    @cached_property
    def stages(self) -> tuple[StageSummary, ...]:
        """Per stage its regimes, switch times and force peaks while sliding."""
        peaks = _peaks(self._sliding, self.module.STAGES)
        return tuple(_stage(self.module, self.run, k, peaks[k]) for k in range(self.module.STAGES))

    @cached_property
    def answers(self) -> dict:
        """The drive train's: trip, peak after it, extra travel, hold, stall margin."""
        return drive_train_answers(self.module, self.run, self.voltage)

    @cached_property
    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(t, q0, v0, stage forces, the last body's coordinate) of the sliding phases' samples, NaN between
        phases."""
        return _samples(self._sliding, self.module.STAGES)

    @property
    def p(self) -> np.ndarray:
        """p at the start: latches, the scene's values as run, derived slots."""
        return self.run.p

    @property
    def _sliding(self) -> list:
        return [phase for phase in self.run.phases if phase.mode != RESTING]

    @property
    def trip(self) -> dict | None:
        """t, thrust (the last stage's force on the last body), drive (body 0's torque), travel at the cut."""
        return self.answers["trip"] if self.answers else None

    def to_dict(self) -> dict:
        """The summary as plain data (no arrays)."""
        return {"scene": self.scene, "status": self.status, "message": self.message, "t_stop": self.t_stop,
                "stages": [asdict(s) for s in self.stages], "events": [dict(e) for e in self.events],
                "n_steps": self.n_steps,
                "answers": self.answers,
                **({"impacts": self.run.impacts} if clearance_stages(self.module) else {})}


def settings(module: ModuleType, overrides: dict) -> dict:
    """The chain scene's run settings with ``overrides`` applied, validated, naming a bad one; remembered
    per module and overrides (their types included: True is no valid 1), so that repeated calls are
    checked once."""
    try:
        key = (module.__name__, module.SCENE_DIGEST, overrides_key(overrides))
        known = _SETTINGS.get(key)
    except TypeError:   # an unhashable value: checked (and refused) below
        key, known = None, None
    if known is not None and known[0] is module:
        return dict(known[1])
    run = _checked(module, overrides)
    if key is not None:
        remember(_SETTINGS, key, (module, dict(run)))
    return run


_SETTINGS: dict = {}


def _checked(module: ModuleType, overrides: dict) -> dict:
    run = {**module.RUN, "points": DEFAULT_POINTS, "max_events": DEFAULT_MAX_EVENTS, "voltage": None}
    for key, value in overrides.items():
        _check(key in run, "setting", key, lambda: f"one of {', '.join(run)}")
        if value is not None:
            run[key] = value
    for key in ("t_end", "v0", "rtol", "atol"):
        run[key] = _finite(key, run[key])
    if run["voltage"] is not None:
        run["voltage"] = _finite("voltage", run["voltage"])
        _check(hasattr(module, "MOTOR_VOLTAGE"), "voltage", run["voltage"], "for a chain with a motor on body 0")
        _check(0.0 < run["voltage"] <= 2.0, "voltage", run["voltage"], "U / U_n in (0, 2]")
    _check(run["t_end"] > 0.0, "t_end", run["t_end"], "> t0 = 0 s")
    _check(RTOL_RANGE[0] <= run["rtol"] <= RTOL_RANGE[1], "rtol", run["rtol"], f"in [{RTOL_RANGE[0]:g}, "
           f"{RTOL_RANGE[1]:g}]")
    _check(ATOL_RANGE[0] <= run["atol"] <= ATOL_RANGE[1], "atol", run["atol"], f"in [{ATOL_RANGE[0]:g}, "
           f"{ATOL_RANGE[1]:g}]")
    for key, top in (("max_steps", MAX_STEPS), ("points", MAX_POINTS), ("max_events", MAX_EVENTS)):
        _check(isinstance(run[key], int) and not isinstance(run[key], bool) and 1 <= run[key] <= top, key,
               run[key], f"an integer in [1, {top:g}]")
    return run


def simulate_chain(module: ModuleType, params: dict | None = None, method: int = 0, **overrides) -> ChainResult:
    """One run of a chain module by ``method`` (segment.DOPRI5 or ROSENBROCK23); ``params`` replace the
    scene's values by name (PARAM_NAMES and ``voltage``, the motor's U / U_n; numbers in SI or strings with
    a unit, checked as the scene reader checks them); t_end, v0, rtol, atol, max_steps, points, max_events
    and voltage override the scene's run."""
    run, t_out, prepared = _plan(module, params, method, overrides)
    result = run_prepared(module, prepared, t_out.copy(), run["max_events"])   # the remembered times are read-only
    return ChainResult(module.SCENE, result.status, result.message, result.t_stop, _events(module, result), result.t,
                       result.y[:, 0], result.y[:, 1], result.n_steps, result, module, run["voltage"])


def _plan(module: ModuleType, params: dict | None, method: int, overrides: dict) -> tuple[dict, np.ndarray, tuple]:
    """(the run's settings, its output times, what ``run_prepared`` takes): remembered per module, method and
    overrides for the scene's values, so that a repeated call goes to the run at once (building them cost
    about a tenth of a short run, several times that right after other code has run)."""
    try:
        key = None if params else (module.__name__, module.SCENE_DIGEST, method, overrides_key(overrides))
        known = _PLANS.get(key) if key else None
    except TypeError:   # an unhashable value: checked (and refused) by ``settings``
        key, known = None, None
    if known is not None and known[0] is module:
        return known[1]
    values, voltage = chain_values(module, params)
    run = settings(module, {**overrides, **({"voltage": voltage} if voltage is not None else {})})
    plan = (run, output_times(run["t_end"], run["points"]),
            prepare(module, t_end=run["t_end"], v0=run["v0"], rtol=run["rtol"], atol=run["atol"], method=method,
                    max_steps=run["max_steps"], voltage=run["voltage"], values=values))
    if key:
        remember(_PLANS, key, (module, plan))
    return plan


_PLANS: dict = {}


def _samples(sliding: list, stages: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The sliding phases' samples as arrays (t, q0, v0, forces with 3 columns per stage, the last body's
    coordinate), a NaN row after each phase so that plotted lines break where the chain rests or a force jumps."""
    width = 4 + 3 * stages
    breaks = np.full((len(sliding), width), np.nan)
    breaks[:, 0] = [phase.t_end for phase in sliding]
    table = np.concatenate([part for j, phase in enumerate(sliding) for part in (phase.table, breaks[j:j + 1])]
                           or [np.empty((0, width))])
    return table[:, 0], table[:, 1], table[:, 2], table[:, 3:-1], table[:, -1]


def _peaks(sliding: list, stages: int) -> list[dict]:
    """Per stage, FORCES -> Peak over the sliding phases' maxima (the kernel's, of the continuous solution; None:
    it never slid): the first phase's of largest magnitude; a NaN (a force undetermined in a whole phase, a stuck
    group's) is never the peak, unless all are NaN (then its time is NaN too)."""
    m = 3 * stages
    maxima = np.array([phase.peaks for phase in sliding]).reshape(-1, 2 * m)
    if maxima.shape[0] == 0:
        return [dict.fromkeys(FORCES) for _ in range(stages)]
    forces = maxima[:, :m]
    size = np.abs(forces)
    size[np.isnan(size)] = -1.0
    rows, columns = np.argmax(size, axis=0), np.arange(m)
    values, times = forces[rows, columns].tolist(), maxima[rows, m + columns].tolist()
    return [{name: Peak(values[3 * k + j], times[3 * k + j]) for j, name in enumerate(FORCES)} for k in range(stages)]


def plot(result: ChainResult, module: ModuleType, path) -> object:
    """The run's figure (results/chain_plot.py): travel and speed, each stage's forces, the trip."""
    from tswm_runtime.results.chain_plot import plot_stages

    t, _, v0, forces, travel = result.samples
    stages = [(f"stage {k + 1} ({module.STAGE_KINDS[k]})", UNITS[module.BODY_MOTIONS[k]],
               UNITS[module.BODY_MOTIONS[k + 1]]) for k in range(module.STAGES)]
    clear, gap = clearance_stages(module), None
    if len(clear) == 1:   # the stage's gap from the output rows
        gap = (clear[0] - 1, result.run.t, gaps(module, result))
    return plot_stages(path, f"{module.SCENE}: {result.status}", t, travel, v0, forces, stages,
                       result.trip["t"] if result.trip else None, gap)


def gaps(module: ModuleType, result: ChainResult) -> np.ndarray:
    """The normal gap of the stage with a clearance (of a chain with one) at the output rows (NaN after a stop): the
    module's open-phase guard gap_a, which depends on the coordinates and the scene's values only."""
    g, index, p = np.empty(len(module.GUARDS)), module.GUARDS.index("gap_a"), result.p.copy()
    out = np.full(result.run.t.size, np.nan)
    for i, (t, y) in enumerate(zip(result.run.t.tolist(), result.run.y)):
        if np.isfinite(y).all():
            module.guards(module.OPEN, t, np.ascontiguousarray(y), p, g)
            out[i] = g[index]
    return out


def _regime(module: ModuleType, phase, k: int) -> tuple[str, str]:
    """Stage k's (0-based) regime and flank in a phase: resting, open (the stage with the clearance while its
    flanks are apart; the other stages' regimes then are the phase's latches, resting in a group stuck at rest),
    or the mode's."""
    mode = phase.mode
    if mode == RESTING:
        return "resting", ""
    if clearance_stages(module) and mode >= module.OPEN:
        p = phase.latches
        opened = clearance_stages(module)[int(p[module.P_CURRENT])]
        if k + 1 == opened:
            return "open", ""
        before = k + 1 < opened
        if p[module.P_HELD_IN if before else module.P_HELD_OUT] > 0.0:
            return "resting", ""    # its group stuck at rest
        sign = p[module.P_RHO_SIGN + k]
        direction = p[module.P_DIRECTION_IN if before else module.P_DIRECTION_OUT]
        return ("tractive" if sign > 0 else "inverse-tractive"), ("a" if sign * direction > 0 else "b")
    return module.MODE_REGIMES[mode][k], module.MODE_FLANKS[mode][k]


def _stage(module: ModuleType, run: ChainRun, k: int, peaks: dict) -> StageSummary:
    phases: list[StagePhase] = []
    for phase in run.phases:
        regime, flank = _regime(module, phase, k)
        if phases and (phases[-1].regime, phases[-1].flank) == (regime, flank):
            phases[-1] = StagePhase(regime, flank, phases[-1].t_start, phase.t_end)
        else:
            phases.append(StagePhase(regime, flank, phase.t_start, phase.t_end))
    return StageSummary(module.STAGE_KINDS[k], tuple(phases), tuple(p.t_start for p in phases[1:]), peaks)


class EventRow(Mapping):
    """An event as plain data: t, guard, from, to (None: stop), outcome, reason; read from the run's event rows,
    the reason from its event when asked for, so a run read for its numbers never builds its events nor
    evaluates the reason (the Python decision's words)."""

    KEYS = ("t", "guard", "from", "to", "outcome", "reason")
    __slots__ = ("_module", "_run", "_index", "_row")

    def __init__(self, module: ModuleType, run: ChainRun, index: int, row: tuple):
        self._module, self._run, self._index, self._row = module, run, index, row

    def _mode(self, mode):
        return None if mode is None else ("resting" if mode == RESTING else self._module.MODES[mode])

    def __getitem__(self, key):
        t, guard, before, after, outcome = self._row
        if key == "t":
            return t
        if key == "guard":
            return guard
        if key == "from":
            return self._mode(before) if guard != "start" else None
        if key == "to":
            return self._mode(after)
        if key == "outcome":
            return outcome
        if key == "reason":
            return self._run.events[self._index].decision.reason
        raise KeyError(key)

    def __iter__(self):
        return iter(self.KEYS)

    def __len__(self):
        return len(self.KEYS)

    def __repr__(self):
        return f"EventRow({ {key: self[key] for key in self.KEYS[:-1]} })"


def _events(module: ModuleType, run: ChainRun) -> tuple[EventRow, ...]:
    return tuple([EventRow(module, run, e, row) for e, row in enumerate(run.event_rows)])


def impact_lines(run: ChainRun, module: ModuleType) -> list[str]:
    """The impacts of the stages with a clearance: time, (with several: the stage,) flank, normal speed of approach
    and of rebound at the flank, kinetic energy lost, and whether the stage closed; nothing for a rigid chain."""
    stages = clearance_stages(module)
    if not stages:
        return []
    lines = [f"  stage {', '.join(map(str, stages))} impacts ({len(run.impacts)}):"]
    for row in run.impacts:
        at = f"stage {row['stage']:.0f} " if len(stages) > 1 else ""
        lines.append(f"    t = {row['t']:.9g} s {at}on flank {row['flank']}: normal speed {row['nu before']:.6g} -> "
                     f"{row['nu after']:.6g} (SI), energy lost {row['energy lost']:.6g} J, "
                     + ("closed" if row["closed"] else "rebounds"))
    return lines


def summary(result: ChainResult, module: ModuleType) -> list[str]:
    """The run at a glance, as printed by ``tswm simulate``: status, per stage its regimes, switch
    times and force maxima, the events with the decisions' outcomes (and their reasons where not unique, at
    rest of two stages or more, and at every event of a chain with a clearance)."""
    lines = [f"  status: {result.status}" + (f": {result.message}" if result.message else ""),
             f"  t_stop = {result.t_stop:.9g} s, steps {result.n_steps}"]
    for k, stage in enumerate(result.stages):
        lines.append(f"  stage {k + 1} ({stage.kind}, body {k} -> body {k + 1}):")
        lines += [f"    {p.regime:<17} {p.flank or '-':<2} {p.t_start:.9g} s .. {p.t_end:.9g} s" for p in stage.phases]
        lines.append("    switches at: " + (", ".join(f"{t:.9g} s" for t in stage.switches) or "none"))
        units = (UNITS[module.BODY_MOTIONS[k]], UNITS[module.BODY_MOTIONS[k + 1]], "N")
        for (name, peak), unit in zip(stage.peaks.items(), units):
            shown = "- (never slid)" if peak is None else f"{abs(peak.value):.6g} {unit} at t = {peak.t:.6g} s" + (
                f" (the force is {peak.value:.6g} {unit})" if peak.value < 0 else "")
            lines.append(f"    max |{name} force| while sliding: {shown}")
    lines += impact_lines(result.run, module)
    lines += drive_train_lines(result.answers, module)
    lines.append(f"  decisions ({len(result.events)}):")
    for e in result.events:
        lines.append(f"    t = {e['t']:.9g} s, {e['guard']}: {e['from'] or '(start)'} -> {e['to'] or '(stop)'} "
                     f"[{e['outcome']}]")
        if e["outcome"] != "unique" or (e["to"] == "resting" and module.STAGES > 1) or clearance_stages(module):
            lines.append(f"      {e['reason']}")
    return lines
