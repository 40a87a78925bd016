"""The paper gear run up from rest, then loaded by a step: where it stalls, by scipy's DOP853.

Written by hand on the formulas of ``paper_gear`` (imports nothing else of tswm): forward sliding
on flank a (a load F2 < 0 keeps phi > 0), x1' = v1, v1' = a1(v1, F2), integrated by DOP853 at
rtol 1e-13 with its own event location for v1 = 0. The run-up (F2 = 0) is one dense solution per
m2, shared by every load step of that m2; the loaded phase starts from its state at t_step.
At rest the self-locking gear sticks (rho(0) > gamma), so x1 at the stall is x1 for all later times.
"""
from __future__ import annotations

from typing import NamedTuple

from scipy.integrate import solve_ivp

from tswm_runtime.reference.paper_gear import accel

TIGHT = dict(method="DOP853", rtol=1e-13, atol=1e-15)


class Outcome(NamedTuple):
    """Whether v1 fell to 0 before t_end; the time and x1 of the stall (else t_end and x1 there)."""

    stalled: bool
    t: float
    x1: float


def run_up(m2: float, t_last: float):
    """The free run-up from rest on [0, t_last]: a dense solution sol(t) = (x1, v1)."""
    sol = solve_ivp(lambda t, y: (y[1], accel(y[1], 1, 0.0, m2)), (0.0, t_last), (0.0, 0.0), dense_output=True,
                    **TIGHT)
    assert sol.status == 0, sol.message
    return sol.sol


def loaded(free, m2: float, F2: float, t_step: float, t_end: float) -> Outcome:
    """From the run-up ``free`` (of this m2) at t_step on under the load F2 < 0, up to the stall or t_end."""
    def at_rest(t, y):
        return y[1]
    at_rest.terminal, at_rest.direction = True, -1
    sol = solve_ivp(lambda t, y: (y[1], accel(y[1], 1, F2, m2)), (t_step, t_end), free(t_step), events=at_rest,
                    **TIGHT)
    if sol.t_events[0].size:
        return Outcome(True, float(sol.t_events[0][0]), float(sol.y_events[0][0][0]))
    return Outcome(False, t_end, float(sol.y[0, -1]))
