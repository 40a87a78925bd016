"""What ``tswm generate`` costs: every shipped scene from empty caches, scenes with N-breakpoint
schedules, and what each event of such a schedule costs in a run.

Generation: ``python -m tswm_runtime.cli generate`` in a fresh process that writes no bytecode (cold:
SymPy derives the mechanics in that process, no stored derivation), wall seconds from the parent and
the CPU seconds of the process. Schedules: the load or the drive as a schedule (in t and in x2, steps
and linear, ``SHAPES``) of N breakpoints. Events: a frictionless wedge (rho = 0) driven by an N-step
drive schedule in time over 1 s passes N breakpoints; the run's wall time (the model compiled and
warm, best of 3), its events, and the cost of one call of the model's ``guards`` (which event
location calls at every sample).
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHAPES = (("load", "t", "steps"), ("load", "x2", "linear"), ("drive", "t", "linear"), ("drive", "x2", "steps"))
HEAD = """name = "{name}"
description = "a schedule of {n} breakpoints"
equations = "consistent"
[wedge]
flanks = ["a", "b"]
gamma = "4.76 deg"
m1 = "11.8 kg"
m2 = "200 kg"
[friction]
law = "{friction}"
{friction_params}
{drive}
{load}
[modes]
include = ["forward", "backward", "stick"]
[run]
t_end = "1 s"
x1 = "0 m"
v1 = "0 m/s"
rtol = 1e-6
atol = 1e-9
method = "dopri5"
"""
SLOWEST_SCENES = ("mesh", "backlash", "valve-travel")  # the slowest to generate (docs/architecture.md): --quick
PAPER_FRICTION = ("velocity", "a = 0.161\nb = 0.535\nc = 0.088")
FRICTIONLESS = ("constant", 'rho = "0 deg"')
KLOSS = '[drive]\nlaw = "kloss"\nFmax = "2178 N"\nV0 = "7.85 m/s"\nVmax = "6.5 m/s"'


def shipped_scenes() -> list[str]:
    """The shipped single-stage scenes (``derivation/scenes/*.toml``) by name."""
    return sorted(p.stem for p in (ROOT / "derivation" / "scenes").glob("*.toml"))


def schedule(owner: str, variable: str, shape: str, n: int) -> str:
    """An n-breakpoint schedule table, breakpoints evenly over 1 s or 0.1 m."""
    span, unit = (1.0, "s") if variable == "t" else (0.1, "m")
    at = ", ".join(f'"{span * (k + 1) / (n + 1):.9g} {unit}"' for k in range(n))
    sign, base = (-1, 500.0) if owner == "load" else (1, 900.0)
    count = n + 1 if shape == "steps" else n
    values = ", ".join(f'"{sign * (base + 300.0 * ((7 * k) % 5)):.6g} N"' for k in range(count))
    return f'[{owner}]\nlaw = "schedule"\nvariable = "{variable}"\nshape = "{shape}"\nat = [{at}]\nvalues = [{values}]'


def scene(owner: str, variable: str, shape: str, n: int, friction=PAPER_FRICTION) -> tuple[str, str]:
    """(name, scene file text) of a wedge whose ``owner`` (load or drive) is an n-breakpoint schedule."""
    name = f"{owner}-{variable}-{shape}-{n}"
    other = '[load]\nlaw = "constant"\nF2 = "-500 N"' if owner == "drive" else KLOSS
    table = schedule(owner, variable, shape, n)
    drive, load = (table, other) if owner == "drive" else (other, table)
    return name, HEAD.format(name=name, n=n, friction=friction[0], friction_params=friction[1], drive=drive,
                             load=load)


def generate_time(root: Path, scene_ref: str, out: Path, timeout: float) -> tuple[float, float, str]:
    """(wall s, CPU s, outcome) of a cold ``tswm generate`` of ``scene_ref`` (a shipped name or a path)."""
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONDONTWRITEBYTECODE": "1"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-m", "tswm_runtime.cli", "generate", scene_ref, "-o", str(out)],
                              cwd=root, env=env, capture_output=True, timeout=timeout)
        outcome = "ok" if done.returncode == 0 else f"exit {done.returncode}"
    except subprocess.TimeoutExpired:
        outcome = f"not done in {timeout:g} s"
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), outcome


def generate_runs(scenes=None, sizes=(3, 999), shapes=SHAPES, root: Path = ROOT, timeout: float = 600.0,
                  log=print) -> list[dict]:
    """``generate_time`` of each shipped scene in ``scenes`` (default all) and of each schedule scene
    (``shapes`` x ``sizes``): rows of kind ("shipped" or "schedule"), scene, breakpoints, wall, CPU,
    outcome, the 1-minute load before."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        jobs = [("shipped", name, name, None) for name in (shipped_scenes() if scenes is None else scenes)]
        for n in sizes:
            for shape in shapes:
                name, text = scene(*shape, n)
                (work / f"{name}.toml").write_text(text)
                jobs.append(("schedule", name, str(work / f"{name}.toml"), n))
        for kind, name, ref, n in jobs:
            load = os.getloadavg()[0]
            wall, cpu, outcome = generate_time(root, ref, work / "out", timeout)
            rows.append({"kind": kind, "scene": name, "breakpoints": n, "wall_s": wall, "cpu_s": cpu,
                         "outcome": outcome, "load_1min": load})
            log(f"generate {name:22s} wall {wall:6.1f} s  CPU {cpu:6.1f} s  {outcome}")
    return rows


def event_rate(path: Path) -> tuple[float, int, float]:
    """(best wall s of 3 runs, events, s per guards call) of the scene at ``path``, after a warm-up
    run (compiling)."""
    import numpy as np
    from tswm_runtime.model.scenes import load_model
    from tswm_runtime.simulation.simulate import parameter_vector, simulate
    result = simulate(str(path), max_events=10_000)
    best = min(_timed(simulate, str(path)) for _ in range(3))
    module = load_model(str(path))
    p = np.concatenate([parameter_vector(module, None)[:len(module.PARAM_NAMES)], np.zeros(len(module.LATCH_NAMES))])
    y, g, calls = np.full(len(module.STATES), 1.0), np.zeros(len(module.GUARDS)), 1_000_000
    _call_guards(module.guards, y, p, g, 1)
    start = time.perf_counter()
    _call_guards(module.guards, y, p, g, calls)
    return best, len(result.events), (time.perf_counter() - start) / calls


def event_runs(sizes=(3, 999), log=print) -> list[dict]:
    """``event_rate`` of the frictionless wedge with an N-step drive schedule for each N in ``sizes``."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            name, text = scene("drive", "t", "steps", n, friction=FRICTIONLESS)
            path = Path(tmp) / f"{name}.toml"
            path.write_text(text)
            load = os.getloadavg()[0]
            wall, events, call = event_rate(path)
            rows.append({"breakpoints": n, "events": events, "run_s": wall, "events_per_s": events / wall,
                         "guards_call_s": call, "load_1min": load})
            log(f"events (frictionless, drive steps in t) {n:4d} breakpoints: {events:4d} events in "
                f"{wall * 1e3:7.2f} ms, {events / wall:9.0f} events/s; guards() {call * 1e9:.0f} ns a call")
    return rows


def _call_guards(guards, y, p, g, calls: int) -> None:
    """``calls`` calls of the model's guards at t = 0.5 s, from compiled code (as the kernels call it)."""
    from numba import njit

    @njit
    def loop(guards, y, p, g, calls):
        for i in range(calls):
            guards(0, 0.5 + 1e-12 * i, y, p, g)
    loop(guards, y, p, g, calls)


def _timed(simulate, path: str) -> float:
    start = time.perf_counter()
    simulate(path, max_events=10_000)
    return time.perf_counter() - start
