"""The drive train's switched and valve-side laws in SymPy: the motor cut by the torque switch, the
valve's Coulomb friction (packing and differential pressure) and its seat.

The generated module keeps three latches in its parameter vector p, set by the runtime at its events
(tswm_runtime/chains/run.py): the switch's state (armed, picked up, tripped), the time it picked up,
and whether the last body presses its seat; a fourth slot holds the motor's voltage U / U_n (the
scene's by default), so that a sweep over it needs no new module. The forces below read them as the symbols ``powered`` and
``seated``; the switch's own logic (which quantity it measures, when it trips) is in the template.
"""
from __future__ import annotations

import sympy as sp

from derivation.chain.scene import Valve

POWERED = sp.Symbol("powered", real=True)      # 1 while the motor runs, 0 once the switch has tripped
SEATED = sp.Symbol("seated", real=True)        # 1 while the last body presses its seat, else 0
ARMED, PICKED, TRIPPED = 0, 1, 2               # the switch's states, p[P_SWITCH]
P_SWITCH, P_PICK, P_SEATED, P_VOLTAGE = 0, 1, 2, 3   # slots of p
P_NAMES = ("switch", "t_pick", "seated", "voltage")


def symbol(param) -> sp.Symbol:
    return sp.Symbol(param.name, real=True)


def drive(motor: sp.Expr) -> sp.Expr:
    """The motor's torque on body 0: its table's torque while powered, none after the trip (no brake)."""
    return POWERED * motor


def coulomb(valve: Valve) -> sp.Expr:
    """The magnitude of the valve's friction: the packing's force, a constant part and one proportional to
    the differential pressure (packing_dp dp: the pressure presses the packing onto the stem), and the
    differential pressure's force dp area on the disc times its valve (friction) factor."""
    return (symbol(valve.packing) + symbol(valve.packing_dp) * symbol(valve.dp)
            + symbol(valve.valve_factor) * symbol(valve.dp) * symbol(valve.area))


def valve_force(valve: Valve, travel: sp.Expr, direction: sp.Expr) -> sp.Expr:
    """The valve's force on the last body at travel x and motion sign s: the friction -s |F_c| (s = 0: at
    rest, where the friction is whatever holds, up to |F_c|) and, while seated, the seat's spring
    -k_seat (x - x_seat)."""
    force = -direction * coulomb(valve)
    if valve.seat is not None:
        force -= SEATED * symbol(valve.seat_stiffness) * (travel - symbol(valve.seat))
    return force
