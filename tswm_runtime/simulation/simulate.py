"""Simulate one scene: check the inputs, run the mode machine, return a ``Result``.

``simulate("paper", {"F2": -5000.0})`` loads the generated module of a shipped scene
(or takes a module), validates every input with a message that names it, runs
the mode machine (``entry.integrate``), which keeps its steps, and returns a Result that
evaluates the states and a1, S1, S2, F1, F2 at the output times from them when first read.
"""
from __future__ import annotations

import math
import sys
from types import ModuleType
from typing import NamedTuple

import numpy as np

from tswm_common import units
from tswm_runtime.common.memo import overrides_key, remember, remembered
from tswm_runtime.jit import coldstart

coldstart.announce(("integrate",))  # before the next imports compile the kernels, if not cached
from tswm_runtime.hybrid import entry  # noqa: E402
from tswm_runtime.hybrid.entry import Sizes  # noqa: E402

from tswm_runtime.integration import segment  # noqa: E402

from tswm_runtime.model import checks, modes  # noqa: E402
from tswm_runtime.model.scenes import load_model  # noqa: E402
from tswm_runtime.model.values import ValueInputError, quantities, si_value  # noqa: E402
from tswm_runtime.hybrid.machine import INCONSISTENT, NOT_FINITE  # noqa: E402
from tswm_runtime.jit.cache_guard import entry_point  # noqa: E402
from tswm_runtime.jit.structures import ModeTables, Settings, Start  # noqa: E402
from tswm_runtime.results.result import Result, RunRecord, first_non_finite  # noqa: E402
from tswm_runtime.results.rows import MAX_LOGGED_STEPS, Rows, output_times, state_names  # noqa: E402

coldstart.done()

METHODS = {"dopri5": segment.DOPRI5, "rosenbrock23": segment.ROSENBROCK23, "rodas4": segment.RODAS4,
           "auto": segment.AUTO}
# Below 1e-13 a step's error is rounding; above 1e-2 the error per step is not controlled any more
# (paper-runup against rtol 1e-12: S1 max 0.24 % off at rtol 1e-2, 90 % off at rtol 0.1).
RTOL_RANGE = (1e-13, 1e-2)
# The tightest rtol each method delivers: every output row within 10 rtol of the dense reference
# (tests/hard_cases/test_sample_accuracy.py), and why not below. Measured worst rows on its three cases:
# rosenbrock23 3.9 rtol at 1e-9, 38.6 at 1e-10; dopri5 3.8 at 1e-12, 37.7 at 1e-13; rodas4 and auto
# (which switches to rodas4) 3.8 at 1e-12 (below 1e-12 the reference itself, 1.7e-12 of |v1|, cannot tell).
METHOD_RTOL_MIN = {
    "dopri5": (1e-12, "below it the rows cannot be shown to be within 10 rtol (the reference is good to "
                      "1.7e-12)"),
    "rosenbrock23": (1e-9, "its step tolerance stops at 1e-12, so below 1e-9 its rows are about "
                           "1e-8/rtol rtol off (39 rtol at 1e-10); use dopri5 for a tighter rtol"),
    "rodas4": (1e-12, "below it the rows cannot be shown to be within 10 rtol (the reference is good to "
                      "1.7e-12)"),
    "auto": (1e-12, "below it the rows cannot be shown to be within 10 rtol (the reference is good to "
                    "1.7e-12)"),
}
# atol is absolute on x1 [m] and v1 [m/s]: below 1e-20 the error estimate underflows (NaN steps), above 1 m
# it accepts any step and the answer is silently wrong. Within that range a run is judged after it ends:
# atol must stay below ATOL_SCALE x the largest |state| it reached (atol 1 on paper-runup, where |v1|
# reaches 7.85 m/s: S1 max 90 % off; atol 1e-3: 1.6e-5 off).
ATOL_RANGE = (1e-20, 1.0)
ATOL_SCALE = RTOL_RANGE[1]
RUN_QUANTITIES = {"t_end": "time", "x1": "length", "v1": "velocity", "gap": "length"}   # held to units.LIMITS
DEFAULT_POINTS = 1001
DEFAULT_MAX_EVENTS = 1000
# Sizes that allocate memory up front (docs/promises.md): output points and the event log.
MAX_POINTS = 10**6           # about 100 MB of arrays and 150 MB of CSV at the limit
MAX_EVENTS = 10**6           # about 60 MB of event log at the limit
MAX_STEPS = 10**9            # a step budget (no memory); keeps it an int64
BYTES_PER_POINT = 8 * 16     # t, states, mode, a1, S1, S2, F1, F2 ... (estimate for messages)
BYTES_PER_EVENT = 8 * 7


