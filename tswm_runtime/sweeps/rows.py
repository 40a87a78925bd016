"""One chunk's rows: every case of a parameter block integrated in one parallel numba batch
(``case_table``), with its regime code and load factors, as Arrow columns (``columns``).
Importing this module loads (or compiles, saying so first) the batch kernel, so a dask worker
imports it only when it runs a chunk."""
from __future__ import annotations

from types import ModuleType

import numpy as np

from tswm_runtime.jit import coldstart

coldstart.announce(("integrate", "batch"))  # before the next imports compile the kernels, if not cached
from tswm_runtime.hybrid import batch, entry  # noqa: E402
from tswm_runtime.jit.structures import Settings, Start, Tolerances  # noqa: E402
from tswm_runtime.model import checks, modes  # noqa: E402
from tswm_runtime.hybrid import machine as hybrid  # noqa: E402
from tswm_runtime.results.result import NOT_FINITE_CAUSE, STATUS_NAMES  # noqa: E402
from tswm_runtime.sweeps import columns  # noqa: E402
from tswm_runtime.simulation.simulate import METHODS, initial_state, method_step, with_latches  # noqa: E402

coldstart.done()

REGIME_LETTERS = {"tractive": "T", "inverse-tractive": "I", "stick": "S", "backward on flank a": "A",
                  "backward on flank b": "B", "sliding along phi = 0": "F", "free flight": "G"}
SEQ_LEN = 32  # modes kept per case; longer sequences end in '…'
INVALID = "invalid-parameter"

def sequence_texts(module: ModuleType, seq: np.ndarray, n_modes: np.ndarray) -> tuple[list, list, np.ndarray]:
    """Its regimes as letters ("TS") and its mode indices ("0 2") for each distinct sequence of
    modes, and which of them each case has, from each case's first SEQ_LEN modes (``seq``, padded
    with -1) and its number of modes (more end in '…'). A grid has a few distinct sequences, each
    spelt once."""
    letters = [REGIME_LETTERS.get(r, "?") for r in module.MODE_REGIME]
    longest = min(SEQ_LEN, int(n_modes.max(initial=0)))   # the columns any case uses
    kept = np.where(np.arange(longest) < n_modes[:, None], seq[:, :longest], -1)  # the first n_modes only
    small = len(letters) < 255   # a key of one byte per mode (the padding -1 as 255): a quicker sort
    width = np.dtype(np.uint8 if small else np.int64)
    keys = np.ascontiguousarray(np.column_stack([kept, n_modes > SEQ_LEN]).astype(width))
    distinct, which = np.unique(keys.view(np.dtype((np.void, keys.shape[1] * width.itemsize))).ravel(),
                                return_inverse=True)
    regimes, codes = [], []
    for key in distinct:
        *modes_of, more = np.frombuffer(key.tobytes(), width).tolist()
        modes_of = [m for m in modes_of if m != (255 if small else -1)]  # not the padding
        regimes.append("".join(letters[m] for m in modes_of) + ("…" if more else ""))
        codes.append(" ".join(map(str, modes_of)) + (" …" if more else ""))
    return regimes, codes, which.ravel()


def load_factor_columns(module: ModuleType, S1m, S2m, full: np.ndarray, valid) -> tuple[np.ndarray, np.ndarray]:
    """(KD1, KD2) of every case (NaN where not run, or without Ft1, Ft2): the generated
    ``load_factors`` (|S| / Ft, elementwise) evaluated once on the columns as plain Python,
    with p[k] the k-th parameter of every case; one compiled call per case cost ~1.7 us."""
    KD1, KD2 = np.full(S1m.size, np.nan), np.full(S1m.size, np.nan)
    if module.HAS_LOAD_FACTORS and valid.any():
        python = getattr(module.load_factors, "py_func", module.load_factors)
        KD1[valid], KD2[valid] = python(S1m[valid], S2m[valid], full[valid].T)
    return KD1, KD2


NOT_FINITE_COLUMNS = {"t_stop": batch.F_T_STOP, "S1m": batch.F_S1M, "S2m": batch.F_S2M, "x1": batch.F_X1,
                      "v1": batch.F_V1}


def _mark_not_finite(out_f: np.ndarray, out_i: np.ndarray, valid: np.ndarray, problems: list[str]) -> None:
    """Cases whose results hold inf or NaN get status not-finite and the column in ``problems``
    (in place). Not an inconsistent case (S1m, S2m = +-inf: unbounded, its status says so), nor NaN
    x1, v1 of a run that stopped inside a step (documented), nor NaN S1m, S2m of a run that stopped
    at its start (nothing integrated, no maxima); a finished one holds finite numbers."""
    status = out_i[:, batch.I_STATUS]
    finished = status == hybrid.FINISHED
    integrated = out_i[:, batch.I_FIRST] >= 0
    for name, column in NOT_FINITE_COLUMNS.items():
        values = out_f[:, column]
        bad = np.isinf(values) | (np.isnan(values) & (finished if name in ("x1", "v1") else integrated))
        for case in np.flatnonzero(bad & valid & (status != hybrid.INCONSISTENT) & (status != hybrid.NOT_FINITE)):
            status[case] = hybrid.NOT_FINITE
            problems[case] = f"{name} = {values[case]:g}: not finite; likely cause: {NOT_FINITE_CAUSE}"


