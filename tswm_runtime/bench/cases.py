"""The benchmark's cases, their independent reference, and how each solver is called.

A case is one run of the paper gear under a piecewise-constant (or piecewise-linear) load,
given twice: as a shipped tswm scene with parameters and run settings, and as the
hand-formula data (m1, m2, loads, v1(0), t_end) that the peers and the reference read. The
reference (``quadrature``: each load segment is v1' = A(v1), solved by quadrature in v1 at
34 digits; under a load linear in t, which quadrature in v1 cannot follow, the DOP853 peer
at rtol 1e-13) knows nothing of tswm; it is computed once per case and run.

Every solver returns a ``bench_peers.Outcome`` (max |S1| signed, v1(t_end), events,
x1(t_end)). Every timed call of simulate() and of a peer gets new parameters (``new_m2``).
"""
from __future__ import annotations

import itertools
import math
import statistics
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from tswm_runtime.bench.peers import Outcome, peer_run
from tswm_runtime.reference.paper_gear import M1


@dataclass(frozen=True)
class Case:
    name: str
    scene: str  # shipped tswm scene
    params: tuple  # ((name, value), ...) free parameters set (``--set``)
    loads: tuple  # ((t_from, F2) or (t_from, F2, dF2/dt), ...) the same load for the peers and the reference
    v0: float = 0.0
    t_end: float = 1.0
    m1: float = M1
    m2: float = 200.0

    def overrides(self) -> dict:
        """tswm run settings beyond the scene's: v1(0) and t_end."""
        return {"v1": self.v0, "t_end": self.t_end}


RUNUP = ((0.0, 0.0), (0.3, -15000.0))


def linear_loads(at, values) -> tuple:
    """A load linear in t between the breakpoints ``at`` through ``values`` (a schedule of shape
    "linear"), constant outside them, as ``Case.loads``."""
    pieces = [(0.0, values[0], 0.0)]
    for k in range(len(at) - 1):
        pieces.append((at[k], values[k], (values[k + 1] - values[k]) / (at[k + 1] - at[k])))
    return (*pieces, (at[-1], values[-1], 0.0))


# slow-load.toml's schedule: nothing settles, so nothing is held (``integration.steady``)
SLOW = linear_loads((0.05, 25.0, 50.0, 75.0, 125.0), (0.0, -8000.0, -3000.0, -10000.0, -5000.0))
CASES = {c.name: c for c in (
    Case("run-up then load", "paper-runup", (), RUNUP),
    Case("stiff drive m1=0.05", "stiff-drive", (), RUNUP, m1=0.05),
    Case("flank switch near V0", "paper", (("F2", 200.0),), ((0.0, 200.0),)),
    Case("decelerate-and-stick", "paper", (("F2", -15000.0),), ((0.0, -15000.0),), v0=2.0),
    Case("long run T=100", "paper-runup", (), RUNUP, t_end=100.0),
    Case("load schedule: stall, restart", "load-schedule", (), ((0.0, 0.0), (0.3, -30000.0), (0.6, -2000.0))),
    *(Case(f"slow load T={t_end:g}", "slow-load", (), tuple(p for p in SLOW if p[0] < t_end), t_end=t_end)
      for t_end in (1.0, 10.0, 100.0)),
)}
REFERENCE_RTOL = 1e-13  # the DOP853 reference under a load linear in t
REFERENCE_ATOL = 1e-15


_CALLS = itertools.count(1)


def new_m2(case: Case) -> float:
    """case.m2 times (1 + k 2^-52) for the k-th call in this process: a value no earlier call had
    (new to every cache), the same problem to 1e-11 for the first 45,000 calls (the reference is
    at case.m2; the bench's errors are compared at 1e-9 and above)."""
    return case.m2 * (1.0 + next(_CALLS) * 2.0**-52)


