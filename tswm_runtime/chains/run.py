"""A rigid chain of wedge stages run in one compiled call (``kernel.run_chain_at``); here the
Python that builds its result.

A chain module (derivation/chain/codegen.py) has one coordinate q0 and a sliding mode per direction
and combination of the stages' flanks. The kernel integrates one mode at a time with the mode
machine's segment kernel and stops it at the first chain event: D (the Painleve approach locates
D = 0), the stages' jam factor and each stage's normal force, v0, the seat's contact, the torque
switch and its delay. At each it decides the next mode in compiled code (``rules``) for
all stages at once by the complementarity logic the derivation uses (tswm_common/chain_decision.py):
a flank change, breakaway or rest; no mode or several (a Painleve-type case) stop the run. D or the
jam factor reaching 0 stops it too (no contact force keeps the stages together).

The torque switch and the valve's seat are latches in the parameter vector p (the module's P_NAMES; after
them the scene's values, what the module's ``prepare`` derives from them and the motor's table, which
``latches`` copies in from the module's MOTOR_SPEED and MOTOR_TORQUE; the compiled decision reads them
through the slots in ``chain_tables``): at their events the seat's contact flips, the switch picks up
(its delay starts), drops out (below setting - hysteresis) or trips (the motor is cut for good); then the
mode is decided again with the new forces. A resting chain stays at rest: its forces depend on q0
(springs, the seat) and v0 (a motor's table), which rest with it, except when a picked-up switch's delay
ends while it rests: the motor is cut then and the chain decided again. While it rests, the switch sees
body 0's drive torque; a switch on a stage's force keeps its state (the split of a resting chain's forces
is statically undetermined).

Each event keeps the state and latches its decision saw; its ``decision`` (with the reason in words
and, at rest, the admissible internal forces) is the Python decision (``decide``) evaluated there on
first access, which tests/test_chain_kernel.py checks against the compiled one.

Each sliding phase keeps the stage forces at its ends and at the output points inside it (its samples) and
their peaks: per force the largest |value| of the continuous solution in the phase and its time (``Phase.peaks``;
how the kernel finds them, at a phase end without a powered motor, monitored and refined on the dense output
while it runs: kernel.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np

from tswm_common.chain_decision import Candidate, Decision, Statics, decide_numbers
from tswm_runtime.common.memo import remember
from tswm_runtime.jit import coldstart

coldstart.announce(("integrate", "chain"))  # before the next imports compile the kernels, if not cached

from tswm_runtime.chains import rules as compiled  # noqa: E402
from tswm_runtime.chains import kernel  # noqa: E402
from tswm_runtime.chains.backlash import IMPACT_COLUMNS  # noqa: E402
from tswm_runtime.hybrid import entry  # noqa: E402
from tswm_runtime.integration import segment  # noqa: E402
from tswm_runtime.jit.cache_guard import entry_point  # noqa: E402
from tswm_runtime.jit.signatures import GUARDS_SIG, address  # noqa: E402
from tswm_runtime.jit.structures import EventLog, Outputs, Record, StepLog  # noqa: E402

RESTING = compiled.RESTING   # the mode index of the resting chain (no mode of the module)
STATUS = {segment.STEP_TOO_SMALL: "step-too-small", segment.MAX_STEPS: "max-steps",
          segment.NOT_FINITE: "not-finite", segment.INVALID_INPUT: "invalid-input",
          kernel.TOO_MANY_EVENTS: "too-many-events", kernel.CHATTERING: "chattering"}


@dataclass
class Phase:
    """A stretch of the run in one mode (RESTING: at rest), with the stage forces sampled in it and their maxima."""

    mode: int
    t_start: float
    t_end: float
    latches: np.ndarray                          # p in the phase: switch state, pick-up time, seated
    table: np.ndarray = field(default_factory=lambda: np.empty((0, 4)), repr=False)  # rows (t, q0, v0, forces, q_N)
    peaks: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)  # the forces' maxima, then their times

    @property
    def samples(self) -> list:
        """(t, y, stage_forces) at its ends and output points (sliding phases; none at rest)."""
        return [(float(row[0]), row[1:3], row[3:-1]) for row in self.table]


@dataclass
class ChainEvent:
    """What happened at time t: the guard that fired (or "start"), the modes before and after, the compiled
    decision's outcome; ``decision`` (with its reason) is the Python decision at the state and latches it
    saw, evaluated on first access."""

    t: float
    guard: str
    from_mode: int
    to_mode: int | None          # None: the run stops here
    outcome: str
    at: tuple = field(default=(), repr=False)  # (module, the run's chain record, its row): what the decision saw
    given: Decision | None = field(default=None, repr=False)

    @property
    def seen(self) -> tuple:
        """(module, y, p) the decision saw, views into the run's record; () when given."""
        if not self.at:
            return ()
        module, chain, row = self.at
        n = len(module.STATES)
        return module, chain.event_f[row, 1:1 + n], chain.event_f[row, 1 + n:1 + n + len(module.P_NAMES)]

    @cached_property
    def decision(self) -> Decision:
        if self.given is not None:
            return self.given
        if clearance_stages(self.seen[0]):
            return _clearance_decision(self)
        return decide(self.seen[0], self.t, *self.seen[1:])


