"""A constant force driving a wedge into a preloaded spring: where and when it stalls, in closed form.

Written by hand from the force balance of a wedge sliding forward on flank a, independent of
derivation/ and generated/. With a constant drive force F1 = F0, constant friction angle rho
and Psi = tan(gamma + rho), forward sliding is

    (m1 + Psi m2 tan(gamma)) a1 = F0 + Psi F2,   x2 = x1 tan(gamma),

with F2 = 0 before body 2 reaches the spring (x2 < x2_contact) and F2 = -(preload + k (x2 -
x2_contact)) after it: constant acceleration up to the contact, then harmonic motion about
the point where the spring balances the drive. v1 falls to 0 at the top of the first swing,
x1 = x_eq + amplitude: the stall. With rho > gamma (self-locking) the friction cones hold
there (the spring presses harder than the drive), so the wedge sticks and stays at that x1.
"""
from __future__ import annotations

import math
from typing import NamedTuple


class Stall(NamedTuple):
    """Time and position of the stall, and of the spring contact before it."""

    t_contact: float
    x1_contact: float
    t_stall: float
    x1_stall: float


def stall(gamma, rho, m1, m2, F0, k, preload, x2_contact, x1_0=0.0, v1_0=0.0) -> Stall:
    """Where forward sliding from (x1_0, v1_0 > 0 or F0 > 0) stalls against the spring (SI, angles in rad).

    Needs a start before the contact (x1_0 tan(gamma) <= x2_contact) moving or pushed forward."""
    tg = math.tan(gamma)
    psi = math.tan(gamma + rho)
    m_eff = m1 + psi * m2 * tg
    x1_c = x2_contact / tg
    a_free = F0 / m_eff
    gap = x1_c - x1_0
    if gap > 0.0:  # free travel at constant acceleration: v1_0 t + a t^2 / 2 = gap
        v_c = math.sqrt(v1_0 * v1_0 + 2.0 * a_free * gap)
        t_c = 2.0 * gap / (v1_0 + v_c)  # the root without cancellation
    else:
        v_c, t_c = v1_0, 0.0
    omega = math.sqrt(psi * k * tg / m_eff)
    x_eq = x1_c + (F0 - psi * preload) / (psi * k * tg)
    # x1 - x_eq = A cos(omega s - delta) after the contact: v1 = 0 first where omega s = delta
    delta = math.atan2(v_c / omega, x1_c - x_eq)
    amplitude = math.hypot(x1_c - x_eq, v_c / omega)
    return Stall(t_c, x1_c, t_c + delta / omega, x_eq + amplitude)
