"""Many runs of one chain module in one compiled call, in parallel over the cores, and a drive train's
answers per case computed from each run's record in compiled code.

``run_chain_batch`` runs case after case (one row of p each: latches, voltage, the module's run-time
values) with ``kernel.run_chain_at``, called through its address (its code is not linked into this
kernel), in a ``prange`` loop over chunks of CHUNK_CASES cases; each chunk allocates one record and
resets it per case. Every case writes one row of answers (the same numbers ``simulation/drive_train.py``
takes from a ChainRun; tests/test_chain_sweep.py checks them case by case):

    f[c] = (t_stop, t_trip, thrust at the trip, body 0's drive at the trip, travel at the trip,
            peak thrust after the trip, its time, extra travel after the trip)
            (NaN: no trip; thrust NaN when the chain rested at the trip; peak NaN when it never slid
            after the trip, the extra travel then 0)
    i[c] = (status (kernel's code), hold verdict (``VERDICTS``), events, steps and rejected steps)

The thrust is the last stage's force on the last body; travel is the last body's coordinate. A case
whose record was too small (kernel.RECORD_FULL) is run again by ``run_cases`` with twice the room,
as ``run.run_chain`` does.
"""
from collections import namedtuple

import numpy as np
from numba import prange, types

from tswm_runtime.chains import kernel
from tswm_runtime.chains.rules import RESTING
from tswm_runtime.chains.run import chain_functions, chain_tables, first_room, run_status, samples_room
from tswm_runtime.hybrid import entry
from tswm_runtime.hybrid.addressed import ADDRESSES
from tswm_runtime.integration import segment
from tswm_runtime.integration.steplog import no_steps
from tswm_runtime.jit import cache_guard
from tswm_runtime.jit.addresses import function_at
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit
from tswm_runtime.jit.signatures import MATRIX, VECTOR, address
from tswm_runtime.jit.structures import SETTINGS, EventLog, Outputs, Record, Settings, Tolerances

F_T_STOP, F_T_TRIP, F_THRUST, F_DRIVE, F_TRAVEL, F_PEAK, F_T_PEAK, F_EXTRA = range(8)
N_F = 8
I_STATUS, I_VERDICT, I_EVENTS, I_STEPS = range(4)
N_I = 4
CHUNK_CASES = 16

#: What is left after the motor's cut, by code (``hold_verdict``); {status} is the run's status.
VERDICTS = ("no trip: the motor was not cut", "no seat in the scene", "undecided: the run stopped ({status})",
            "holds", "holds, though no stage self-locks", "undecided: still moving on the seat at the end of the run",
            "seat lost: no stage self-locks", "seat lost", "rests before the seat (never reached it)",
            "undecided: still moving before the seat at the end of the run")

#: What the answers need besides the chain's tables: the slot of p that holds the last body's speed
#: factor (q_N = factor q0), whether the scene has a seat; the record's room (phases, samples).
Answering = namedtuple("Answering", "p_speed has_seat phases samples")
ANSWERING = types.NamedTuple((types.int64, types.boolean, types.int64, types.int64), Answering)
#: Where run_chain_batch writes, one row per case: f (N_F floats), i (N_I integers).
Answers = namedtuple("Answers", "f i")
ANSWERS = types.NamedTuple((MATRIX, types.int64[:, ::1]), Answers)

_chain_at = function_at(types.FunctionType(kernel.CHAIN_SIG))

BATCH_SIG = types.none(types.int64, ADDRESSES, types.UniTuple(types.int64, 2), kernel.CHAIN_TABLES, SETTINGS, VECTOR,
                       MATRIX, VECTOR, ANSWERING, types.int64, ANSWERS)


def hold_verdict(tripped: bool, has_seat: bool, finished: bool, seated: bool, resting: bool, ever_seated: bool,
                 locking: bool) -> int:
    """The code in VERDICTS of what holds after the cut: ``seated`` and ``resting`` (finished at rest)
    at the end of the run, ``ever_seated`` in any phase, ``locking`` any stage self-locking."""
    if not tripped:
        return 0
    if not has_seat:
        return 1
    if not finished:
        return 2
    if seated:
        return (3 if locking else 4) if resting else 5
    if ever_seated:
        return 7 if locking else 6
    return 8 if resting else 9