class ChainRun:
    """A chain run: status, message, t_stop, the output times t and states y there (NaN after a stop), the
    steps taken (accepted and rejected), the trip (t, y, mode, stage forces (None at rest), drive just before
    the switch cut the motor; None: no cut), p at the start (latches, values, derived slots), the kernel's status
    code and the chain record the run wrote; its phases and events (and the events' plain rows) are read from that
    record (views into it) on first access."""

    def __init__(self, module, code: int, t_stop: float, record: Record, chain: kernel.ChainRecord):
        self._module = module
        self.code, self.record = int(code), chain   # the kernel's status code and the chain record the run wrote
        self.status, self.message, self.t_stop = run_status(code), "", float(t_stop)
        self.t, self.y = record.out.t, record.out.y
        counters = record.counters
        self.n_steps = int(counters[segment.N_STEPS] + counters[segment.N_REJECTED])
        self.trip = _trip(module, chain.trip)
        self.p: np.ndarray | None = None

    @cached_property
    def phases(self) -> list[Phase]:
        chain = self.record
        phase_f = chain.phase_f
        n_phases = int(chain.counts[0])
        times = phase_f[:n_phases, :2].tolist()
        return [Phase(mode, *times[j], phase_f[j, 2:], chain.samples[s0:s1], chain.peaks[j])
                for j, (mode, s0, s1) in enumerate(chain.phases[:n_phases].tolist())]

    @cached_property
    def impacts(self) -> list[dict]:
        """The flanks' impacts of the stages with a clearance (backlash.IMPACT_COLUMNS; flank "a" or "b", closed:
        whether the stage stayed closed after it)."""
        return [_impact_row(row) for row in self.record.impacts[:int(self.record.counts[3])].tolist()]

    @cached_property
    def event_rows(self) -> list[tuple]:
        """Per event (t, guard, from_mode, to_mode (None: stop), outcome), plain numbers and words: what
        ``events`` are built from, cheaper to read when their decisions are not needed."""
        module, chain = self._module, self.record
        n_events = int(chain.counts[2])
        times = chain.event_f[:n_events, 0].tolist()
        return [(times[e], "start" if guard == compiled.START else module.GUARDS[guard], before,
                 None if after == compiled.NO_MODE else after, compiled.OUTCOMES[outcome])
                for e, (guard, before, after, outcome) in enumerate(chain.events[:n_events].tolist())]

    @cached_property
    def events(self) -> list[ChainEvent]:
        at = self._module, self.record
        return [ChainEvent(*row, (*at, e)) for e, row in enumerate(self.event_rows)]


