"""A drive train's answers from a chain run's record, in compiled code: the one place they are computed,
for the sweep's batch (``batch.run_chain_batch`` links ``answer``) and for one run
(``answer_run``, which ``simulation/drive_train.py`` calls and words).

One row of floats and one of integers per run:

    f = (t_stop, t_trip, thrust at the trip, body 0's drive at the trip, travel at the trip,
         peak thrust after the trip, its time, extra travel after the trip,
         torque needed at the trip thrust, pull-out torque, stall margin, kinetic energy the impacts lost)
        (NaN: no trip; thrust NaN when the chain rested at the trip; peak and its time NaN when it never
        slid after the trip, the extra travel then 0; needed NaN without a trip thrust; pull-out NaN
        without a motor; margin NaN without both or where the needed torque is <= 0)
    i = (status (kernel's code), hold verdict (``VERDICTS``), events, steps and rejected steps,
         seated at the end, resting at the end (finished at rest), impacts of the stage with a clearance)

The thrust is the last stage's force on the last body; travel is the last body's coordinate (the kernel's
``rules.last_coordinate``: c_N q0 for a rigid chain, from body k's own coordinate with a clearance in stage k). The
peak after the trip is the largest |thrust| among the tripped phases' peaks (the kernel's maxima of the continuous
solution), the extra travel the farthest of their samples' travel: the last body turns only where its speed is 0, an
event (a phase end, sampled), also alone in the open phase of a clearance in the last stage without valve friction
(a free group: its direction latch is its speed's sign, ``rules._open_candidate``). The torque needed holds the
thrust with every stage sliding forward tractive at constant speed, from the stages' derived FTFs: prod_i Psi_t,i
r_in,i / r_out,i times the thrust (the intermediate bodies' own forces not counted). The pull-out torque is the
motor table's largest torque times (U/U_n)^2; the stall margin is it over the needed torque.
"""
from collections import namedtuple

import numpy as np
from numba import types

from tswm_runtime.jit import coldstart

coldstart.announce(("integrate", "chain"))  # before the next imports compile the kernels, if not cached

from tswm_runtime.chains import kernel  # noqa: E402
from tswm_runtime.chains.backlash import IMPACT_COLUMNS  # noqa: E402
from tswm_runtime.chains.rules import RESTING  # noqa: E402
from tswm_runtime.jit import cache_guard  # noqa: E402
from tswm_runtime.jit.cache_guard import njit  # noqa: E402
from tswm_runtime.jit.signatures import VECTOR  # noqa: E402

(F_T_STOP, F_T_TRIP, F_THRUST, F_DRIVE, F_TRAVEL, F_PEAK, F_T_PEAK, F_EXTRA, F_NEEDED, F_PULL_OUT, F_MARGIN,
 F_LOST) = range(12)
N_F = 12
I_STATUS, I_VERDICT, I_EVENTS, I_STEPS, I_SEATED, I_RESTING, I_IMPACTS = range(7)
N_I = 7
LOST = IMPACT_COLUMNS.index("energy lost")   # an impact row's column

#: What is left after the motor's cut, by code (``hold_verdict``); {status} is the run's status.
VERDICTS = ("no trip: the motor was not cut", "no seat in the scene", "undecided: the run stopped ({status})",
            "holds", "holds, though no stage self-locks", "undecided: still moving on the seat at the end of the run",
            "seat lost: no stage self-locks", "seat lost", "rests before the seat (never reached it)",
            "undecided: still moving before the seat at the end of the run")

#: The module's numbers the answers read: its stages; the slots of p of the stages' Psi (t, i per stage), levers
#: in and out, the switch's state, the seat's contact and the voltage U / U_n; the switch's tripped state,
#: whether the scene has a seat, the motor's largest torque (NaN: no motor).
Answering = namedtuple("Answering", "stages p_psi p_lever_in p_lever_out p_switch p_seated p_voltage "
                                    "tripped has_seat rated")
ANSWERING = types.NamedTuple((*(types.int64,) * 7, types.float64, types.boolean, types.float64), Answering)
ANSWER_SIG = types.none(types.int64, types.float64, types.int64, kernel.CHAIN_RECORD, ANSWERING, VECTOR, VECTOR,
                        types.int64[::1])