_hold_verdict = njit(error_model="numpy")(hold_verdict)


@njit(error_model="numpy")
def _records(t_out, n_p, stages, room):
    """A case's Record (the output rows at t_out; no event log or step log: the chain keeps its own)
    and its ChainRecord with room for ``room.phases`` phases and ``room.samples`` samples."""
    out = Outputs(t_out, np.full((t_out.size, 2), np.nan), np.full(t_out.size, -1, np.int64),
                  np.empty((t_out.size, n_p)))
    record = Record(out, EventLog(np.empty(1), np.empty((1, 4), np.int64), np.empty((1, 2)), np.empty((1, 4))),
                    np.zeros((0, 3)), np.zeros(segment.N_COUNTERS, np.int64), no_steps(2, n_p))
    chain = kernel.ChainRecord(np.empty((room.phases, 3), np.int64), np.empty((room.phases, 2 + n_p)),
                               np.empty((room.samples, 3 + 3 * stages)), np.empty((room.phases, 4), np.int64),
                               np.empty((room.phases, 3 + n_p)), np.empty(5 + 3 * stages), np.zeros(3, np.int64))
    return record, chain


@njit(error_model="numpy")
def _reset(record, p, row):
    """The chunk's record made ready for its next case (no output rows, no counts; a call of its own:
    numba's prange hoists array writes from its body), the case's p from ``row``."""
    record.out.y[:, :] = np.nan
    record.out.mode[:] = -1
    record.counters[:] = 0
    copy_into(p, row)


@njit(error_model="numpy")
def _answer(status, t_stop, record, rec, c, room, p, f, i):
    """The case's answers from its records (and its p at the start: the speed factor, Psi_i) into rows f
    and i (module docstring)."""
    n = c.stages
    speed = p[room.p_speed]
    locking = False
    for k in range(n):
        locking = locking or p[c.p_psi + 2 * k + 1] <= 0.0
    n_phases = rec.counts[0]
    thrust_at = 3 * n - 2                # the last stage's force on the last body among a stage row's forces
    f[:] = np.nan
    f[F_T_STOP] = t_stop
    tripped = not np.isnan(rec.trip[0])
    if tripped:
        f[F_T_TRIP], f[F_DRIVE] = rec.trip[0], rec.trip[3]
        f[F_TRAVEL] = speed * rec.trip[1]
        if rec.trip[rec.trip.size - 1] != RESTING:
            f[F_THRUST] = rec.trip[4 + thrust_at]
        f[F_EXTRA] = 0.0
        far, found = -np.inf, False
        for k in range(n_phases):
            if rec.phases[k, 0] == RESTING or rec.phase_f[k, 2 + c.p_switch] != c.tripped:
                continue
            for s in range(rec.phases[k, 1], rec.phases[k, 2]):
                row = rec.samples[s]
                if not found or abs(row[3 + thrust_at]) > abs(f[F_PEAK]):
                    f[F_PEAK], f[F_T_PEAK] = row[3 + thrust_at], row[0]
                far = max(far, speed * row[1])
                found = True
        if found:
            f[F_EXTRA] = far - f[F_TRAVEL]
    ever_seated = False
    for k in range(n_phases):
        ever_seated = ever_seated or rec.phase_f[k, 2 + c.p_seated] > 0.5
    last = n_phases - 1
    finished = status == kernel.FINISHED
    seated = room.has_seat and n_phases > 0 and rec.phase_f[last, 2 + c.p_seated] > 0.5
    resting = n_phases > 0 and rec.phases[last, 0] == RESTING and finished
    i[I_STATUS] = status
    i[I_VERDICT] = _hold_verdict(tripped, room.has_seat, finished, seated, resting, room.has_seat and ever_seated,
                                 locking)
    i[I_EVENTS] = rec.counts[2]
    i[I_STEPS] = record.counters[segment.N_STEPS] + record.counters[segment.N_REJECTED]