def latches(module, y: np.ndarray, voltage: float | None = None, values: np.ndarray | None = None) -> np.ndarray:
    """The complete p at the start: the switch armed, the motor's voltage U / U_n (the scene's unless given),
    the scene's values (PARAM_DEFAULTS unless ``values``, one per PARAM_NAMES, in SI), the slots derived
    from them (the module's ``prepare``), the motor's table (MOTOR_SPEED, MOTOR_TORQUE) and the seat pressed
    if the last body starts at or beyond it."""
    prepared = _parts(module).prepared if values is None else {}   # the scene's values: remembered per voltage
    known = prepared.get(voltage)
    if known is None:
        known = np.zeros(len(module.P_NAMES))
        known[module.P_VOLTAGE] = getattr(module, "MOTOR_VOLTAGE", 1.0) if voltage is None else voltage
        known[module.P_VALUES:module.P_DERIVED] = module.PARAM_DEFAULTS if values is None else values
        if hasattr(module, "MOTOR_POINTS"):
            known[module.P_MOTOR_SPEED:module.P_MOTOR_SPEED + module.MOTOR_POINTS] = module.MOTOR_SPEED
            known[module.P_MOTOR_TORQUE:module.P_MOTOR_TORQUE + module.MOTOR_POINTS] = module.MOTOR_TORQUE
        module.prepare(known)
        remember(prepared, voltage, known, 64)
    p = known.copy()
    p[module.P_SEATED] = float(module.HAS_SEAT and p[module.P_SPEED + module.STAGES] * y[0] >= p[module.P_SEAT])
    stages = clearance_stages(module)
    if stages:
        contacts = [start_contact(module, p, k) for k in stages]
        p[module.P_CONTACT:module.P_CONTACT + len(stages)] = contacts
        p[module.P_GAP:module.P_GAP + len(stages)] = [p[getattr(module, f"V_gap_{k}")] for k in stages]
        current = contacts.index(0.0) if 0.0 in contacts else 0
        p[module.P_CURRENT], p[module.P_SPEED_CUR] = current, p[module.P_SPEED + stages[current]]
    return p


def start_contact(module, p: np.ndarray, k: int) -> float:
    """Stage k (with a clearance) at the start: closed on flank a (gap 0, +1), on flank b (gap = clearance, -1),
    else open (0)."""
    gap, clearance = p[getattr(module, f"V_gap_{k}")], p[getattr(module, f"V_clearance_{k}")]
    return 1.0 if gap <= 0.0 else -1.0 if gap >= clearance else 0.0


def numbers(module, p: np.ndarray) -> Statics:
    """What p's derived slots say of the chain: per stage (Psi_t, Psi_i) and its levers, the valve's friction
    magnitude (the forces left empty)."""
    n = module.STAGES
    psi = tuple((float(p[module.P_PSI + 2 * k]), float(p[module.P_PSI + 2 * k + 1])) for k in range(n))
    return Statics(psi, tuple(float(x) for x in p[module.P_LEVER_IN:module.P_LEVER_IN + n]),
                   tuple(float(x) for x in p[module.P_LEVER_OUT:module.P_LEVER_OUT + n]), (),
                   float(p[module.P_SLACK]))


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


def decide(module, t: float, y: np.ndarray, p: np.ndarray, flank: float = 0.0) -> Decision:
    """The chain's mode at (t, y) under latches p: every candidate in the direction of v0 (both at rest),
    and rest (the valve's friction holding anything up to its magnitude). With a clearance closed on ``flank``
    (+1 a, -1 b) (the current clearance stage's): the candidates loading that flank, and rest with the stage
    pushing on it only; the other stages with a clearance on their flanks in contact (p's latches)."""
    v = y[1]
    directions = (1, -1) if v == 0 else ((1,) if v > 0 else (-1,))
    statics = replace(numbers(module, p), force=tuple(float(f) for f in module.body_forces(t, y, p, 0.0)))
    candidates = _candidates(module, t, y, p, directions)
    if flank:
        sides = {k: float(p[module.P_CONTACT + i]) for i, k in enumerate(clearance_stages(module))}
        sides[clearance_stages(module)[int(p[module.P_CURRENT])]] = flank
        loaded = {module.MODES[m] for m, flanks in enumerate(module.MODE_FLANKS)
                  if flanks and all(flanks[k - 1] == FLANKS[side] for k, side in sides.items())}
        candidates = [c for c in candidates if c.name in loaded]
        statics = replace(statics, flanks=tuple((k - 1, int(side)) for k, side in sides.items()))
    return decide_numbers(candidates, v, statics)


FLANKS = {1.0: "a", -1.0: "b"}


