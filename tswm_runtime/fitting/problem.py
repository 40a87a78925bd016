"""The least-squares problem of ``tswm fit``: the model against a measured table.

``Problem`` turns evaluation points (rows of free parameter values) into model values,
per-case statuses and scaled residuals. Peaks: the model runs on the jitted batch
(``rows.run_cases``: all cases of all evaluation points in one parallel call);
``magnitude=True`` compares |S1m|, |S2m| instead of the signed values. Time histories:
``simulate()`` per case, read at the measured times (``history_values``): v1 by the
Result's Hermite interpolation (``Result.sol``), S1 and S2 linearly between output points
within a phase (never across an event).

Residuals are scaled per quantity: r = (model - measured) / scale_q with scale_q the
root mean square of the measured values of q (1 where they are all 0), so quantities of
different units weigh alike; the cost is 0.5 sum r^2 (scipy's). A case whose run does not
finish (status other than 'finished', or a non-finite value) contributes the finite
penalty PENALTY to each of its residuals and is listed as failed; it is never compared.
"""
from __future__ import annotations

from types import ModuleType

import numpy as np

from tswm_runtime.fitting.inputs import FitInputError, Measured
from tswm_runtime.model import checks

PENALTY = 10.0  # scaled residual of a failed case (10 x the quantity's RMS)