def _distinct(texts: list[str]) -> tuple[list[str], np.ndarray]:
    """(distinct values, which of them each row has) of a column of mostly empty texts."""
    held = np.array(texts, dtype=object)
    given = np.flatnonzero(held.astype(bool))
    words, which = [""], np.zeros(held.size, np.int64)
    if given.size:
        distinct, inverse = np.unique(held[given], return_inverse=True)
        words += distinct.tolist()
        which[given] = inverse.ravel() + 1
    return words, which


def _status(out_i: np.ndarray, valid: np.ndarray) -> tuple[list[str], np.ndarray]:
    """(status names, which of them each case has): STATUS_NAMES by code, INVALID for a row not run."""
    codes = sorted(STATUS_NAMES)
    which = np.searchsorted(codes, out_i[:, batch.I_STATUS])
    return [STATUS_NAMES[c] for c in codes] + [INVALID], np.where(valid, which, len(codes))


def case_table(module: ModuleType, P: np.ndarray, run: dict):
    """Integrate every row of P (free parameters) in one parallel batch; a pyarrow Table, one row
    per case (columns: sweep.py). Rows that break the scene's parameter rules are not run: status
    'invalid-parameter'."""
    y0, quad = initial_state(module, run)
    full = with_latches(module, P)
    cases = P.shape[0]
    problems = checks.violations(module, P) if cases else []
    valid = ~np.array(problems, dtype=object).astype(bool) if cases else np.zeros(0, bool)
    out_f = np.full((cases, batch.N_F), np.nan)
    out_i = np.zeros((cases, batch.N_I), np.int64)
    seq = np.full((cases, SEQ_LEN), -1, np.int64)
    if valid.any():
        f, i, sq = out_f[valid], out_i[valid], seq[valid]
        method_step(run["method"])  # announced if it compiles
        tol = Tolerances(run["rtol"], np.full(y0.size, run["atol"]), 0.0, run["hmax"])
        batch.run_batch(entry.functions(METHODS[run["method"]], module), modes.tables(module),
                        np.ascontiguousarray(full[valid]), Start(0.0, y0, quad, -1, np.empty(0)),
                        Settings(METHODS[run["method"]], float(run["t_end"]), tol, int(run["max_steps"])),
                        run["max_events"], len(module.OBSERVABLES), batch.Results(f, i, sq))
        out_f[valid], out_i[valid], seq[valid] = f, i, sq
    _mark_not_finite(out_f, out_i, valid, problems)
    regimes, mode_codes, sequence = sequence_texts(module, seq, out_i[:, batch.I_NMODES])
    KD1, KD2 = load_factor_columns(module, out_f[:, batch.F_S1M], out_f[:, batch.F_S2M], full, valid)
    number = columns.numbers
    table = {name: number(P[:, j]) for j, name in enumerate(module.PARAM_NAMES)}
    table.update({
        "status": columns.texts(*_status(out_i, valid)), "problem": columns.texts(*_distinct(problems)),
        "t_stop": number(out_f[:, batch.F_T_STOP]), "S1m": number(out_f[:, batch.F_S1M]),
        "tS1m": number(out_f[:, batch.F_TS1M]), "S2m": number(out_f[:, batch.F_S2M]),
        "tS2m": number(out_f[:, batch.F_TS2M]), "KD1": number(KD1), "KD2": number(KD2),
        "x1": number(out_f[:, batch.F_X1]), "v1": number(out_f[:, batch.F_V1]),
        "regimes": columns.texts(regimes, sequence), "modes": columns.texts(mode_codes, sequence),
        "n_events": number(out_i[:, batch.I_EVENTS]), "steps": number(out_i[:, batch.I_STEPS]),
        "rejected": number(out_i[:, batch.I_REJECTED]), "nfev": number(out_i[:, batch.I_RHS]),
        "njev": number(out_i[:, batch.I_JAC]), "n_switches": number(out_i[:, batch.I_SWITCHES]),
        "impacts": number(out_i[:, batch.I_IMPACTS]), "impact_energy": number(out_f[:, batch.F_IMPACT_E]),
    })
    return columns.table(table)


def run_cases(module: ModuleType, P: np.ndarray, run: dict):
    """``case_table`` as a pandas DataFrame (the fit's evaluations)."""
    return case_table(module, P, run).to_pandas()