def _clearance_decision(event: ChainEvent) -> Decision:
    """The reason of an event of a chain with clearances, about the current clearance stage k (the one open, or
    last opened): the rigid decision with the flank constraints while the stages are closed (``decide`` with the
    flank in contact); where it opens, which flank and why (its normal force reached 0, or no mode loading that
    flank holds and the chain cannot rest); at an impact, the flank, the normal speed before and after and whether
    the stage closed; in the open phase, each group's direction and the closed stages' regimes (the latches the
    compiled decision set); a second stage that would open while k is open."""
    module, chain, row = event.at
    _, y, p = event.seen
    index = int(p[module.P_CURRENT])
    k = clearance_stages(module)[index]
    contact = module.P_CONTACT + index
    before = float(chain.event_f[row - 1, 1 + len(module.STATES) + contact]) if row else start_contact(module, p, k)
    words = []
    opened = event.from_mode is not None and event.from_mode >= module.OPEN
    if opened and event.to_mode is None and event.guard.startswith("N_"):
        return Decision(event.outcome, (), None, two_open(event.guard, k))
    if opened and event.guard in ("gap_a", "gap_b"):
        if event.to_mode is None:
            return Decision(event.outcome, (), None, f"stage {k}'s flanks meet on flank {event.guard[-1]} and the "
                            "impulse cannot stop their approach")
        hit = _impact(module, chain, row)
        words.append(f"stage {k}'s flanks meet on flank {hit['flank']}: normal speed {hit['nu before']:.6g} -> "
                     f"{hit['nu after']:.6g} m/s, " + ("closed (plastic, or its rebound within the tolerances)"
                                                        if hit["closed"] else "rebound: the flanks part again"))
        before = 1.0 if hit["flank"] == "a" else -1.0
        if not hit["closed"]:
            return Decision(event.outcome, (), None, f"{words[0]}; {_open_words(module, p)}")
    elif opened or (before == 0.0 and event.guard == "start"):
        words.append(f"stage {k} starts open (its flanks apart)" if event.guard == "start" else
                     f"{event.guard} in the open phase")
        before = 0.0
    if before == 0.0 or (event.to_mode is not None and event.to_mode >= module.OPEN):
        if event.to_mode is None:
            why = {"group at rest": "a group of bodies would stay at rest while the flanks are apart (its stick is not "
                                    "decided yet)", "several": "several open phases hold"}
            return Decision(event.outcome, (), None, "; ".join([*words, why.get(event.outcome, "no open phase holds")]))
        if before != 0.0:
            flank = FLANKS[before]
            if event.guard == f"N_{k}":
                words.append(f"stage {k}'s normal force on flank {flank} reached 0")
            else:
                closed = decide(module, event.t, y, p, before)
                words.append(f"no mode loading flank {flank} holds and the chain cannot rest with stage {k} pushing "
                             f"on it ({closed.reason})")
            words.append(f"its flanks part from flank {flank}")
        return Decision(event.outcome, (module.MODES[module.OPEN + index],), None,
                        "; ".join([*words, _open_words(module, p)]))
    closed = decide(module, event.t, y, p, before)
    words.append(f"stage {k} closed on flank {FLANKS[before]}: {closed.reason}")
    return Decision(closed.outcome, closed.modes, closed.accel, "; ".join(words), closed.internal)


def _impact(module, chain: kernel.ChainRecord, row: int) -> dict:
    """The impact of the gap event in ``row``: one impact row per gap event of the open phase, in order."""
    gaps = (module.GUARDS.index("gap_a"), module.GUARDS.index("gap_b"))
    i = sum(1 for guard, before in chain.events[:row, :2].tolist() if before >= module.OPEN and guard in gaps)
    return _impact_row(chain.impacts[i].tolist())


def _impact_row(row: list) -> dict:
    """An impact row (IMPACT_COLUMNS) in words: flank "a" or "b", closed: whether the stage stayed closed after it."""
    return {**dict(zip(IMPACT_COLUMNS, row)), "flank": "a" if row[1] > 0 else "b", "closed": row[5] > 0}