def answering(module) -> Answering:
    """The numbers of a chain module the answers read (``Answering``)."""
    return Answering(module.STAGES, module.P_PSI, module.P_LEVER_IN, module.P_LEVER_OUT, module.P_SWITCH,
                     module.P_SEATED, module.P_VOLTAGE, float(module.TRIPPED),
                     bool(module.HAS_SEAT), float(max(module.MOTOR_TORQUE)) if hasattr(module, "MOTOR_TORQUE")
                     else np.nan)


def hold_verdict(tripped: bool, has_seat: bool, finished: bool, seated: bool, resting: bool, ever_seated: bool,
                 locking: bool) -> int:
    """The code in VERDICTS of what holds after the cut: ``seated`` and ``resting`` (finished at rest)
    at the end of the run, ``ever_seated`` in any phase, ``locking`` any stage self-locking."""
    if not tripped:
        return 0
    if not has_seat:
        return 1
    if not finished:
        return 2
    if seated:
        return (3 if locking else 4) if resting else 5
    if ever_seated:
        return 7 if locking else 6
    return 8 if resting else 9


_hold_verdict = njit(error_model="numpy")(hold_verdict)


@njit(error_model="numpy")
def answer(status, t_stop, steps, rec, a, p, f, i):
    """The run's answers from its chain record (and its p at the start: Psi_i, levers,
    voltage) into rows f and i (module docstring); ``steps`` its accepted and rejected steps."""
    n = a.stages
    locking = False
    for k in range(n):
        locking = locking or p[a.p_psi + 2 * k + 1] <= 0.0
    n_phases = rec.counts[0]
    thrust_at = 3 * n - 2                # the last stage's force on the last body among a stage row's forces
    f[:] = np.nan
    f[F_T_STOP] = t_stop
    tripped = not np.isnan(rec.trip[0])
    if tripped:
        f[F_T_TRIP], f[F_DRIVE] = rec.trip[0], rec.trip[3]
        f[F_TRAVEL] = rec.trip[rec.trip.size - 2]
        if rec.trip[rec.trip.size - 1] != RESTING:
            f[F_THRUST] = rec.trip[4 + thrust_at]
        f[F_EXTRA] = 0.0
        far, found, m = -np.inf, False, 3 * n
        for k in range(n_phases):
            if rec.phases[k, 0] == RESTING or rec.phase_f[k, 2 + a.p_switch] != a.tripped:
                continue
            thrust = rec.peaks[k, thrust_at]    # the phase's maximum; NaN: undetermined (a stuck group's)
            if not np.isnan(thrust) and (np.isnan(f[F_PEAK]) or abs(thrust) > abs(f[F_PEAK])):
                f[F_PEAK], f[F_T_PEAK] = thrust, rec.peaks[k, m + thrust_at]
            for s in range(rec.phases[k, 1], rec.phases[k, 2]):
                row = rec.samples[s]
                far = max(far, row[row.size - 1])
                found = True
        if found:
            f[F_EXTRA] = far - f[F_TRAVEL]
    factor = 1.0
    for k in range(n):
        factor = factor * (p[a.p_psi + 2 * k] * p[a.p_lever_in + k] / p[a.p_lever_out + k])
    f[F_NEEDED] = f[F_THRUST] * factor
    f[F_PULL_OUT] = a.rated * p[a.p_voltage]**2
    if f[F_NEEDED] > 0.0:
        f[F_MARGIN] = f[F_PULL_OUT] / f[F_NEEDED]
    ever_seated = False
    for k in range(n_phases):
        ever_seated = ever_seated or rec.phase_f[k, 2 + a.p_seated] > 0.5
    last = n_phases - 1
    finished = status == kernel.FINISHED
    seated = a.has_seat and n_phases > 0 and rec.phase_f[last, 2 + a.p_seated] > 0.5
    resting = n_phases > 0 and rec.phases[last, 0] == RESTING and finished
    i[I_STATUS] = status
    i[I_VERDICT] = _hold_verdict(tripped, a.has_seat, finished, seated, resting, a.has_seat and ever_seated, locking)
    i[I_EVENTS] = rec.counts[2]
    i[I_STEPS] = steps
    i[I_SEATED] = seated
    i[I_RESTING] = resting
    i[I_IMPACTS] = rec.counts[3]
    f[F_LOST] = 0.0
    for k in range(rec.counts[3]):
        f[F_LOST] += rec.impacts[k, LOST]


@cache_guard.compile_cached(ANSWER_SIG, error_model="numpy")
def answer_run(status, t_stop, steps, rec, a, p, f, i):
    """``answer`` for one run, called from Python (``simulation/drive_train.py``)."""
    answer(status, t_stop, steps, rec, a, p, f, i)