@lru_cache(maxsize=None)
def reference(case: Case) -> Outcome:
    """The quadrature reference (under a load linear in t, the DOP853 peer at REFERENCE_RTOL,
    without max |S1|: NaN): max |S1| (signed), v1(t_end), events (cached per case)."""
    from tswm_runtime.reference import quadrature as q

    if any(len(piece) > 2 and piece[2] != 0.0 for piece in case.loads):
        out = peer_run("DOP853", REFERENCE_RTOL, REFERENCE_ATOL, case.m2, list(case.loads), case.v0, case.t_end,
                       m1=case.m1)
        out.S1 = math.nan  # taken at the peer's steps only (S1 depends on t too): not compared
        return out
    tr = q.solve(q.paper_wedge(case.m2, m1=case.m1), list(case.loads), case.v0, case.t_end)
    if tr.status != "finished":
        raise RuntimeError(f"reference for {case.name}: {tr.status}")
    events = [("load" if e.kind in ("load", "breakaway") else e.kind, float(e.t)) for e in tr.events]
    return Outcome(float(tr.S_extrema()["S1"][0]), float(tr.v_at(case.t_end)), events,
                   x_end=float(tr.x_at(case.t_end)))


def _tswm_kind(guard: str) -> str:
    if guard in ("phi", "v1"):
        return guard
    return "load" if guard.startswith("load") else guard


def run_simulate(case: Case, rtol: float, atol: float, points: int | None = None,
                 t_end: float | None = None, method: str | None = None) -> Outcome:
    """tswm as a user calls it: simulate(scene, params, rtol=, atol=, ...) with a new m2 (default output:
    1001 points, evaluated only if read; ``points``, ``t_end``, ``method`` override the case's and the
    scene's), then max |S1|, v1(t_end), x1(t_end) - x1(0) and the events from the Result."""
    from tswm_runtime.simulation.simulate import simulate

    extra = {k: v for k, v in (("points", points), ("t_end", t_end), ("method", method)) if v is not None}
    r = simulate(case.scene, {**dict(case.params), "m2": new_m2(case)}, rtol=rtol, atol=atol,
                 **{**case.overrides(), **extra})
    if r.status != "finished":
        raise RuntimeError(f"tswm: {r.status}: {r.message}")
    end = r.final_state  # at t_stop (= t_end: finished), from the run itself: reading it evaluates no rows
    return Outcome(r.S1_max, end["v1"], [(_tswm_kind(e.guard), e.t) for e in r.events], r.nfev,
                   end["x1"] - r.settings["x1"], r.n_steps)


FIXED_COST_T_END = 1e-6  # s: one step, no event (at 1e-9 s a run from rest is refused: v1 stays below 100 atol)


def run_fixed_cost(case: Case, rtol: float, atol: float) -> Outcome:
    """``run_simulate`` to t_end = FIXED_COST_T_END: what a call costs without integrating
    (checks, one step, the Result; no row is read). Its Outcome is not compared with the reference."""
    return run_simulate(case, rtol, atol, t_end=FIXED_COST_T_END)


def timed_calls(scene: str, params, n: int, **settings) -> tuple[list[int], list[int], list[int], object]:
    """n whole ``simulate(scene, params(), **settings)`` calls back to back, each reading the status, the
    maxima and the final state: per call wall ns, thread-CPU ns and the kernel's ns (its compiled entry
    timed where simulate() calls it, ``simulate._direct``, its arguments' unboxing included; empty if
    simulate() has no such hook any more), and the last Result."""
    from tswm_runtime.simulation import simulate as S

    direct, kernel, wall, cpu = getattr(S, "_direct", None), [], [], []

    def timed_direct(*args):
        t0 = time.perf_counter_ns()
        try:
            return direct(*args)
        finally:
            kernel.append(time.perf_counter_ns() - t0)
    if direct is not None:
        S._direct = timed_direct
    try:
        for _ in range(n):
            c0, t0 = time.thread_time_ns(), time.perf_counter_ns()
            r = S.simulate(scene, params(), **settings)
            (r.status, r.S1_max, r.S2_max, r.final_state["v1"])
            wall.append(time.perf_counter_ns() - t0)
            cpu.append(time.thread_time_ns() - c0)
    finally:
        if direct is not None:
            S._direct = direct
    return wall, cpu, kernel, r