def _open_words(module, p: np.ndarray) -> str:
    """The open phase's latches in words: each group's direction (free: its forces do not depend on it; held: at rest,
    its own statics holding it), each closed stage's regime."""
    k, n = clearance_stages(module)[int(p[module.P_CURRENT])], module.STAGES
    names = {1.0: "forward", -1.0: "backward"}

    def group(index: int, held: int, direction: int) -> str:
        if compiled.free_group(index, k, n, p[module.P_SLACK]):
            return "free (its forces do not depend on its direction)"
        return "held at rest (its statics hold it)" if p[held] > 0.0 else names[float(p[direction])]

    regimes = [f"stage {i + 1} {'tractive' if p[module.P_RHO_SIGN + i] > 0 else 'inverse-tractive'}"
               for i in range(n) if i != k - 1]
    group_in = "body 0" if k == 1 else f"bodies 0..{k - 1}"
    group_out = f"body {n}" if k == n else f"bodies {k}..{n}"
    return (f"open phase: {group_in} {group(0, module.P_HELD_IN, module.P_DIRECTION_IN)}, {group_out} "
            f"{group(1, module.P_HELD_OUT, module.P_DIRECTION_OUT)}; closed stages: {', '.join(regimes) or 'none'}")


class _ModuleParts(NamedTuple):
    """What a chain module's runs share (``_parts``): the compiled decision's tables, the addresses of its
    stage_forces and body_forces_into, and the parts of a Record that a chain's run never writes (the event
    log, the step log's rows: a chain keeps its phases, samples and maxima in its own record;
    the output rows' modes and p), and p prepared from the scene's values (copied by each run)."""

    module: object
    digest: str
    tables: compiled.ChainTables
    functions: tuple[int, int, int]
    event_log: EventLog
    no_steps: tuple
    out_mode: np.ndarray
    out_p: np.ndarray
    prepared: dict      # voltage (None: the scene's) -> p with the scene's values prepared, the seat not yet set


def _parts(module) -> _ModuleParts:
    """The module's shared parts, built on its first run and remembered per module (its identity and its
    scene's digest: a module loaded again, or generated anew, gets its own)."""
    known = _PARTS.get(module.__name__)
    if known is None or known.module is not module or known.digest != module.SCENE_DIGEST:
        n_modes, n_p = len(module.MODES), len(module.P_NAMES)
        ints = dict(stages=module.STAGES, p_psi=module.P_PSI, p_lever_in=module.P_LEVER_IN,
                    p_lever_out=module.P_LEVER_OUT, p_slack=module.P_SLACK, switch_on=module.SWITCH_ON,
                    p_delay=module.P_DELAY, p_switch=module.P_SWITCH, p_pick=module.P_PICK, p_seated=module.P_SEATED)
        stages = clearance_stages(module)
        flank = {"a": 1, "b": -1}
        tables = compiled.ChainTables(
            direction=np.array(module.MODE_DIRECTION, np.int64),
            guard_direction=np.array(module.GUARD_DIRECTIONS, np.int64).reshape(n_modes, len(module.GUARDS)),
            **{k: int(v) for k, v in ints.items()}, armed=float(module.ARMED), picked=float(module.PICKED),
            tripped=float(module.TRIPPED),
            mode_contact=np.array([[flank[f[k - 1]] if f else 0 for k in stages] for f in module.MODE_FLANKS],
                                  np.int64).reshape(n_modes, len(stages)),
            open_mode=module.OPEN if stages else -1, clear_stage=np.array(stages, np.int64),
            **{name: getattr(module, slot) if stages else 0 for name, slot in (
                ("p_contact", "P_CONTACT"), ("p_direction", "P_DIRECTION_IN"), ("p_rho_sign", "P_RHO_SIGN"),
                ("p_gap", "P_GAP"), ("p_current", "P_CURRENT"), ("p_speed_k", "P_SPEED_CUR"))},
            p_speed=module.P_SPEED, motor=int(hasattr(module, "MOTOR_POINTS")))
        no_steps = (np.empty((0, 4)), np.empty((0, 2), np.int64), np.empty((0, 2)), np.empty((0, 2)),
                    np.empty((0, 3, 4)), np.empty(0, np.int64), np.empty((0, n_p)))
        known = _PARTS[module.__name__] = _ModuleParts(
            module, module.SCENE_DIGEST, tables,
            (address(module.stage_forces, GUARDS_SIG), address(module.body_forces_into, GUARDS_SIG),
             address(module.impact, GUARDS_SIG)),
            EventLog(np.empty(1), np.empty((1, 4), np.int64), np.empty((1, 2)), np.empty((1, 4))), no_steps, np.empty(0, np.int64), np.empty((0, n_p)), {})
    return known