class Problem:
    """The model against the measured table: evaluation points (rows of free values) to
    model values, statuses and scaled residuals."""

    def __init__(self, module: ModuleType, measured: Measured, free: dict, run: dict, magnitude: bool):
        from tswm_runtime.sweeps.sweep import grid_cases

        self.module, self.measured, self.run, self.magnitude = module, measured, run, magnitude
        self.names = list(free)
        self.lo = np.array([free[n][0] for n in self.names])
        self.hi = np.array([free[n][1] for n in self.names])
        self.width = self.hi - self.lo
        self.free_index = [module.PARAM_NAMES.index(n) for n in self.names]
        self.known_index = [module.PARAM_NAMES.index(n) for n in measured.known]
        base = grid_cases(module, {})  # one row: the scene's defaults (sweep's parameter matrix)
        self.base = np.repeat(base, len(measured.cases), axis=0)
        if self.known_index:
            self.base[:, self.known_index] = measured.params
        rms = np.sqrt(np.mean(measured.values ** 2, axis=0))
        self.scale = np.where(rms > 0, rms, 1.0)
        self.evaluations = 0
        self.runs = 0
        self.last_modes = np.empty((0, 0), dtype=object)  # mode sequence per point and case, last evaluate()

    def tightened(self, factor: float) -> "Problem":
        """The same problem run at rtol and atol divided by ``factor``, no tighter than simulate
        accepts (own counters)."""
        from copy import copy

        from tswm_runtime.simulation.simulate import ATOL_RANGE, METHOD_RTOL_MIN

        tight = copy(self)
        tight.run = {**self.run, "rtol": max(self.run["rtol"] / factor, METHOD_RTOL_MIN[self.run["method"]][0]),
                     "atol": max(self.run["atol"] / factor, ATOL_RANGE[0])}
        tight.evaluations = tight.runs = 0
        return tight

    @property
    def n_residuals(self) -> int:
        return self.measured.values.size

    def matrix(self, X: np.ndarray) -> np.ndarray:
        """Rows of all free parameters for evaluation points X (k x free): k blocks of cases."""
        X = np.atleast_2d(X)
        P = np.tile(self.base, (X.shape[0], 1))
        P[:, self.free_index] = np.repeat(X, self.base.shape[0], axis=0)
        return P

    def check_rules(self) -> None:
        """Known values and the bounds against the scene's rules (refused before any run)."""
        cases = self.measured.cases
        mid = (self.lo + self.hi) / 2
        for row, reason in enumerate(checks.violations(self.module, self.matrix(mid))):
            if reason:
                raise FitInputError(f"--measured: case {cases[row]!r}: {reason}")
        for j, name in enumerate(self.names):
            for end, value in (("LO", self.lo[j]), ("HI", self.hi[j])):
                x = mid.copy()
                x[j] = value
                for row, reason in enumerate(checks.violations(self.module, self.matrix(x))):
                    if reason:
                        raise FitInputError(f"--free {name}={self.lo[j]:g}:{self.hi[j]:g}: at {end} "
                                            f"(case {cases[row]!r}): {reason}")

    def evaluate(self, X: np.ndarray):
        """Model values (k x rows x quantities; NaN where failed) and per-case status (k x cases);
        each case's sequence of mode names is kept in ``last_modes`` (k x cases)."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        self.evaluations += X.shape[0]
        self.runs += X.shape[0] * len(self.measured.cases)
        if self.measured.kind == "peaks":
            return self._peaks(X)
        return self._history(X)

    def _peaks(self, X):
        from tswm_runtime.sweeps import columns
        from tswm_runtime.sweeps.rows import case_table

        k, n = X.shape[0], len(self.measured.cases)
        table = case_table(self.module, self.matrix(X), self.run)   # read from Arrow: no DataFrame per evaluation
        values = np.column_stack([columns.numbers_of(table.column(q)).astype(np.float64)
                                  for q in self.measured.quantities]).reshape(k, n, -1)
        if self.magnitude:
            for j, q in enumerate(self.measured.quantities):
                if q in ("S1m", "S2m"):
                    values[:, :, j] = np.abs(values[:, :, j])
        status = np.array(table.column("status").to_pylist(), dtype=object).reshape(k, n)
        modes = table.column("modes").to_pylist()
        names = {c: " ".join(self.module.MODES[int(i)] if i.isdigit() else i for i in c.split()) for c in set(modes)}
        self.last_modes = np.array([names[c] for c in modes], dtype=object).reshape(k, n)
        bad = (status != "finished")[:, :, None] | ~np.isfinite(values)
        values = np.where(bad, np.nan, values)
        return values, status

    def _history(self, X):
        from tswm_runtime.simulation.simulate import SimulationInputError, simulate

        m = self.measured
        k = X.shape[0]
        values = np.full((k, m.values.shape[0], len(m.quantities)), np.nan)
        status = np.empty((k, len(m.cases)), dtype=object)
        self.last_modes = np.full((k, len(m.cases)), "", dtype=object)
        P = self.matrix(X)
        for e in range(k):
            for c in range(len(m.cases)):
                params = dict(zip(self.module.PARAM_NAMES, P[e * len(m.cases) + c].tolist()))
                try:
                    result = simulate(self.module, params, **self.run)
                except SimulationInputError:
                    status[e, c] = "invalid-parameter"
                    continue
                status[e, c] = result.status
                self.last_modes[e, c] = " ".join(phase.mode for phase in result.phases)
                if result.status != "finished":
                    continue
                rows = np.flatnonzero(m.row_case == c)
                values[e, rows] = history_values(result, m.t[rows], m.quantities)
        return values, status

    def residuals(self, X: np.ndarray):
        """Scaled residuals (k x rows*quantities), with PENALTY where a case failed; values; status."""
        values, status = self.evaluate(X)
        r = (values - self.measured.values[None]) / self.scale
        r[~np.isfinite(r)] = PENALTY
        return r.reshape(r.shape[0], -1), values, status


def history_values(result, t: np.ndarray, quantities: list[str]) -> np.ndarray:
    """The Result's quantities at times t: v1 by Result.sol (cubic Hermite), S1 and S2
    linearly between output points within one phase (rows at an event time belong to the
    phase that ends there; a time at an event reads the earlier phase)."""
    out = np.full((t.size, len(quantities)), np.nan)
    cuts = [0.0, *sorted({e.t for e in result.events}), result.t_stop]
    for j, q in enumerate(quantities):
        if q == "v1":
            out[:, j] = result.sol(t)[1]
            continue
        series = getattr(result, q)
        for a, b in zip(cuts[:-1], cuts[1:]):
            rows = (result.t >= a) & (result.t <= b)
            if a > 0.0:
                rows &= result.t > a
            want = (t >= a) & (t <= b) & np.isnan(out[:, j])
            if want.any() and rows.any():
                out[want, j] = np.interp(t[want], result.t[rows], series[rows])
    return out