def fixed_cost(case: Case, calls: int, warmup: int = 50) -> dict:
    """The fixed cost of the case's simulate() call to t_end = FIXED_COST_T_END (one step) with a new m2
    each (``timed_calls``, after ``warmup`` untimed calls): medians in us of the whole call, its thread
    CPU, the kernel, and the fixed cost = whole call - kernel (the whole call if the kernel is not timed)."""
    def params():
        return {**dict(case.params), "m2": new_m2(case)}
    settings = {**case.overrides(), "t_end": FIXED_COST_T_END}
    timed_calls(case.scene, params, warmup, **settings)
    wall, cpu, kernel, r = timed_calls(case.scene, params, calls, **settings)
    fixed = [w - k for w, k in zip(wall, kernel)] if kernel else wall
    return {"case": case.name, "scene": case.scene, "calls": calls, "steps": r.n_steps,
            "whole_us": statistics.median(wall) / 1e3, "cpu_us": statistics.median(cpu) / 1e3,
            "kernel_us": statistics.median(kernel) / 1e3 if kernel else math.nan,
            "fixed_us": statistics.median(fixed) / 1e3, "fixed_p90_us": float(np.percentile(fixed, 90)) / 1e3}


def run_sweep(case: Case, rtol: float, atol: float, n: int) -> Outcome:
    """tswm's sweep of n identical cases (all cores), one whole call; the Outcome of the
    first row (the sweep table has no event times: events empty, counted in nfev only)."""
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.sweeps.sweep import sweep

    module = load_module(case.scene)
    row = dict(zip(module.PARAM_NAMES, module.PARAM_DEFAULTS)) | dict(case.params)
    P = np.tile([row[k] for k in module.PARAM_NAMES], (n, 1))
    table = sweep(case.scene, P, {"rtol": rtol, "atol": atol, **case.overrides()}).table
    if (table["status"] != "finished").any():
        raise RuntimeError(f"tswm sweep: {table['status'].value_counts().to_dict()}")
    first = table.iloc[0]
    return Outcome(float(first["S1m"]), float(first["v1"]), None, int(first["nfev"]), float(first["x1"]))


def run_peer(case: Case, method: str, rtol: float, atol: float) -> Outcome:
    """The peer ``method`` on the case, with a new m2."""
    return peer_run(method, rtol, atol, new_m2(case), list(case.loads), case.v0, case.t_end, m1=case.m1)


def errors(out: Outcome, ref: Outcome) -> dict:
    """err_S1: relative error of max |S1|; err_v1: error of v1(t_end) relative to
    max(|v1_ref|, 1 m/s); err_x1: relative error of x1(t_end) (the whole transient, where
    the others can sit on equilibria); err_t: largest absolute error of the event times
    when the event kinds agree in order (inf when they do not, NaN when not reported);
    err: the largest of them."""
    e = {"err_S1": abs(out.S1 - ref.S1) / abs(ref.S1),
         "err_v1": abs(out.v_end - ref.v_end) / max(abs(ref.v_end), 1.0),
         "err_x1": abs(out.x_end - ref.x_end) / abs(ref.x_end)}
    if out.events is None:
        e["err_t"] = math.nan
    elif [k for k, _ in out.events] != [k for k, _ in ref.events]:
        e["err_t"] = math.inf
    else:
        e["err_t"] = max((abs(t - tr) for (_, t), (_, tr) in zip(out.events, ref.events)), default=0.0)
    e["err"] = max(x for x in e.values() if not math.isnan(x))
    return e