_PARTS: dict = {}


def clearance_stages(module) -> tuple[int, ...]:
    """The stages with a clearance (1-based), () for a rigid chain."""
    return getattr(module, "CLEARANCE_STAGES", ())


def two_open(guard: str, k: int) -> str:
    """The words of a run stopped because stage j (the guard N_j) would open while stage k is open."""
    return f"stage {guard[2:]} opens while stage {k} is open: two open stages are not modelled"


def start_state(module, v0: float) -> np.ndarray:
    """The states at t = 0: q0 = 0 and v0; with clearances also qk = 0 and vk of the current clearance stage k (vk
    the kernel sets to c_k v0 of each run's p: the chain moves as one body)."""
    y0 = np.zeros(len(module.STATES))
    y0[1] = v0
    return y0


def chain_tables(module) -> compiled.ChainTables:
    """The compiled decision's tables of a chain module: its modes and the slots of p it reads (the numbers
    themselves are in each run's p)."""
    return _parts(module).tables


def chain_functions(module) -> tuple[int, int, int]:
    """The addresses of the module's stage_forces, body_forces_into and impact, as the kernel takes them."""
    return _parts(module).functions


def first_room(max_events: int) -> int:
    """The phases a run's record has room for at first (twice as many again while a run needs more)."""
    return min(max_events, 58) + 6


def samples_room(phases: int, points: int) -> int:
    """The samples a record of room for ``phases`` phases and ``points`` output times holds."""
    return points + 3 * phases


def _record(module, t_out: np.ndarray, phases: int, samples: int) -> tuple[Record, kernel.ChainRecord]:
    """A run's records: its own output rows, counters and chain record, the module's shared parts besides."""
    parts = _parts(module)
    forces = 3 * module.STAGES
    rows = np.empty((t_out.size, len(module.STATES)))
    rows.fill(np.nan)   # np.full costs three times as much
    out = Outputs(t_out, rows, parts.out_mode, parts.out_p)
    record = Record(out, parts.event_log, np.empty((forces, 3)), np.zeros(segment.N_COUNTERS, np.int64),
                    StepLog(*parts.no_steps, np.zeros(2, np.int64)))
    return record, kernel.chain_record(phases, samples, len(module.STATES), len(module.P_NAMES), module.STAGES)


def run_chain(module, *, t_end: float, v0: float, rtol: float, atol: float, t_out: np.ndarray,
              method: int = 0, max_steps: int = 100_000, max_events: int = 1000,
              voltage: float | None = None, values: np.ndarray | None = None) -> ChainRun:
    """Integrate the chain from q0 = 0, v0 to t_end through its mode changes and its switch's and seat's
    events; ``voltage`` (U / U_n) replaces the scene's motor voltage, ``values`` (one per PARAM_NAMES, SI,
    checked by the caller) the scene's values."""
    prepared = prepare(module, t_end=t_end, v0=v0, rtol=rtol, atol=atol, method=method, max_steps=max_steps,
                       voltage=voltage, values=values)
    return run_prepared(module, prepared, np.ascontiguousarray(t_out, dtype=np.float64), max_events)


def prepare(module, *, t_end: float, v0: float, rtol: float, atol: float, method: int, max_steps: int,
            voltage: float | None, values: np.ndarray | None) -> tuple[np.ndarray, tuple]:
    """What ``run_prepared`` takes of a run's settings: (p at the start, the kernel's arguments before it);
    never written by a run (a caller may keep them for later runs with the same settings)."""
    start = latches(module, np.zeros(2), voltage, values)   # the latches at q0 = 0 (y0's)
    y0 = start_state(module, float(v0))
    settings = entry.settings(int(method), y0.size, t_end=float(t_end), rtol=float(rtol), atol=float(atol),
                              max_steps=int(max_steps))
    return start, (entry.functions(method, module), chain_functions(module), chain_tables(module), settings, y0)