class SimulationInputError(ValueError):
    """An input to ``simulate`` that is out of its allowed range; the message names it."""


def _check(ok: bool, field: str, value, allowed) -> None:
    """Raise naming ``field`` unless ``ok``; ``allowed``: the rule, or a callable that words it
    (built only on failure: formatting every rule on every call cost ~8 us of a simulate())."""
    if not ok:
        raise SimulationInputError(f"{field} = {value!r}: must be {allowed() if callable(allowed) else allowed}")


def _finite(field: str, value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise SimulationInputError(f"{field} = {value!r}: must be a number") from None
    _check(math.isfinite(value), field, value, "finite")
    return value


def unknown_parameter(module: ModuleType, name: str) -> str:
    """Why ``name`` cannot be set: the free parameters, and whether it is a fixed one."""
    fixed = f"; {name} is fixed in this scene (make it free in the scene file)" if name in module.FIXED else ""
    free = ", ".join(module.PARAM_NAMES) or "none"
    return f"scene {module.SCENE!r} has no such free parameter (free: {free}){fixed}"


def with_latches(module: ModuleType, P: np.ndarray) -> np.ndarray:
    """Rows of free parameters extended by the module's latch slots (inf: not yet latched)."""
    P = np.atleast_2d(np.asarray(P, dtype=np.float64))
    latches = np.full((P.shape[0], len(getattr(module, "LATCH_NAMES", ()))), np.inf)
    return np.ascontiguousarray(np.hstack([P, latches]))


def parameter_vector(module: ModuleType, params: dict | None) -> np.ndarray:
    """The free parameters (scene defaults, overridden by ``params``) plus latches (inf),
    checked against the scene file's rules for them. A finite float within its quantity's limits
    is taken as it is (``_free``); any other value goes through ``si_value`` and ``_finite``, which
    word why it is refused."""
    index, row, largest, smallest, latches, holds = _free(module)
    row = list(row)
    for name, value in (params or {}).items():
        j = index.get(name)
        if j is not None and type(value) is float and abs(value) <= largest[j] and (
                abs(value) >= smallest[j] or value == 0.0):
            row[j] = value
        else:
            row[_index(module, name)] = _free_value(module, name, value)
    try:
        ok = holds(row)
    except ArithmeticError:
        ok = False
    if not ok:
        problem = checks.row_violation(module, tuple(row))
        if problem:
            raise SimulationInputError(problem)
    return np.array(row + latches, dtype=np.float64)


def _index(module: ModuleType, name: str) -> int:
    try:
        return module.PARAM_NAMES.index(name)
    except ValueError:
        raise SimulationInputError(f"parameter {name!r}: {unknown_parameter(module, name)}") from None


def _free_value(module: ModuleType, name: str, value) -> float:
    """A free parameter's value in SI (``si_value``), finite, or a message naming it and the value."""
    try:
        value = si_value(module, name, value)
    except ValueInputError as error:
        raise SimulationInputError(str(error)) from None
    return value if type(value) is float and math.isfinite(value) else _finite(f"parameter {name}", value)


def _free(module: ModuleType) -> tuple:
    """({free parameter: index}, the defaults, per parameter the largest and the smallest nonzero |value|
    its quantity allows (``units.LIMITS``; none: any finite value), the latches (inf), the scene's rules
    (``checks.row_check``)), once per module."""
    def build():
        quantity = quantities(module)
        limits = [units.LIMITS.get(quantity[name][1], (None, sys.float_info.max)) for name in module.PARAM_NAMES]
        return ({name: j for j, name in enumerate(module.PARAM_NAMES)}, tuple(module.PARAM_DEFAULTS),
                [hi for _, hi in limits], [lo or 0.0 for lo, _ in limits],
                [math.inf] * len(getattr(module, "LATCH_NAMES", ())), checks.row_check(module))
    return remembered(_FREE, module, build)


_FREE: dict = {}


def initial_state(module: ModuleType, run: dict) -> tuple[np.ndarray, np.ndarray]:
    """(y0, quad): the states at t = 0 (the gap's rate 0: the bodies start together; the stem at
    rest where it is held), and x1 as the quadrature's start if it is no state."""
    start = {"x1": run["x1"], "v1": run["v1"], "gap": run.get("gap", 0.0), "gap_rate": 0.0, "x3": 0.0, "v3": 0.0}
    y0 = np.array([start[name] for name in module.STATES], dtype=np.float64)
    return y0, (np.array([run["x1"]]) if module.STATES == ("v1",) else np.empty(0))


class Prepared(NamedTuple):
    """What a run's settings alone decide, worked out once per module and settings (``prepared``): the
    validated settings, the initial state and its integral (``initial_state``; the kernel never writes
    them: shared by every run with these settings), their width and names (``state_names``), the
    method's code, the kernel's Settings and ModeTables, and the key of the step log's size
    (``_STEPS_NEEDED``)."""

    run: dict
    y0: np.ndarray
    quad: np.ndarray
    width: int
    names: tuple
    method: int
    settings: Settings
    tables: ModeTables
    steps_key: tuple


def settings(module: ModuleType, overrides: dict) -> dict:
    """The run settings: the scene's [run] table with ``overrides`` applied, validated (a new dict)."""
    return dict(prepared(module, overrides).run)


def prepared(module: ModuleType, overrides: dict) -> Prepared:
    """The Prepared run for ``overrides`` (validated: ``settings``), remembered per module and
    overrides: validating and building the initial state cost ~8 us a call. Its run dict is shared:
    copy it to change it."""
    try:  # the key tells 1 from True and 1.0, and 0.0 from -0.0 (equal in Python, not here)
        key = (module, *overrides_key(overrides))
        known = _PREPARED_RUNS.get(key)
    except TypeError:  # an unhashable value: validated below, which names it
        key = known = None
    if known is not None:
        return known
    run = _validated(module, overrides)
    y0, quad = initial_state(module, run)
    method = METHODS[run["method"]]
    known = Prepared(run, y0, quad, y0.size + quad.size, state_names(module, y0.size + quad.size), method,
                     entry.settings(method, y0.size, t_end=run["t_end"], rtol=run["rtol"], atol=run["atol"],
                                    hmax=run["hmax"], max_steps=run["max_steps"]),
                     modes.tables(module), (module, run["method"], run["rtol"], run["atol"], run["t_end"], run["hmax"]))
    if key is not None:
        remember(_PREPARED_RUNS, key, known, 1024)
    return known


_PREPARED_RUNS: dict = {}


def _validated(module: ModuleType, overrides: dict) -> dict:
    run = {"gap": 0.0, **module.RUN, "points": DEFAULT_POINTS, "max_events": DEFAULT_MAX_EVENTS, "hmax": math.inf}
    for key, value in overrides.items():
        _check(key in run, "setting", key, lambda: f"one of {', '.join(run)}")
        if value is not None:
            run[key] = value
    _check(run["method"] in METHODS, "method", run["method"], lambda: f"one of {', '.join(METHODS)}")
    for key in ("t_end", "x1", "v1", "gap", "rtol", "atol", "hmax"):
        run[key] = float(run[key]) if key == "hmax" else _finite(key, run[key])
    for key, quantity in RUN_QUANTITIES.items():
        problem = units.out_of_bounds(run[key], quantity)
        if problem:
            raise SimulationInputError(f"{key} = {run[key]!r}: {problem.replace('value', key, 1)}")
    lo, hi = RTOL_RANGE
    _check(lo <= run["rtol"] <= hi, "rtol", run["rtol"], lambda: f"in [{lo:g}, {hi:g}]")
    least, why = METHOD_RTOL_MIN[run["method"]]
    _check(run["rtol"] >= least, "rtol", run["rtol"], lambda: f">= {least:g} with method {run['method']}: {why}")
    lo_a, hi_a = ATOL_RANGE
    _check(lo_a <= run["atol"] <= hi_a, "atol", run["atol"],
           lambda: f"in [{lo_a:g}, {hi_a:g}] (absolute, in m and m/s)")
    _check(run["t_end"] > 0.0, "t_end", run["t_end"], "> t0 = 0 s")
    _check(run["gap"] >= 0.0, "gap", run["gap"], ">= 0 m (the gap from flank a)")
    _check(run["hmax"] > 0.0, "hmax", run["hmax"], "> 0 s")
    for key, top in (("max_steps", MAX_STEPS), ("points", MAX_POINTS), ("max_events", MAX_EVENTS)):
        _check(isinstance(run[key], int) and not isinstance(run[key], bool) and 1 <= run[key] <= top, key,
               run[key], lambda: _integer_rule(key, top))
    return run


def check_atol_scale(module: ModuleType, atol: float, scales: list[float]) -> None:
    """Refuse a run whose atol is loose against the states it reached (``scales``: the largest |value|
    of each state over the run, the integral of v1 last when x1 is no state; ``entry.summarize``):
    there the error control lets a step be off by more than the loosest rtol allowed. A run whose
    states all stay 0, or one with a NaN among them, has nothing to judge."""
    total = sum(scales)  # NaN if any is NaN (all are >= 0)
    if not scales or total != total:
        return
    largest = max(scales)
    if 0.0 < largest < math.inf and atol > ATOL_SCALE * largest:
        k = scales.index(largest)
        name = (*module.STATES, "x1")[k]
        unit = "m/s" if name.startswith("v") or name.endswith("rate") else "m"
        raise SimulationInputError(
            f"atol = {atol:g}: must be <= {ATOL_SCALE:g} x the largest |state| this run reached "
            f"(|{name}| = {scales[k]:.6g} {unit}), i.e. <= {ATOL_SCALE * scales[k]:.3g}: a looser atol lets "
            f"steps be off by more than rtol {RTOL_RANGE[1]:g} allows")


def _integer_rule(key: str, top: int) -> str:
    return (f"an integer in [1, {top:.0e}]".replace("e+0", "e").replace("e+", "e")
            + (f" (it sizes memory up front: about {memory_estimate(key, top) / 1e6:.0f} MB at the limit)"
               if key != "max_steps" else ""))


def memory_estimate(key: str, count: int) -> float:
    """Bytes allocated up front for ``count`` output points or events (an estimate, for messages)."""
    return count * (BYTES_PER_POINT if key == "points" else BYTES_PER_EVENT)


PROGRESS_EVERY = 2.0  # seconds between progress lines of an interruptible run


def _in_a_thread(kernel, args: tuple, counters: np.ndarray):
    """kernel(*args) in a worker thread (the kernel releases the GIL), so that Ctrl-C
    reaches Python at once (KeyboardInterrupt; the abandoned worker is a daemon thread),
    and a long run prints its step count (read live from counters) every PROGRESS_EVERY s."""
    import sys
    import threading
    import time

    box = {}

    def work():
        try:
            box["out"] = kernel(*args)
        except BaseException as error:  # noqa: BLE001 - raised again in the calling thread
            box["error"] = error

    worker = threading.Thread(target=work, daemon=True)
    start = next_report = time.monotonic() + PROGRESS_EVERY
    worker.start()
    while worker.is_alive():
        worker.join(0.05)
        if time.monotonic() >= next_report:
            next_report += PROGRESS_EVERY
            print(f"  ... running: {int(counters[segment.N_STEPS]):,} steps after "
                  f"{time.monotonic() - start + PROGRESS_EVERY:.0f} s (Ctrl-C stops)", file=sys.stderr, flush=True)
    if "error" in box:
        raise box["error"]
    return box["out"]


_LOADED: dict = {}


def _load(model: str):
    """``load_model(model)``, remembered for a shipped scene name while its module stays the one
    imported (the import lookup and contract check cost ~8 us a call). A .py or .toml path is
    loaded afresh on every call."""
    module = _LOADED.get(model)
    if module is not None and sys.modules.get(module.__name__) is module:
        return module
    coldstart.announce((), model)
    module = load_model(model)
    coldstart.done()
    if not str(model).endswith((".py", ".toml")):
        _LOADED[model] = module
    return module


def method_step(method: str) -> None:
    """Make the steps of ``method`` (a METHODS name, ``segment.method_steps``) ready: on their first
    use in this process they compile, if not cached, after ``coldstart`` has said so."""
    if method not in _PREPARED:
        coldstart.announce(coldstart.STEP_GROUPS[method])
        segment.method_steps(METHODS[method])
        coldstart.done()
        _PREPARED.add(method)


_PREPARED: set = set()  # methods whose step is compiled or loaded in this process
def _direct(kernel, args: tuple, counters: np.ndarray):
    return entry_point(kernel)(*args)


def _direct_in_a_thread(kernel, args: tuple, counters: np.ndarray):
    return _in_a_thread(entry_point(kernel), args, counters)


def _first_non_finite(module: ModuleType, t: np.ndarray, values: dict, maxima: list[float]):
    """(name, time, value) of the run's first inf or NaN in its series, else in the maxima of S1
    and S2 (found between output points; ``maxima``: (|value|, value, t) per observable, in a row);
    None if all are finite."""
    found = [(f"{name} max", maxima[3 * k + 2], maxima[3 * k + 1]) for k, name in enumerate(module.OBSERVABLES)]
    return first_non_finite(t, values) or next((m for m in found if not math.isfinite(m[2])), None)


def _plan(run: dict, needed: tuple[int, int]) -> tuple[tuple, np.ndarray]:
    """(the step log's capacity (steps, segments), the output times the kernel writes rows at) for a
    run that needs ``needed`` steps and segments: twice that, at least MIN_STEP_CAPACITY, at most
    MAX_LOGGED_STEPS, all steps kept and no rows; or, beyond MAX_LOGGED_STEPS, the rows written as
    the run goes and the last step kept."""
    steps, segments = needed
    if steps <= MAX_LOGGED_STEPS and segments <= MAX_LOGGED_STEPS:
        return (min(MAX_LOGGED_STEPS, max(MIN_STEP_CAPACITY, 2 * steps)),
                min(MAX_LOGGED_STEPS, max(MIN_STEP_CAPACITY, 2 * segments))), _NO_TIMES
    return (1, 1), output_times(run["t_end"], run["points"]).copy()


MIN_STEP_CAPACITY = 256
# (module, method, rtol, atol, t_end, hmax): (steps, segments) of the last run with these settings (runs
# with other tolerances in between, as in a work-precision benchmark, do not make it run twice)
_STEPS_NEEDED: dict = {}


def _integrate(module: ModuleType, p: np.ndarray, ready: Prepared, interruptible: bool) -> tuple:
    """entry.run for ``simulate``: every step kept and no output rows (run again with a larger step
    log if it filled up), or, for a run of more than MAX_LOGGED_STEPS steps, run again writing its
    rows at the output times, its log keeping the last step only. ``p``: the parameter vector with
    its latches unset (inf), which the run sets. Returns (the kernel's outcome, the RunArrays, the
    counters as a list, whether the run wrote rows)."""
    run = ready.run
    known = _STEPS_NEEDED.get(ready.steps_key, (0, 0))
    capacity, t_out = _plan(run, known)
    start = Start(0.0, ready.y0, ready.quad, -1, p)
    n_observables = len(module.OBSERVABLES)
    while True:
        outcome, arrays = entry.run(ready.method, module, ready.tables, start, ready.settings, t_out,
                                    Sizes(ready.width, p.size, n_observables, *capacity, run["max_events"]),
                                    _direct_in_a_thread if interruptible else _direct)
        head = arrays.ints[:N_HEAD].tolist()   # the counters, then the step log's count
        needed = tuple(head[N_COUNTERS:])
        if needed != known:
            known = remember(_STEPS_NEEDED, ready.steps_key, needed)
        if t_out.size or (needed[0] <= capacity[0] and needed[1] <= capacity[1]):
            return outcome, arrays, head[:N_COUNTERS], bool(t_out.size)
        capacity, t_out = _plan(run, needed)
        p[len(module.PARAM_NAMES):] = math.inf  # the latches unset again


N_COUNTERS = entry.N_COUNTERS
N_HEAD = N_COUNTERS + 2
_NO_TIMES = np.empty(0)


def simulate(model: str | ModuleType, params: dict | None = None, *, interruptible: bool = False,
             **overrides) -> Result:
    """Run a scene. ``model``: a shipped scene name, a scene file (.toml), a path to a generated
    module, or the module; ``params``: free parameters by name, numbers in SI or strings with a
    unit ("-5 kN"); ``overrides``: run settings (t_end,
    x1, v1, rtol, atol, method, max_steps, points, max_events, hmax). ``interruptible``:
    run the kernel in a thread so that Ctrl-C stops a long run at once (the CLI does).
    The status, events, maxima, load factors and final state come from the run; the per-point
    series (``Result.t``, ``S1``, ...) are evaluated from its steps when first read."""
    module = model if isinstance(model, ModuleType) else _load(model)
    p = parameter_vector(module, params)
    ready = prepared(module, overrides)
    run, width = ready.run, ready.width
    method_step(run["method"])
    (status, t_stop, n_ev, last, need, first), arrays, counts, wrote = _integrate(module, p, ready, interruptible)
    head = arrays.floats[:2 * width + 3 * len(module.OBSERVABLES)].tolist()
    largest, final, maxima = head[:width], head[width:2 * width], head[2 * width:]
    rows = Rows(module, arrays, run["t_end"], run["points"], p, wrote)
    found = last_point = None
    # (a run that stopped at its start, first < 0, integrated nothing: its maxima are NaN, no defect)
    if status != INCONSISTENT and first >= 0 and (status == NOT_FINITE or not all(map(math.isfinite, maxima[1::3]))):
        values = {k: v for k, v in rows.values().items() if k not in ("mode", "p", "y", "x2", "v2")}
        t_kept = values.pop("t")
        found = _first_non_finite(module, t_kept, values, maxima)
        last_point = (float(t_kept[-1]), {k: float(v[-1]) for k, v in values.items()}) if t_kept.size else None
    if found is not None:
        status = NOT_FINITE
    else:
        check_atol_scale(module, run["atol"], largest)
    record = RunRecord(module, p, arrays, n_ev, first, last, status, need, ready.y0, found, last_point)
    return Result.build(record, run, rows, dict(zip(ready.names, final)), maxima, counts, t_stop)
