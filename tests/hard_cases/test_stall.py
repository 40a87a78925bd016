"""Stalls (v1 falls to 0 into stick) located as precisely as other events, in simulate and in sweeps.

References: the closed form of a constant drive against a preloaded spring
(``tswm_runtime.reference.spring_stall``), and scipy's DOP853 at rtol 1e-13 on the paper gear's
hand formulas (``tswm_runtime.reference.runup_stall``, checked here against the quadrature
reference), never tswm's own output.
"""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from tswm_runtime.integration import segment
from tswm_runtime.reference import quadrature as q
from tswm_runtime.reference import runup_stall
from tswm_runtime.reference.spring_stall import stall
from tswm_runtime.simulation.simulate import simulate
from tswm_runtime.sweeps.sweep import sample_cases, sweep

sys.path.insert(0, str(Path(__file__).parents[1]))
from test_integrators import run as run_segment  # noqa: E402

METHODS = ("dopri5", "rosenbrock23", "auto")
SPRING = (Path(__file__).parent / "spring-stall.toml").read_text()
V1_0 = 0.5  # the scene's run.v1
# A load step that paper-runup (dopri5, rtol 1e-6) stepped across with one step whose error
# estimate was 0.25 of the tolerance and whose error was 1000 times it: the stall 290 rtol off.
UNLUCKY = {"m2": 278.44802199332855, "F2_after": -37362.988078332324, "t_step": 0.19774596711152623}


@pytest.fixture(scope="module")
def spring(scene_module):
    return scene_module(SPRING)


def closed_form(module, values):
    p = dict(zip(module.PARAM_NAMES, values))
    return stall(p["gamma"], p["friction_rho"], p["m1"], p["m2"], p["F1"], p["k"], p["preload"], p["x2_contact"],
                 v1_0=V1_0)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("rtol", [1e-3, 1e-6, 1e-9])
def test_spring_stall_at_the_closed_form_time_and_position(spring, method, rtol):
    """Free travel, the spring contact, half a swing up to v1 = 0, stick: the contact and the
    stall where the closed form puts them, x1 held there."""
    ref = closed_form(spring, spring.PARAM_DEFAULTS)
    r = simulate(spring, None, method=method, rtol=rtol, atol=rtol * 1e-3)
    assert r.status == "finished", r.message
    assert [(e.guard, e.from_mode, e.to_mode) for e in r.events] == [("load_contact", "fwd_a", "fwd_a"),
                                                                    ("v1", "fwd_a", "stick")]
    contact, rest = r.events
    assert abs(contact.t / ref.t_contact - 1) <= 10 * rtol
    assert abs(rest.x1 / ref.x1_stall - 1) <= 10 * rtol
    assert np.all(r.x1[r.t >= rest.t] == rest.x1)
    # v1 = 0 at the top of the swing, where x1 is stationary: its time is as good as v1 there,
    # which for ode23s (order 2) is its global error, about 20 rtol at 1e-6 and 200 at 1e-9.
    assert abs(rest.t / ref.t_stall - 1) <= (300 if method == "rosenbrock23" else 10) * rtol


@pytest.mark.parametrize("method", METHODS)
def test_spring_stall_sweep_positions_at_the_closed_form(spring, method):
    """200 random cases through the sweep's parallel batch: every one stalls (regimes 'TS') where
    the closed form says."""
    ranges = {"k": (1e4, 1e6), "F1": (100.0, 2000.0), "preload": (0.0, 500.0), "m2": (5.0, 50.0),
              "x2_contact": (1e-4, 0.05)}
    P = sample_cases(spring, 200, ranges, 7)
    rtol = 1e-6
    table = sweep(spring, P, {"method": method, "rtol": rtol, "atol": rtol * 1e-3}).table
    assert (table["regimes"] == "TS").all() and (table["status"] == "finished").all()
    x1 = np.array([closed_form(spring, row).x1_stall for row in P])
    assert np.abs(table["x1"].to_numpy() / x1 - 1).max() <= 10 * rtol


def test_runup_reference_agrees_with_the_quadrature():
    """The DOP853 reference of the loaded run-up against the 34-digit quadrature."""
    free = runup_stall.run_up(200.0, 0.3)
    got = runup_stall.loaded(free, 200.0, -20000.0, 0.3, 1.0)
    ref = q.solve(q.paper_wedge(200.0), [(0.0, 0.0), (0.3, -20000.0)], 0.0, 1.0)
    rest = [e for e in ref.events if e.kind == "v1"]
    assert got.stalled and len(rest) == 1
    assert got.t == pytest.approx(float(rest[0].t), rel=1e-11)
    assert got.x1 == pytest.approx(float(ref.x_at(rest[0].t)), rel=1e-11)


@pytest.fixture(scope="module")
def unlucky_reference():
    return runup_stall.loaded(runup_stall.run_up(UNLUCKY["m2"], 0.3), *UNLUCKY.values(), 1.0)


def test_first_step_after_the_load_step_is_not_trusted_blindly(unlucky_reference):
    """From synchronous speed under the load step, a first step of 4.72 ms has an error estimate
    of 0.25 tolerance and an error of 1000 tolerances (the estimate changes sign near it); the
    midpoint defect of its dense output (1550 tolerances) rejects it. So the segment's stall is
    where the reference has it whatever step it starts with."""
    import generated.paper_runup as model

    p = np.array([UNLUCKY["m2"], UNLUCKY["F2_after"], 0.0, 1.0])  # the load latched on (its guard t - 0 stays > 0)
    t0 = UNLUCKY["t_step"]
    for h0 in (4.72e-3, 4.75e-3, 1e-2, 0.0):
        r = run_segment(segment.DOPRI5, model, [model.V0], 1.0, t0=t0, rtol=1e-6, atol=1e-9, h0=h0, p=p,
                        directions=model.GUARD_DIRECTIONS[0])
        assert (r.status, model.GUARDS[r.k]) == (segment.EVENT, "v1"), h0
        assert abs(r.t / unlucky_reference.t - 1) <= 10e-6, h0


@pytest.mark.parametrize("method", METHODS)
def test_stall_after_a_load_step_in_simulate_and_sweep(unlucky_reference, method):
    """The run-up, the load step, the stall: the stall position within 10 rtol of the reference,
    in simulate and in the sweep's batch alike (290 rtol before the first step was checked)."""
    rtol = 1e-6
    r = simulate("paper-runup", UNLUCKY, method=method, rtol=rtol, atol=rtol * 1e-3)
    assert [(e.guard, e.to_mode) for e in r.events] == [("load_step", "fwd_a"), ("v1", "stick")]
    assert abs(r.events[-1].x1 / unlucky_reference.x1 - 1) <= 10 * rtol
    table = sweep("paper-runup", np.array([list(UNLUCKY.values())]),
                  {"method": method, "rtol": rtol, "atol": rtol * 1e-3}).table
    assert table["regimes"][0] == "TS"
    assert abs(table["x1"][0] / unlucky_reference.x1 - 1) <= 10 * rtol
    assert math.isclose(table["x1"][0], r.x1[-1], rel_tol=1e-14)