@cache_guard.compile_cached(BATCH_SIG, parallel=True, error_model="numpy")
def run_chain_batch(chain_at, functions, chain_addresses, c, settings, y0, P, t_out, room, max_events, answers):
    """Run the chain (``kernel.run_chain_at`` at address ``chain_at``) from (0, y0) for every row of P
    to settings.t_end, each case's answers into ``answers``; chunks of CHUNK_CASES cases share a record."""
    n_cases, n_p, stages = P.shape[0], P.shape[1], c.stages
    method, t_end, max_steps = settings.method, settings.t_end, settings.max_steps
    tol = Tolerances(settings.tol.rtol, settings.tol.atol, settings.tol.hmin, settings.tol.hmax)
    run = _chain_at(chain_at)
    for chunk in prange((n_cases + CHUNK_CASES - 1) // CHUNK_CASES):
        record, rec = _records(t_out, n_p, stages, room)
        p = np.empty(n_p)
        case_settings = Settings(method, t_end, tol, max_steps)
        for case in range(chunk * CHUNK_CASES, min((chunk + 1) * CHUNK_CASES, n_cases)):
            _reset(record, p, P[case])
            status, t_stop = run(functions, chain_addresses, c, case_settings, y0, p, record, rec, max_events)
            _answer(status, t_stop, record, rec, c, room, P[case], answers.f[case], answers.i[case])


#: The answers of a batch as arrays, one entry per case (module docstring): status and verdict as
#: codes into the lists of their words (``status_words``, ``verdict_words``).
CaseAnswers = namedtuple("CaseAnswers", "status status_words verdict verdict_words t_stop t_trip thrust drive travel "
                                        "peak t_peak extra_travel events steps")


def run_cases(module, P: np.ndarray, *, t_end: float, v0: float, rtol: float, atol: float, t_out: np.ndarray,
              method: int = 0, max_steps: int = 100_000, max_events: int = 1000) -> CaseAnswers:
    """Every row of P (the module's complete p, as ``run.latches`` gives it) run from q0 = 0, v0 to t_end;
    the answers per case.
    The record starts with the room ``run.run_chain`` gives it; cases that need more run again with twice it."""
    P = np.ascontiguousarray(P, dtype=np.float64)
    t_out = np.ascontiguousarray(t_out, dtype=np.float64)
    settings = Settings(int(method), float(t_end), Tolerances(float(rtol), np.full(2, float(atol)), 0.0, np.inf),
                        int(max_steps))
    args = (address(kernel.run_chain_at, kernel.CHAIN_SIG), entry.functions(method, module), chain_functions(module),
            chain_tables(module), settings, np.array([0.0, float(v0)]))
    f, i = np.full((P.shape[0], N_F), np.nan), np.zeros((P.shape[0], N_I), np.int64)
    todo, phases = np.arange(P.shape[0]), first_room(max_events)
    while todo.size:
        room = Answering(module.P_SPEED + module.STAGES, bool(module.HAS_SEAT), phases,
                         samples_room(phases, t_out.size))
        answers = Answers(np.empty((todo.size, N_F)), np.empty((todo.size, N_I), np.int64))
        run_chain_batch(*args, np.ascontiguousarray(P[todo]), t_out, room, int(max_events), answers)
        f[todo], i[todo] = answers.f, answers.i
        todo, phases = todo[answers.i[:, I_STATUS] == kernel.RECORD_FULL], 2 * phases
    codes, status = np.unique(i[:, I_STATUS], return_inverse=True)
    status_words = [run_status(int(code)) for code in codes]
    pairs, verdict = np.unique(np.column_stack([i[:, I_VERDICT], status]), axis=0, return_inverse=True)
    verdict_words = [VERDICTS[v].format(status=status_words[s]) for v, s in pairs]
    return CaseAnswers(status.ravel(), status_words, verdict.ravel(), verdict_words, *f.T, i[:, I_EVENTS],
                       i[:, I_STEPS])
