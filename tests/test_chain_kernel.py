"""The chain's mode decision in compiled code (tswm_runtime/chains/rules.py) against the Python one of
tswm_common/chain_decision.py (which the derivation's document uses), over a grid of states and forces that
reaches every outcome: rest, each flank combination in each direction, no consistent mode, several; and
every decision of whole runs (the seat's and the switch's latches included) as the Python one."""
from __future__ import annotations

import itertools

import numpy as np

from tswm_runtime.chains import rules as compiled
from tswm_runtime.chains.kernel import decide_at
from tswm_runtime.hybrid import entry
from tswm_runtime.chains.run import chain_functions, chain_tables, decide, latches, run_chain
from tswm_runtime.model.scenes import load_chain_model

# Body 0 carries a force plus a flat motor table scaled by U^2 = p[voltage]^2 (the drive's force is a run-time
# number); springs on the other bodies make their forces follow q0, crossing 0 in one order in scene A and in the
# other in B, so that every sign of the three forces is met. In the one-stage scene a light input drives a heavy
# output through a self-locking wedge (a Painleve case).
MOTOR = 'motor = { speed = [0.0, 1000.0], torque = [10.0, 10.0] }\n'


def two_stages(name: str, f1: float, f2: float) -> str:
    return (f'name = "{name}"\n'
            '[[stage]]\nkind = "wedge"\ngamma = "20 deg"\nmu = 0.1\n'
            '[[stage]]\nkind = "wedge"\ngamma = "25 deg"\nmu = 0.1\n'
            f'[[body]]\nmass = "1 kg"\nforce = "-5 N"\n{MOTOR}'
            f'[[body]]\nmass = "1 kg"\nforce = "{f1!r} N"\nstiffness = "824 N/m"\n'
            f'[[body]]\nmass = "1 kg"\nforce = "{f2!r} N"\nstiffness = "1765 N/m"\n'
            '[run]\nt_end = 1.0\nv0 = 0.0\n')


ONE_STAGE = ('name = "grid-one"\n'
             '[[stage]]\nkind = "wedge"\ngamma = "5 deg"\nmu = 0.1405\n'
             f'[[body]]\nmass = "1 kg"\nforce = "-50 N"\n{MOTOR.replace("10.0", "100.0")}'
             '[[body]]\nmass = "1000 kg"\nforce = "0 N"\nstiffness = "20000 N/m"\n'
             '[run]\nt_end = 1.0\nv0 = 0.0\n')


def python_choice(module, t, y, p, current):
    """(outcome, mode) of the Python decision, as the compiled one reports it."""
    d = decide(module, t, y, p)
    if d.outcome == "unique":
        return "unique", compiled.RESTING if d.modes == ("stuck",) else module.MODES.index(d.modes[0])
    if d.outcome == "critical":
        return "critical", next(module.MODES.index(m) for m in d.modes if module.MODES.index(m) != current)
    return d.outcome, compiled.NO_MODE


def compiled_choice(module, t, y, p, current):
    outcome, mode = decide_at(entry.functions(0, module), chain_functions(module), chain_tables(module), t,
                              np.ascontiguousarray(y, dtype=np.float64), p, current)
    return compiled.OUTCOMES[outcome], mode


def decisions(module) -> set:
    """Every (outcome, mode) over the grid of voltages, q0 and v0, each the same compiled and in Python."""
    seen = set()
    for voltage, q0, v0 in itertools.product(np.linspace(0.0, 1.2, 13), np.linspace(-0.3, 0.3, 13), (-1.0, 0.0, 1.0)):
        y = np.array([q0, v0])
        p = latches(module, y, voltage)
        expected = python_choice(module, 0.0, y, p, compiled.RESTING)
        assert compiled_choice(module, 0.0, y, p, compiled.RESTING) == expected, (voltage, q0, v0)
        seen.add(expected)
    return seen


def test_the_compiled_decision_is_the_python_one_over_a_grid(chain_module):
    """Two stages: rest, and every flank combination in each direction (modes 0-7) somewhere on the grid."""
    seen = decisions(chain_module(two_stages("grid-a", 30.0, -30.0))) | decisions(chain_module(two_stages(
        "grid-b", -30.0, 30.0)))
    assert {mode for outcome, mode in seen if outcome == "unique"} == set(range(8)) | {compiled.RESTING}, seen


def test_the_compiled_decision_reports_no_mode_and_several_as_the_python_one(chain_module):
    seen = decisions(chain_module(ONE_STAGE))
    assert {("none", compiled.NO_MODE), ("several", compiled.NO_MODE)} <= seen, seen


def test_every_decision_of_a_valve_run_is_the_python_one():
    """The shipped valve drive (seat, torque switch and its delay, a cut, rest): the compiled run's modes after
    each event are those the Python decision gives at the state and latches the event recorded."""
    module = load_chain_model("mov")
    run = run_chain(module, t_end=3.0, v0=0.0, rtol=1e-8, atol=1e-10, t_out=np.linspace(0.0, 3.0, 7))
    assert run.status == "finished" and run.trip is not None
    guards = [e.guard for e in run.events]
    assert guards == ["start", "seat", "switch", "delay", "v0"]
    for event in run.events:
        _, y, p = event.seen
        outcome, mode = python_choice(module, event.t, y, p, event.from_mode)
        assert (event.outcome, event.to_mode) == (outcome, mode), event
