"""A drive train's answers from one chain run, in words: the switch's trip, the peak thrust after it and
the extra travel, whether the seat holds after power off (and which stage self-locks), the stall margin.

The numbers are computed from the run's record by the compiled code the sweep's batch uses
(chains/answers.py: ``answer_run``); here they become the summary's dict and the printed lines. The
thrust is the last stage's force on the last body (the stem). Its peak after the trip is the largest of the
tripped phases' peaks, each the maximum of the continuous solution (chains/kernel.py). A stage self-locks
when its inverse-tractive FTF Psi_i <= 0 (derived from the run's p by the module's prepare):
tan(gamma) <= the effective friction. The stall margin is the motor's pull-out torque at the run's
voltage (the table's largest torque times (U/U_n)^2) over the torque the chain needs at the trip:
prod_i Psi_t,i r_in,i / r_out,i times the thrust. Above 1 the motor can reach the trip quasi-statically.
"""
from __future__ import annotations

import math
from types import ModuleType

import numpy as np

from tswm_common.chain_decision import internal_forces
from tswm_runtime.chains import answers as compiled
from tswm_runtime.chains.run import RESTING, ChainRun, numbers

UNITS = {"rotation": "N m", "translation": "N"}


def answers(module: ModuleType, run: ChainRun, voltage: float | None = None) -> dict:
    """trip, peak_after_trip, extra_travel, holds (verdict, self_locking, seated, undetermined), stall_margin
    (pull_out over needed); ``voltage`` is the run's U / U_n (None: the scene's)."""
    f, i = np.empty(compiled.N_F), np.zeros(compiled.N_I, np.int64)
    compiled.answer_run(run.code, run.t_stop, run.n_steps, run.record, compiled.answering(module), run.p, f, i)
    out = {"trip": None, "peak_after_trip": None, "extra_travel": None, "holds": _holds(module, run, i),
           "stall_margin": _number(f[compiled.F_MARGIN]), "pull_out": _number(f[compiled.F_PULL_OUT]),
           "needed": _number(f[compiled.F_NEEDED]),
           "voltage": getattr(module, "MOTOR_VOLTAGE", None) if voltage is None else voltage}
    if math.isnan(f[compiled.F_T_TRIP]):
        return out
    out["trip"] = {"t": float(f[compiled.F_T_TRIP]), "thrust": _number(f[compiled.F_THRUST]),
                   "drive": float(f[compiled.F_DRIVE]), "travel": float(f[compiled.F_TRAVEL])}
    if not math.isnan(f[compiled.F_T_PEAK]):
        out["peak_after_trip"] = {"thrust": float(f[compiled.F_PEAK]), "t": float(f[compiled.F_T_PEAK])}
    out["extra_travel"] = float(f[compiled.F_EXTRA])
    return out


def _number(x) -> float | None:
    """A float, None for NaN (an answer the run does not give)."""
    return None if math.isnan(x) else float(x)


def _holds(module: ModuleType, run: ChainRun, i: np.ndarray) -> dict:
    """After the motor's cut, from the answers' row i: the verdict in words, whether the chain rests on its
    seat at the end; which stages self-lock, and the admissible internal forces where every stage is stuck
    (statically undetermined for two stages or more)."""
    psi = numbers(module, run.p).psi
    locking = [k + 1 for k, (_, psi_i) in enumerate(psi) if psi_i <= 0]
    resting = bool(i[compiled.I_RESTING])
    rest = next((e.decision for e in reversed(run.events) if e.to_mode == RESTING), None) if resting else None
    undetermined = [list(map(list, xs)) for xs in rest.internal] if rest is not None and module.STAGES > 1 else []
    verdict = compiled.VERDICTS[i[compiled.I_VERDICT]].format(status=run.status)
    return {"verdict": verdict, "self_locking": locking, "psi_i": [psi[k - 1][1] for k in locking],
            "seated": bool(i[compiled.I_SEATED]), "resting": resting, "undetermined": undetermined}


def drive_train_lines(answers: dict, module: ModuleType) -> list[str]:
    """The drive train's answers as printed: trip, peak after it, extra travel, hold, stall margin."""
    if module.SWITCH_ON < 0 and not module.HAS_SEAT:
        return []
    thrust_unit = UNITS[module.BODY_MOTIONS[-1]]
    torque_unit = UNITS[module.BODY_MOTIONS[0]]
    travel_unit = "m" if module.BODY_MOTIONS[-1] == "translation" else "rad"
    lines = ["  drive train:"]
    trip = answers["trip"]
    if trip is None:
        lines.append("    switch: did not trip (the motor was never cut)")
    else:
        thrust = ("undetermined (the chain rested: statically undetermined split)" if trip["thrust"] is None
                  else f"{trip['thrust']:.6g} {thrust_unit}")
        lines.append(f"    trip at t = {trip['t']:.9g} s: thrust {thrust}, drive {trip['drive']:.6g} {torque_unit}, "
                     f"travel {trip['travel']:.6g} {travel_unit}")
        peak = answers["peak_after_trip"]
        if peak is not None:
            lines.append(f"    peak thrust after the trip: {peak['thrust']:.6g} {thrust_unit} at t = {peak['t']:.9g} s")
        lines.append(f"    extra travel after the trip: {answers['extra_travel']:.6g} {travel_unit}")
    holds = answers["holds"]
    locking = ", ".join(f"stage {k} ({module.STAGE_KINDS[k - 1]}, Psi_i = {psi_i:.6g} <= 0)"
                        for k, psi_i in zip(holds["self_locking"], holds["psi_i"])) or "none"
    lines.append(f"    after power off: {holds['verdict']}; self-locking: {locking}")
    if holds["undetermined"]:
        internal = tuple(tuple(map(tuple, xs)) for xs in holds["undetermined"])
        lines.append(f"    all stages stuck: {internal_forces(internal)}")
    if answers["stall_margin"] is not None:
        lines.append(f"    stall margin: {answers['stall_margin']:.4g} (pull-out {answers['pull_out']:.6g} {torque_unit} "
                     f"at U/U_n = {answers['voltage']:g} over {answers['needed']:.6g} {torque_unit} needed at the trip "
                     "thrust)")
    elif answers["pull_out"] is not None:
        why = ("no trip thrust" if answers["needed"] is None else
               f"the trip thrust needs {answers['needed']:.6g} {torque_unit} <= 0 at body 0")
        lines.append(f"    stall margin: - (pull-out {answers['pull_out']:.6g} {torque_unit}; {why})")
    return lines
