"""Many runs of one chain module in one compiled call, in parallel over the cores, and a drive train's
answers per case from each run's record (``answers.answer``, the compiled code ``tswm simulate`` uses too).

``run_chain_batch`` runs case after case (one row of p each: latches, voltage, the module's run-time
values) with ``kernel.run_chain_at``, called through its address (its code is not linked into this
kernel), in a ``prange`` loop over chunks of CHUNK_CASES cases; each chunk allocates one record and
resets it per case. Every case writes one row of answers f and one of i (chains/answers.py). A case
whose record was too small (kernel.RECORD_FULL) is run again by ``run_cases`` with twice the room,
as ``run.run_chain`` does.
"""
from collections import namedtuple

import numpy as np
from numba import prange, types

from tswm_runtime.chains import kernel
from tswm_runtime.chains.answers import (ANSWERING, I_EVENTS, I_IMPACTS, I_STATUS, I_STEPS, I_VERDICT, N_F, N_I,
                                          VERDICTS, answer, answering)
from tswm_runtime.chains.run import chain_functions, chain_tables, first_room, run_status, samples_room, start_state
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

CHUNK_CASES = 16

#: The record's room per case: phases, samples.
Room = namedtuple("Room", "phases samples")
ROOM = types.NamedUniTuple(types.int64, 2, Room)
#: Where run_chain_batch writes, one row per case: f (N_F floats), i (N_I integers).
Answers = namedtuple("Answers", "f i")
ANSWERS = types.NamedTuple((MATRIX, types.int64[:, ::1]), Answers)

_chain_at = function_at(types.FunctionType(kernel.CHAIN_SIG))

BATCH_SIG = types.none(types.int64, ADDRESSES, types.UniTuple(types.int64, 3), kernel.CHAIN_TABLES, SETTINGS, VECTOR,
                       MATRIX, VECTOR, ROOM, ANSWERING, types.int64, ANSWERS)


@njit(refcounted=True, error_model="numpy")
def _records(t_out, n_states, n_p, stages, room):
    """A case's Record (the output rows of n_states at t_out, the stage forces' maxima; no event log or step log:
    the chain keeps its own) and its ChainRecord with room for ``room.phases`` phases and ``room.samples``
    samples."""
    out = Outputs(t_out, np.full((t_out.size, n_states), np.nan), np.full(t_out.size, -1, np.int64),
                  np.empty((t_out.size, n_p)))
    record = Record(out, EventLog(np.empty(1), np.empty((1, 4), np.int64), np.empty((1, 2)), np.empty((1, 4))),
                    np.empty((3 * stages, 3)), np.zeros(segment.N_COUNTERS, np.int64), no_steps(2, n_p))
    return record, kernel.chain_record_compiled(room.phases, room.samples, n_states, n_p, stages)


@njit(error_model="numpy")
def _reset(record, p, row):
    """The chunk's record made ready for its next case (no output rows, no counts; a call of its own:
    numba's prange hoists array writes from its body), the case's p from ``row``."""
    record.out.y[:, :] = np.nan
    record.out.mode[:] = -1
    record.counters[:] = 0
    copy_into(p, row)


@cache_guard.compile_cached(BATCH_SIG, parallel=True, error_model="numpy")
def run_chain_batch(chain_at, functions, chain_addresses, c, settings, y0, P, t_out, room, a, max_events, answers):
    """Run the chain (``kernel.run_chain_at`` at address ``chain_at``) from (0, y0) for every row of P
    to settings.t_end, each case's answers (``answers.answer`` with the module's numbers ``a``) into
    ``answers``; chunks of CHUNK_CASES cases share a record with ``room``."""
    n_cases, n_p, stages = P.shape[0], P.shape[1], c.stages
    method, t_end, max_steps = settings.method, settings.t_end, settings.max_steps
    tol = Tolerances(settings.tol.rtol, settings.tol.atol, settings.tol.hmin, settings.tol.hmax)
    run = _chain_at(chain_at)
    for chunk in prange((n_cases + CHUNK_CASES - 1) // CHUNK_CASES):
        record, rec = _records(t_out, y0.size, n_p, stages, room)
        p = np.empty(n_p)
        case_settings = Settings(method, t_end, tol, max_steps)
        for case in range(chunk * CHUNK_CASES, min((chunk + 1) * CHUNK_CASES, n_cases)):
            _reset(record, p, P[case])
            status, t_stop = run(functions, chain_addresses, c, case_settings, y0, p, record, rec, max_events)
            steps = record.counters[segment.N_STEPS] + record.counters[segment.N_REJECTED]
            answer(status, t_stop, steps, rec, a, P[case], answers.f[case], answers.i[case])


#: The answers of a batch as arrays, one entry per case (chains/answers.py): status and verdict as
#: codes into the lists of their words (``status_words``, ``verdict_words``).
CaseAnswers = namedtuple("CaseAnswers", "status status_words verdict verdict_words t_stop t_trip thrust drive travel "
                                        "peak t_peak extra_travel needed pull_out stall_margin energy_lost events "
                                        "steps impacts")


def run_cases(module, P: np.ndarray, *, t_end: float, v0: float, rtol: float, atol: float, t_out: np.ndarray,
              method: int = 0, max_steps: int = 100_000, max_events: int = 1000) -> CaseAnswers:
    """Every row of P (the module's complete p, as ``run.latches`` gives it) run from q0 = 0, v0 to t_end;
    the answers per case.
    The record starts with the room ``run.run_chain`` gives it; cases that need more run again with twice it."""
    P = np.ascontiguousarray(P, dtype=np.float64)
    t_out = np.ascontiguousarray(t_out, dtype=np.float64)
    y0 = start_state(module, float(v0))
    settings = entry.settings(int(method), y0.size, t_end=float(t_end), rtol=float(rtol), atol=float(atol),
                              max_steps=int(max_steps))
    args = (address(kernel.run_chain_at, kernel.CHAIN_SIG), entry.functions(method, module), chain_functions(module),
            chain_tables(module), settings, y0)
    f, i = np.full((P.shape[0], N_F), np.nan), np.zeros((P.shape[0], N_I), np.int64)
    todo, phases = np.arange(P.shape[0]), first_room(max_events)
    while todo.size:
        answers = Answers(np.empty((todo.size, N_F)), np.empty((todo.size, N_I), np.int64))
        run_chain_batch(*args, np.ascontiguousarray(P[todo]), t_out, Room(phases, samples_room(phases, t_out.size)),
                        answering(module), int(max_events), answers)
        f[todo], i[todo] = answers.f, answers.i
        todo, phases = todo[answers.i[:, I_STATUS] == kernel.RECORD_FULL], 2 * phases
    codes, status = np.unique(i[:, I_STATUS], return_inverse=True)
    status_words = [run_status(int(code)) for code in codes]
    pairs, verdict = np.unique(np.column_stack([i[:, I_VERDICT], status]), axis=0, return_inverse=True)
    verdict_words = [VERDICTS[v].format(status=status_words[s]) for v, s in pairs]
    return CaseAnswers(status.ravel(), status_words, verdict.ravel(), verdict_words, *f.T, i[:, I_EVENTS],
                       i[:, I_STEPS], i[:, I_IMPACTS])
