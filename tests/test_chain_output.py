"""What `tswm simulate` prints of a chain is true: internal forces the statics fix are printed as values,
the hold verdict says what the run showed, the stall margin is the pull-out torque over the needed one or
says why it is missing, the peak and extra travel after the trip come from the phases after the cut. The
answers are computed from a chain record written here (chains/answers.py, as for a run); values by hand."""
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
                              "P_SLACK": 15, "P_VOLTAGE": 3, "HAS_SEAT": True, "SWITCH_ON": 2, "P_SWITCH": 0,
                              "P_SEATED": 2, "TRIPPED": 2, "STAGE_KINDS": ("wedge", "wedge"),
                              "BODY_MOTIONS": ("translation",) * 3, "MOTOR_TORQUE": (30.0, 10.0), "MOTOR_VOLTAGE": 1.0,
                              **changes})


def phase(mode, seated: bool, samples=(), tripped=True, peak=(np.nan, np.nan)):
    """A phase in ``mode`` (RESTING = -1) with its latches, samples (t, q0, v0, six stage forces, travel) and its
    thrust's maximum (value, t), as the kernel's record holds them."""
    return SimpleNamespace(mode=mode, latches=(2 if tripped else 0, 0.0, 1.0 if seated else 0.0), samples=samples,
                           peak=peak)


def run(phases, status="finished", thrust=100.0, p=P):
    """A run that tripped at t = 1 s with ``thrust`` on the last body, as the kernel's chain record holds it."""
    from tswm_runtime.chains.kernel import ChainRecord
    from tswm_runtime.integration.segment import MAX_STEPS

    samples = [row for ph in phases for row in ph.samples]
    bounds = np.cumsum([0] + [len(ph.samples) for ph in phases])
    rows = [np.concatenate([(j, j + 1.0), p]) for j in range(len(phases))]
    for row, ph in zip(rows, phases):
        row[2:5] = ph.latches
    trip = np.array([1.0, 0.1, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, thrust, 0.0, 0.1 * 0.05, 0.0])   # travel c_2 q0
    peaks = np.full((len(phases), 12), np.nan)    # six forces' maxima, then their times; the thrust is force 4
    peaks[:, 4], peaks[:, 10] = np.array([ph.peak for ph in phases]).reshape(-1, 2).T
    record = ChainRecord(np.array([(ph.mode, a, b) for ph, a, b in zip(phases, bounds, bounds[1:])], np.int64),
                         np.array(rows), np.array(samples, dtype=float).reshape(-1, 10), np.zeros((1, 4), np.int64),
                         np.zeros((1, 3 + p.size)), trip, np.array([len(phases), len(samples), 0, 0], np.int64),
                         np.zeros((1, 10)), peaks)
    return SimpleNamespace(phases=phases, status=status, code={"finished": 0, "max-steps": MAX_STEPS}[status],
                           t_stop=5.0, n_steps=0, events=[], p=p, record=record)


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


def test_the_stall_margin_is_the_pull_out_torque_at_the_voltage_over_the_needed_torque():
    """At U/U_n = 0.9 the motor pulls out at 30 N m x 0.81 = 24.3 N m; a trip thrust of 100 N needs
    100 x Psi_t1 x Psi_t2 (levers 1) = 17.299 N m at body 0 (by hand), so the margin is 24.3 / 17.299."""
    p = P.copy()
    p[3] = 0.9
    needed = 100.0 * WORM[0] * NUT[0]
    out = answers(module(), run([phase(0, True), phase(-1, True)], p=p), voltage=0.9)
    assert out["pull_out"] == pytest.approx(30.0 * 0.81, rel=1e-15)
    assert out["needed"] == pytest.approx(needed, rel=1e-14)
    assert out["stall_margin"] == pytest.approx(30.0 * 0.81 / needed, rel=1e-14)
    line = f"    stall margin: {30.0 * 0.81 / needed:.4g} (pull-out 24.3 N at U/U_n = 0.9 over 17.299 N needed at the"
    assert f"{line} trip thrust)" in drive_train_lines(out, module())


def test_the_peak_and_the_extra_travel_after_the_trip_are_read_from_the_tripped_phases():
    """Phases before the trip (switch armed) are not counted; after it the thrust's largest magnitude among the
    phases' maxima (the kernel's, of the continuous solution: 300 N at t = 1.8 s inside the second phase, between
    its samples of 50 and 200 N; beyond -250 N at t = 2.5 s, a NaN never) is the peak, and the extra travel is the
    farthest travel (q0 = 0.7, times the speed factor 0.05: the samples' last column) less the travel at the trip
    (0.1 x 0.05), by hand."""
    def sample(t, q0, thrust):
        return [t, q0, 0.0, 0.0, 0.0, 0.0, 0.0, thrust, 0.0, 0.05 * q0]
    phases = [phase(0, False, [sample(0.5, 0.05, 900.0)], tripped=False, peak=(900.0, 0.5)),
              phase(0, False, [sample(1.0, 0.2, np.nan)]),
              phase(0, False, [sample(1.5, 0.3, 50.0), sample(2.0, 0.7, 200.0)], peak=(300.0, 1.8)),
              phase(1, True, [sample(2.5, 0.6, -250.0)], peak=(-250.0, 2.5)), phase(-1, True)]
    out = answers(module(), run(phases))
    assert out["peak_after_trip"] == {"thrust": 300.0, "t": 1.8}
    assert out["extra_travel"] == pytest.approx(0.05 * 0.7 - 0.05 * 0.1, rel=1e-15)
    assert out["trip"] == {"t": 1.0, "thrust": 100.0, "drive": 3.0, "travel": 0.1 * 0.05}
