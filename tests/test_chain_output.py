"""What `tswm simulate` prints of a chain is true: internal forces the statics fix are printed as values,
the hold verdict says what the run showed, the stall margin says why it is missing. Values by hand."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from tswm_common.chain_decision import Statics, decide_numbers
from tswm_runtime.simulation.drive_train import answers, drive_train_lines

DEG = math.pi / 180


def psi(gamma_deg: float, mu: float) -> tuple[float, float]:
    """A wedge's FTFs by hand: tan(gamma + rho), tan(gamma - rho), tan(rho) = mu."""
    rho = math.atan(mu)
    return math.tan(gamma_deg * DEG + rho), math.tan(gamma_deg * DEG - rho)


WORM, NUT = psi(30.0, 0.1), psi(5.0, 0.15)       # stage 2 self-locks: tan 5 deg < 0.15


def test_a_resting_chain_with_no_force_on_its_drive_prints_the_determined_internal_force():
    """No force on body 0 and stage 1 not self-locking: stage 1 can hold no force, so X_1 = 0 exactly; the
    decision says so instead of "undetermined; X_1 in [0, 0]"."""
    reason = decide_numbers([], 0.0, Statics((WORM, NUT), (1.0, 1.0), (1.0, 1.0), (0.0, 0.0, -50.0))).reason
    assert reason.startswith("all stuck: the statics determine the internal forces: X_1 = 0;"), reason
    assert "undetermined" not in reason and "[0, 0]" not in reason


def test_a_resting_chain_with_a_drive_force_prints_its_admissible_band():
    """5 N on body 0: stage 1 holds while X_1 lies in [5 / Psi_t1, 5 / Psi_i1], stage 2 (self-locking) while
    X_1 lies in [50 Psi_i2, 50 Psi_t2]: by hand X_1 in [6.95552, 11.0792]."""
    lo, hi = max(5.0 / WORM[0], 50.0 * NUT[1]), min(5.0 / WORM[1], 50.0 * NUT[0])
    reason = decide_numbers([], 0.0, Statics((WORM, NUT), (1.0, 1.0), (1.0, 1.0), (5.0, 0.0, -50.0))).reason
    assert f"internal force split statically undetermined; admissible X_1 in [{lo:.6g}, {hi:.6g}];" in reason
    assert (f"{lo:.6g}", f"{hi:.6g}") == ("6.95552", "11.0792")


# p of the run: latches (switch, t_pick, seated, voltage), then the derived slots the answers read: Psi_t, Psi_i per
# stage, the levers in and out, the speed factors, the valve's friction.
P = np.array([0.0, 0.0, 0.0, 1.0, *WORM, *NUT, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.05, 0.0])


def module(**changes) -> SimpleNamespace:
    """A two-stage drive train module's constants: worm and nut as above, a seat, a thrust switch, a motor."""
    return SimpleNamespace(**{"STAGES": 2, "P_PSI": 4, "P_LEVER_IN": 8, "P_LEVER_OUT": 10, "P_SPEED": 12,
                              "P_SLACK": 15, "HAS_SEAT": True, "SWITCH_ON": 2, "P_SWITCH": 0,
                              "P_SEATED": 2, "TRIPPED": 2, "STAGE_KINDS": ("wedge", "wedge"),
                              "BODY_MOTIONS": ("translation",) * 3, "MOTOR_TORQUE": (30.0, 10.0), "MOTOR_VOLTAGE": 1.0,
                              **changes})


def phase(mode, seated: bool, samples=(), tripped=True):
    return SimpleNamespace(mode=mode, latches=(2 if tripped else 0, 0.0, 1.0 if seated else 0.0), samples=samples)


def run(phases, status="finished", thrust=100.0):
    """A run that tripped at t = 1 s with ``thrust`` on the last body; the last phase's mode -1 is resting."""
    forces = [0.0] * 6
    forces[4] = thrust
    return SimpleNamespace(phases=phases, status=status, events=[], p=P,
                           trip={"t": 1.0, "y": (0.1, 0.0), "forces": forces, "drive": 3.0})


@pytest.mark.parametrize("phases, status, verdict", [
    ([phase(0, False), phase(-1, False)], "finished", "rests before the seat (never reached it)"),
    ([phase(0, False), phase(-1, True)], "finished", "holds"),
    ([phase(0, True), phase(-1, False)], "finished", "seat lost"),
    ([phase(0, True), phase(0, False)], "finished", "seat lost"),
    ([phase(0, False), phase(0, True)], "finished", "undecided: still moving on the seat at the end of the run"),
    ([phase(0, False)], "finished", "undecided: still moving before the seat at the end of the run"),
    ([phase(0, True)], "max-steps", "undecided: the run stopped (max-steps)"),
], ids=["short", "holds", "lost", "leaving", "on-seat", "before-seat", "stopped"])
def test_the_hold_verdict_says_what_the_run_showed(phases, status, verdict):
    """"seat lost" only when the stem was on its seat and ends off it; "holds" only at rest on it; a run that
    ends moving elsewhere, or stopped, decides nothing."""
    assert answers(module(), run(phases, status))["holds"]["verdict"] == verdict


def test_the_stall_margin_says_why_it_is_missing():
    """A trip thrust of -100 N needs prod Psi_t r_in / r_out times it at body 0: -100 x 0.71885 x 0.24065 =
    -17.299 N (by hand) <= 0, so there is no margin; the line says that, not "no trip thrust"."""
    needed = -100.0 * WORM[0] * NUT[0]
    assert f"{needed:.5g}" == "-17.299"
    out = answers(module(), run([phase(0, True), phase(-1, True)], thrust=-100.0))
    assert out["needed"] == pytest.approx(needed, rel=1e-14) and out["stall_margin"] is None
    lines = drive_train_lines(out, module())
    assert f"    stall margin: - (pull-out 30 N; the trip thrust needs {needed:.6g} N <= 0 at body 0)" in lines
