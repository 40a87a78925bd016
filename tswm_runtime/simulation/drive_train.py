"""A drive train's answers from one chain run: the switch's trip, the peak thrust after it and the extra
travel, whether the seat holds after power off (and which stage self-locks), the stall margin.

The thrust is the last stage's force on the last body (the stem). Peaks are taken over the sliding
phases' samples (their ends and output points); after the trip the motor is off, the bodies' forces
are affine in q0, which is monotone in a sliding phase, so the peak after the trip is exact. A stage
self-locks when its inverse-tractive FTF Psi_i <= 0 (derived from the run's p by the module's prepare): tan(gamma) <= the
effective friction. The stall margin is the motor's pull-out torque at the scene's voltage (the
table's largest torque times (U/U_n)^2) over the torque the chain needs at the trip: the drive torque
that holds the thrust at the trip while every stage slides forward tractive at constant speed, from
the stages' derived FTFs: T = prod_i Psi_t,i r_in,i / r_out,i times the thrust (the intermediate
bodies' own forces are not counted). Above 1 the motor can reach the trip quasi-statically.
"""
from __future__ import annotations

from types import ModuleType

import numpy as np

from tswm_common.chain_decision import internal_forces
from tswm_runtime.chains.batch import VERDICTS, hold_verdict
from tswm_runtime.chains.run import RESTING, ChainRun, numbers, speed_factor

UNITS = {"rotation": "N m", "translation": "N"}


def answers(module: ModuleType, run: ChainRun, voltage: float | None = None) -> dict:
    """trip, peak_after_trip, extra_travel, holds (verdict, self_locking, seated, undetermined), stall_margin
    (pull_out over needed); ``voltage`` is the run's U / U_n (None: the scene's)."""
    n = module.STAGES
    trip = run.trip
    out = {"trip": None, "peak_after_trip": None, "extra_travel": None, "holds": _holds(module, run),
           "stall_margin": None, "pull_out": _pull_out(module, voltage), "needed": None,
           "voltage": getattr(module, "MOTOR_VOLTAGE", None) if voltage is None else voltage}
    if trip is None:
        return out
    factor = speed_factor(module, run.p)
    travel = float(factor * trip["y"][0])
    thrust = None if trip["forces"] is None else float(trip["forces"][3 * n - 2])
    out["trip"] = {"t": trip["t"], "thrust": thrust, "drive": trip["drive"], "travel": travel}
    after = [(t, y, f) for phase in run.phases if phase.mode != RESTING and phase.latches[module.P_SWITCH]
             == module.TRIPPED for t, y, f in phase.samples]
    if after:
        t, _, forces = max(after, key=lambda s: abs(s[2][3 * n - 2]))
        out["peak_after_trip"] = {"thrust": float(forces[3 * n - 2]), "t": float(t)}
        out["extra_travel"] = max(float(factor * y[0]) for _, y, _ in after) - travel
    else:
        out["extra_travel"] = 0.0
    if thrust is not None:
        out["needed"] = float(needed_torque(module, run.p, thrust))
        if out["pull_out"] is not None and out["needed"] > 0:
            out["stall_margin"] = float(stall_margin(module, run.p, thrust, out["voltage"]))
    return out


def needed_torque(module: ModuleType, p: np.ndarray, thrust):
    """The drive torque that holds ``thrust`` with every stage sliding forward tractive at constant speed,
    from the Psi_t and levers in p (the run's p, or one per row with a thrust per row)."""
    p = np.asarray(p)
    factor = 1.0
    for k in range(module.STAGES):
        psi_t, r_in, r_out = p[..., module.P_PSI + 2 * k], p[..., module.P_LEVER_IN + k], p[..., module.P_LEVER_OUT + k]
        factor = factor * (psi_t * r_in / r_out)
    return thrust * factor


def stall_margin(module: ModuleType, p: np.ndarray, thrust, voltage):
    """Pull-out torque at ``voltage`` over the torque ``thrust`` needs (``needed_torque``; numbers or one
    per row); NaN where that torque is <= 0 or the thrust unknown (NaN), or without a motor."""
    needed = np.asarray(needed_torque(module, p, thrust), dtype=float)
    if not hasattr(module, "MOTOR_TORQUE"):
        return np.full(needed.shape, np.nan)
    pull_out = float(max(module.MOTOR_TORQUE)) * np.asarray(voltage, dtype=float)**2
    return np.divide(pull_out, needed, out=np.full(np.broadcast(pull_out, needed).shape, np.nan), where=needed > 0)


def _pull_out(module: ModuleType, voltage: float | None) -> float | None:
    """The motor's largest torque at the run's voltage (the scene's unless given), or None without a motor."""
    if not hasattr(module, "MOTOR_TORQUE"):
        return None
    return float(max(module.MOTOR_TORQUE) * (module.MOTOR_VOLTAGE if voltage is None else voltage)**2)


def _holds(module: ModuleType, run: ChainRun) -> dict:
    """After the motor's cut: does the chain rest on its seat at the end, which stages self-lock, and the
    admissible internal forces where every stage is stuck (statically undetermined for two stages or more)."""
    psi = numbers(module, run.p).psi
    locking = [k + 1 for k, (_, psi_i) in enumerate(psi) if psi_i <= 0]
    last = run.phases[-1] if run.phases else None
    resting = last is not None and last.mode == RESTING and run.status == "finished"
    seated = bool(module.HAS_SEAT and last is not None and last.latches[module.P_SEATED] > 0.5)
    ever_seated = bool(module.HAS_SEAT and any(p.latches[module.P_SEATED] > 0.5 for p in run.phases))
    rest = next((e.decision for e in reversed(run.events) if e.to_mode == RESTING), None) if resting else None
    undetermined = [list(map(list, xs)) for xs in rest.internal] if rest is not None and module.STAGES > 1 else []
    code = hold_verdict(run.trip is not None, bool(module.HAS_SEAT), run.status == "finished", seated, resting,
                        ever_seated, bool(locking))
    verdict = VERDICTS[code].format(status=run.status)
    return {"verdict": verdict, "self_locking": locking, "psi_i": [psi[k - 1][1] for k in locking], "seated": seated,
            "resting": resting, "undetermined": undetermined}


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