def run_prepared(module, prepared: tuple, t_out: np.ndarray, max_events: int) -> ChainRun:
    """``run_chain`` with its settings ``prepare``d; t_out float64 and contiguous, the run's own."""
    start, args = prepared
    phases = first_room(max_events)
    while True:   # a record too small for the run's phases and samples: again with twice the room
        p = start.copy()
        record, chain = _record(module, t_out, phases, samples_room(phases, t_out.size))
        code, t_stop = entry_point(kernel.run_chain_at)(*args, p, record, chain, int(max_events))   # typed as built
        if code != kernel.RECORD_FULL:
            break
        phases *= 2
    result = _result(module, code, t_stop, record, chain)
    result.p = start.copy()
    return result


def run_status(code: int) -> str:
    """The run's status for the kernel's code: "finished", "indeterminate" (several modes),
    "inconsistent" (none, or no contact force keeps the stages together), or why the run stopped."""
    if code == kernel.FINISHED:
        return "finished"
    if code == kernel.INDETERMINATE:
        return "indeterminate"
    if code in (kernel.UNDECIDED, kernel.SINGULAR, kernel.INCONSISTENT_START, kernel.IMPACT_JAMMED):
        return "inconsistent"
    if code == kernel.GROUP_AT_REST:
        return "group-at-rest"
    if code == kernel.TWO_OPEN:
        return "two-open"
    return STATUS.get(code, f"status {code}")


def _result(module, code: int, t_stop: float, record: Record, chain: kernel.ChainRecord) -> ChainRun:
    """The run from its records (a run's records are its own); the message of a run that stopped."""
    run = ChainRun(module, code, t_stop, record, chain)
    if code == kernel.FINISHED:
        return run
    last = run.events[-1]
    stages = ", ".join(map(str, clearance_stages(module)))
    if code in (kernel.UNDECIDED, kernel.INDETERMINATE) and stages:
        run.message = (f"{'several modes hold' if code == kernel.INDETERMINATE else 'no mode holds'} at "
                       f"t = {t_stop:.9g} s (the chain with stage {stages}'s clearance)")
    elif code in (kernel.UNDECIDED, kernel.INDETERMINATE):
        run.message = last.decision.reason
    elif code == kernel.SINGULAR:
        run.message = (f"{last.guard} reached 0 in mode {module.MODES[last.from_mode]} at t = {t_stop:.9g} s: no "
                       "contact force keeps the stages together (a Painleve-type inconsistency), not integrated "
                       "through")
        last.given = Decision("none", (), None, run.message)
    elif code == kernel.INCONSISTENT_START:
        run.message = (f"D or the jam factor is <= 0 where mode {module.MODES[run.phases[-1].mode]} begins at "
                       f"t = {t_stop:.9g} s: no contact force keeps the stages together")
    elif code == kernel.GROUP_AT_REST:
        run.message = (f"a group of bodies is at rest at t = {t_stop:.9g} s while stage {_current(module, last)}'s "
                       "flanks are apart and can neither stay at rest (its stages' stick cones and friction do not "
                       "hold its forces) nor leave rest in any direction and regimes")
    elif code == kernel.IMPACT_JAMMED:
        run.message = (f"stage {_current(module, last)}'s flanks meet at t = {t_stop:.9g} s and the impulse cannot "
                       "stop their approach (the effective masses and friction jam the impact)")
    elif code == kernel.TWO_OPEN:
        run.message = f"{two_open(last.guard, _current(module, last))} (at t = {t_stop:.9g} s)"
    elif code == kernel.TOO_MANY_EVENTS:
        run.message = f"{len(run.events)} events"
    elif code == kernel.CHATTERING:
        run.message = f"{kernel.MAX_SAME_TIME} decisions at t = {t_stop:.9g} s"
    else:
        run.message = f"the integrator stopped at t = {t_stop:.9g} s"
    return run


def _current(module, event: ChainEvent) -> int:
    """The current clearance stage at an event (the latches its decision saw)."""
    return clearance_stages(module)[int(event.seen[2][module.P_CURRENT])]


def _trip(module, trip: np.ndarray) -> dict | None:
    """What the chain carried just before the motor's cut (None: no cut): mode, state, stage forces (None at
    rest: undetermined), body 0's drive torque, the last body's coordinate."""
    if math.isnan(trip[0]):
        return None
    mode = int(trip[-1])
    return {"t": float(trip[0]), "y": trip[1:3].copy(), "mode": mode,
            "forces": None if mode == RESTING else trip[4:-2].copy(), "drive": float(trip[3]),
            "q_last": float(trip[-2])}
