"""Schedules are data: a schedule of 999 breakpoints generates one law and one event function
(its breakpoints and values are arrays of the module), and its runs match references written
by hand, never tswm's own output: a closed form for a piecewise-constant force on a frictionless
wedge (a free mass), and scipy's DOP853 at rtol 1e-12 on a piecewise-linear law in x2
(numpy's interp), integrated piece by piece.
"""
import math
import re

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from derivation.codegen import generate_module
from derivation.model import build_model
from derivation.scene import parse_scene
from tswm_runtime.simulation.simulate import simulate

N = 999                                  # one below the documented limit of 1000 breakpoints
GAMMA = math.radians(45.0)
M1, M2 = 1.0, 1.0
M_EFF = M1 + M2 * math.tan(GAMMA) ** 2   # frictionless: a1 = (F1 + F2 tan(gamma)) / M_EFF in every mode

SCENE = """name = "{name}"
description = "a frictionless wedge under a schedule of {n} breakpoints"
equations = "consistent"
[wedge]
flanks = ["a", "b"]
gamma = "45 deg"
m1 = "1 kg"
m2 = "1 kg"
[friction]
law = "constant"
rho = "0 deg"
{drive}
{load}
[modes]
include = ["forward", "backward", "stick"]
[run]
t_end = "{t_end} s"
x1 = "0 m"
v1 = "0 m/s"
rtol = 1e-10
atol = 1e-12
method = "dopri5"
"""


def _quoted(numbers, unit: str) -> str:
    return ", ".join(f'"{float(x)!r} {unit}"' for x in numbers)


def schedule_scene(name: str, owner: str, variable: str, shape: str, at, values, other: str, t_end=1.0) -> str:
    """A scene whose ``owner`` (load or drive) follows the schedule; ``other`` is the other law's table."""
    table = (f'[{owner}]\nlaw = "schedule"\nvariable = "{variable}"\nshape = "{shape}"\n'
             f'at = [{_quoted(at, "s" if variable == "t" else "m")}]\nvalues = [{_quoted(values, "N")}]')
    drive, load = (table, other) if owner == "drive" else (other, table)
    return SCENE.format(name=name, n=len(at), drive=drive, load=load, t_end=t_end)


def _functions(source: str) -> dict[str, str]:
    """Each emitted function's source, by name."""
    parts = re.split(r"\n(?=@njit|def )", source)
    return {re.search(r"def (\w+)\(", part)[1]: part for part in parts if re.search(r"^(@njit.*\n)?def ", part)}


@pytest.mark.parametrize("owner,variable,shape", [("load", "t", "steps"), ("load", "x2", "linear"),
                                                  ("drive", "t", "linear"), ("drive", "x2", "steps")])
def test_a_999_breakpoint_schedule_generates_the_code_of_a_3_breakpoint_one(owner, variable, shape):
    """One law and one event function whatever the number of breakpoints: the emitted functions
    of 999 breakpoints are those of 3, character for character; only the arrays grow."""
    other = '[load]\nlaw = "constant"\nF2 = "-10 N"' if owner == "drive" else '[drive]\nlaw = "constant"\nF1 = "50 N"'
    sources = {}
    for n in (3, N):
        at = np.linspace(0.1, 0.9, n)
        values = -100.0 - 50.0 * np.arange(n + (shape == "steps"))
        scene = parse_scene(schedule_scene(f"long-{n}", owner, variable, shape, at, values, other), "test scene")
        sources[n] = generate_module(build_model(scene))
    short, long = _functions(sources[3]), _functions(sources[N])
    assert short == long and f"{owner}_schedule_piece" in long
    namespace = {}
    exec(sources[N].split("\nVECTOR = ")[0], namespace)      # the constants and arrays only: no compiling
    assert namespace["GUARDS"].count(f"{owner}_schedule") == 1 and len(namespace["GUARDS"]) <= 10
    assert namespace["GUARD_PIECES"][namespace["GUARDS"].index(f"{owner}_schedule")] == N + 1
    prefix = owner.upper()
    assert namespace[f"{prefix}_AT"].tolist() == np.linspace(0.1, 0.9, N).tolist()
    assert namespace[f"{prefix}_AT_SLOTS"].tolist() == [-1] * N


# --- a piecewise-constant drive in time on a free mass: a closed form -------------------------

T_AT = np.arange(1, N + 1) / 1000.0                       # 1 ms .. 999 ms
F1_STEPS = 100.0 + 60.0 * ((7 * np.arange(N + 1)) % 5)    # 100 .. 340 N, F1_k from breakpoint k on
F2_CONSTANT = -20.0


def _closed_form(t):
    """(x1, v1) at t from rest: the acceleration is constant between breakpoints."""
    edges = np.concatenate([[0.0], T_AT, [np.inf]])
    x, v = 0.0, 0.0
    for k in range(N + 1):
        a = (F1_STEPS[k] + F2_CONSTANT * math.tan(GAMMA)) / M_EFF
        dt = min(t, edges[k + 1]) - edges[k]
        if dt <= 0:
            break
        x, v = x + v * dt + 0.5 * a * dt * dt, v + a * dt
    return x, v


