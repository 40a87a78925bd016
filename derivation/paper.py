"""The source paper's equations exactly as printed, for the audit and the literal model.

These are transcriptions, not results: nothing in the consistent model is taken from
here. ``tg`` in the paper is tan; ``Psi`` stands for the active FTF Psi_j.
"""
from __future__ import annotations

import sympy as sp

from derivation.mechanics import F1, F2, Psi, S1, S2, a1, a2, gamma, m1, m2, rho, x1, x2

# eq. (1): kinematic constraint on position level (velocity and acceleration alike)
EQ1_RESIDUAL = x1 - x2 * sp.tan(gamma)
EQ1_ACCEL_RESIDUAL = a1 - a2 * sp.tan(gamma)
# eq. (2): force constraint, S1 = -Psi_j S2
EQ2_S1 = -Psi * S2
# eq. (3): the two FTFs
PSI_TRACTIVE = sp.tan(gamma + rho)
PSI_INVERSE = sp.tan(gamma - rho)
# eq. (6): reduced ODE
EQ6_ACCEL = (F1 - F2 * Psi) / (m1 - m2 * Psi * sp.tan(gamma))
# eq. (7): switching function from "own" accelerations F1/m1 and F2/m2
EQ7_SWITCHING = F1 / m1 - F2 / m2 * sp.tan(gamma)
# eq. (8): reaction on body 1
EQ8_S1 = F1 - m1 * a1
# eq. (9): reaction on body 2 from eq. (8) and the FTF
EQ9_S2 = S1 / Psi
