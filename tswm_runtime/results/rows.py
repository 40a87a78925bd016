"""A run's per-point series, evaluated from its step log on first access and kept.

``simulate`` keeps the run's accepted steps (``integration.steplog``) instead of writing rows as
it goes; ``Rows`` evaluates them when a row quantity is first read: the states at the output
times with each step's own interpolant, then a1, S1, S2, F1, F2 there in one compiled pass
(``hybrid.rows.fill_rows``), each with the mode and the latched laws of the segment the time
lies in. ``states`` evaluates the states at any times the same way (``Result.sol``). A run of more than
MAX_LOGGED_STEPS steps keeps only its last one and writes its rows at the output times as it goes
(``written``): memory bounded by the output points, as before the step log, and no ``sol``.
"""
from __future__ import annotations

import functools
import importlib
import sys
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from tswm_runtime.hybrid.rows import fill_rows
from tswm_runtime.integration.steplog import states_at
from tswm_runtime.jit.signatures import GUARDS_SIG, address
from tswm_runtime.jit.structures import Outputs, StepLog

if TYPE_CHECKING:  # the kernels load on importing entry: simulate announces that first
    from tswm_runtime.hybrid.entry import RunArrays

MAX_LOGGED_STEPS = 10**6  # about 200-300 MB of step log at the limit


def state_names(module: ModuleType, width: int) -> tuple[str, ...]:
    """The names of a row of states and their integral: the states, then x1 when it is their integral."""
    return (*module.STATES, "x1")[:width]


@functools.lru_cache(maxsize=32)
def output_times(t_end: float, points: int) -> np.ndarray:
    """np.linspace(0, t_end, points), remembered and read-only (copy it to write or hand it on)."""
    t = np.linspace(0.0, t_end, points)
    t.setflags(write=False)
    return t


def states(steps: StepLog, n_states: int, t, side: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(y, segment): the states and their integral at the times t (any order; one row each, NaN
    outside the run) and the segment each lies in (-1 outside). side 0: at an event, its left
    limit (the step that ends there); 1: its right limit."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    y, segment = np.empty((t.size, steps.y_a.shape[1])), np.empty(t.size, np.int64)
    states_at(steps, n_states, t, side, y, segment)
    return y, segment


class Rows:
    """The series of a run at its output times (``points`` from 0 to ``t_end``), computed on first
    ``values()`` and kept, from the run's arrays (``entry.RunArrays``): its StepLog ``steps``, and
    ``written``: the rows the kernel wrote at t_out as it went (``wrote``), for a run too long to keep
    its steps (None: the steps are kept)."""

    def __init__(self, module: ModuleType, arrays: RunArrays, t_end: float, points: int, p: np.ndarray,
                 wrote: bool = False):
        self.module, self.arrays, self.p, self.wrote = module, arrays, p, wrote
        self.t_end, self.points = t_end, points
        self._values: dict | None = None

    @functools.cached_property
    def steps(self) -> StepLog:
        return self.arrays.record.steps

    @functools.cached_property
    def written(self) -> Outputs | None:
        return self.arrays.record.out if self.wrote else None

    @property
    def t_out(self) -> np.ndarray:
        """The output times (read-only)."""
        return output_times(self.t_end, self.points)

    @property
    def size(self) -> int:
        """How many output points the run reached (without evaluating them)."""
        if self.written is not None:
            return int(np.count_nonzero(self.written.mode >= 0))
        n_steps = min(int(self.steps.count[0]), self.steps.f.shape[0])
        return int(np.searchsorted(self.t_out, self.steps.f[n_steps - 1, 2], side="right")) if n_steps else 0

    def __getstate__(self) -> dict:
        """For pickling (a Result that travels): the rows evaluated, the module by its import name, the
        step log and the rows written without the rest of the run's arrays."""
        self.values()
        state = {**self.__dict__, "module": self.module.__name__, "steps": self.steps, "written": self.written}
        del state["arrays"]
        return state

    def __setstate__(self, state: dict) -> None:
        state["module"] = sys.modules.get(state["module"]) or importlib.import_module(state["module"])
        self.__dict__.update(state)

    def values(self) -> dict:
        """t, the states (and x1), a1, S1, S2, F1, F2, x2, v2, mode and the parameter rows ("p") by
        name, at the output points the run reached."""
        if self._values is None:
            self._values = self._evaluate()
        return self._values

    def _evaluate(self) -> dict:
        module, steps = self.module, self.steps
        n = len(module.STATES)
        if self.written is None:
            t = self.t_out[:self.size].copy()
            y, segment = states(steps, n, t)
            mode, p_rows = steps.seg_mode[segment], steps.seg_p[segment]
        else:
            kept = self.written.mode >= 0
            t, y, mode, p_rows = (np.ascontiguousarray(a[kept]) for a in self.written[:4])
        outputs = np.empty((len(module.OUTPUTS), t.size))
        fill_rows(address(module.outputs, GUARDS_SIG), t, y, mode, p_rows, n, outputs)
        values = {"t": t, **{name: np.ascontiguousarray(y[:, k]) for k, name in enumerate(state_names(module, y.shape[1]))}}
        values.update(zip(module.OUTPUTS, outputs))
        values["x2"], values["v2"] = module.body2(values["x1"], values["v1"], values.get("gap", 0.0),
                                                  values.get("gap_rate", 0.0), self.p)
        values["mode"], values["p"], values["y"] = mode, p_rows, y
        return values