@pytest.mark.heavy
def test_a_999_step_drive_in_time_matches_the_closed_form(tmp_path):
    path = tmp_path / "steps.toml"
    path.write_text(schedule_scene("steps-in-time", "drive", "t", "steps", T_AT, F1_STEPS,
                                   f'[load]\nlaw = "constant"\nF2 = "{F2_CONSTANT!r} N"'))
    r = simulate(str(path), max_events=10 * N, points=1237)
    assert r.status == "finished", r.message
    assert [e.guard for e in r.events] == [f"drive_at{k}" for k in range(1, N + 1)]
    assert all(e.from_mode == e.to_mode == "fwd_a" for e in r.events)
    for e, t_k in zip(r.events, T_AT):   # located at the breakpoint, at most a few ulp past it
        assert t_k <= e.t <= t_k + 1e-14
    checked = [0, 1, 2, 499, 997, 998]
    for k in checked:
        x, v = _closed_form(r.events[k].t)
        assert r.events[k].v1 == pytest.approx(v, rel=1e-10) and r.events[k].x1 == pytest.approx(x, rel=1e-9)
    x, v = _closed_form(1.0)
    assert r.v1[-1] == pytest.approx(v, rel=1e-10) and r.x1[-1] == pytest.approx(x, rel=1e-9)
    rows = np.abs(r.t[:, None] - T_AT[None, :]).min(axis=1) > 1e-9    # rows off the breakpoints
    assert r.F1[rows].tolist() == F1_STEPS[np.searchsorted(T_AT, r.t[rows], side="right")].tolist()


# --- a piecewise-linear load in x2, passed up and down: scipy piece by piece ------------------

X_AT = 1.2 * np.arange(1, N + 1) / (N + 1)                  # 1.2 mm .. 1.199 m
F2_X = -200.0 * X_AT + 10.0 * np.sin(np.arange(N))         # a rough spring, -k x2, k = 200 N/m
F1_X = 100.0                                               # equilibrium near x2 = 0.5 m: x2 swings 0 .. 1 m
T_SWING = 0.45                                             # period 2 pi sqrt(M_EFF / k) = 0.63 s: up, then down


def _swing_reference():
    """DOP853 at rtol 1e-12 on (x1, v1) with F2 = interp(x2) stopped at every breakpoint, so that
    no step straddles a kink: the breakpoints passed (counted from 1) and the state at T_SWING."""
    tg = math.tan(GAMMA)

    def f(t, y):
        return [y[1], (F1_X + np.interp(y[0] * tg, X_AT, F2_X) * tg) / M_EFF]

    t, y, piece, passed = 0.0, np.array([0.0, 0.0]), 0, []
    while True:
        events = []
        if piece > 0:
            events.append(lambda t, y, b=X_AT[piece - 1]: y[0] * tg - b)
            events[-1].direction, events[-1].terminal = -1, True
        if piece < N:
            events.append(lambda t, y, b=X_AT[piece]: y[0] * tg - b)
            events[-1].direction, events[-1].terminal = 1, True
        sol = solve_ivp(f, (t, T_SWING), y, method="DOP853", rtol=1e-12, atol=1e-14, events=events)
        if sol.status == 0:
            return passed, sol.y[:, -1]
        hit = next(i for i, te in enumerate(sol.t_events) if te.size)
        up = events[hit].direction > 0
        passed.append(piece + 1 if up else piece)
        piece += 1 if up else -1
        t, y = sol.t_events[hit][0], sol.y_events[hit][0]


@pytest.mark.heavy
def test_a_999_breakpoint_linear_load_in_x2_passed_both_ways_matches_scipy(tmp_path):
    """The load reads each side of a breakpoint with its own piece, going up and coming back."""
    path = tmp_path / "swing.toml"
    path.write_text(schedule_scene("swing-in-x2", "load", "x2", "linear", X_AT, F2_X,
                                   f'[drive]\nlaw = "constant"\nF1 = "{F1_X!r} N"', t_end=T_SWING))
    passed, (x1, v1) = _swing_reference()
    top = max(passed)       # up through 833 breakpoints, then down through 327 of them
    assert passed == [*range(1, top + 1), *range(top, passed[-1] - 1, -1)] and top - passed[-1] > 300
    r = simulate(str(path), max_events=10 * N)
    assert r.status == "finished", r.message
    breakpoints = [e for e in r.events if e.guard != "v1"]
    assert [e.guard for e in breakpoints] == [f"load_at{k}" for k in passed]
    assert [(e.from_mode, e.to_mode) for e in r.events if e.guard == "v1"] == [("fwd_a", "bwd_a")]
    assert r.x1[-1] == pytest.approx(x1, rel=1e-7) and r.v1[-1] == pytest.approx(v1, rel=1e-6)
    x2 = r.x2
    inside = (x2 > X_AT[0]) & (x2 < X_AT[-1])
    assert r.F2[inside] == pytest.approx(np.interp(x2[inside], X_AT, F2_X), rel=1e-12, abs=1e-9)
