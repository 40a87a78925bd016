"""The contact conditions at rest solved by hand: Newton's law for the worm (body 1, along x1) and
the wheel (body 2, along x2) with the contact force written out for every candidate (stick, sliding
forward or backward on a flank, parting), nothing from derivation/ or generated/. Shared by the
tests of a start at rest (test_start_modes) and of a stop mid-run (test_rest_modes)."""
import itertools
import math

import numpy as np

DEG = math.pi / 180.0
# The light worm on a heavy wheel, every value free: the scene text both test files start from
# (format fields name and clearance; each adds its load, modes and run tables).
WEDGE = """
name = "{name}"
equations = "consistent"
[wedge]
flanks = ["a", "b"]
gamma = {{ value = "8 deg", free = true }}
m1 = {{ value = "1.3 kg", free = true }}
m2 = {{ value = "1500 kg", free = true }}
{clearance}
[friction]
law = "constant"
rho = {{ value = "6 deg", free = true }}
[drive]
law = "constant"
F1 = {{ value = "8 kN", free = true }}
"""


def _bodies(gamma, m1, m2, F1, F2, force_on_2):
    """(a1, a2): Newton for each body on its guide; body 2 feels ``force_on_2`` (x1, x2
    components), body 1 the opposite."""
    return (F1 - force_on_2[0]) / m1, (F2 + force_on_2[1]) / m2


def hand_slide(gamma, rho, m1, m2, F1, F2, f, s):
    """(a1, N, S2, regular) of sliding on flank ``f`` (1: a, body 1 pushes body 2; -1: b) with
    sign(v1) = s. The flank normal (body 1 towards body 2 on flank a) is n = (sin g, cos g), the
    contact line t = (-cos g, sin g); rigid contact keeps (a2 e2 - a1 e1).n = 0, i.e. a2 = a1 tan g;
    body 2 slips along +t relative to body 1 at v1 / cos g, friction -s mu N on body 2; unknowns a1
    and N. regular: the normal acceleration the contact force produces grows with it (else a
    Painleve-type solution)."""
    n = np.array([math.sin(gamma), math.cos(gamma)])
    t = np.array([-math.cos(gamma), math.sin(gamma)])
    direction = f * n - s * math.tan(rho) * t
    matrix = np.array([[m1, direction[0]], [-m2 * math.tan(gamma), direction[1]]])
    a1, N = np.linalg.solve(matrix, np.array([F1, -F2]))
    # d(normal acceleration apart on flank f)/dN for the force direction above
    compliance = f * (direction[1] * n[1] / m2 + direction[0] * n[0] / m1)
    return a1, N, F2 - m2 * math.tan(gamma) * a1, compliance > 0.0


def hand_start(gamma, rho, m1, m2, F1, F2, flanks):
    """Every candidate at rest: a list of (name, a1, S2, regular) for those whose contact conditions
    hold. ``flanks``: the flanks in contact (1: a, -1: b), both without a clearance; with one,
    parting is a candidate."""
    n = np.array([math.sin(gamma), math.cos(gamma)])
    t = np.array([-math.cos(gamma), math.sin(gamma)])
    mu = math.tan(rho)
    found = []
    # stick: a1 = a2 = 0, the contact force (fN n + T t) balances both forces
    fN, T = np.linalg.solve(np.column_stack([n, t]), np.array([F1, -F2]))
    on_flank = len(flanks) == 2 or fN * flanks[0] >= 0.0
    if on_flank and abs(T) <= mu * abs(fN):
        found.append(("stick", 0.0, F2, True))
    for f, s in itertools.product(flanks, (1, -1)):
        a1, N, S2, regular = hand_slide(gamma, rho, m1, m2, F1, F2, f, s)
        if N >= 0.0 and s * a1 > 0.0:
            found.append((("fwd_" if s > 0 else "bwd_") + ("a" if f > 0 else "b"), a1, S2, regular))
    if len(flanks) == 1:  # parting: both free, the gap opens
        a1, a2 = _bodies(gamma, m1, m2, F1, F2, (0.0, 0.0))
        if flanks[0] * (a2 * n[1] - a1 * n[0]) > 0.0:
            found.append(("free", a1, 0.0, True))
    return found


def expected(found):
    """(status, mode) tswm must report for the hand candidates ``found``: the one that holds, a
    Painleve solution alone (inconsistent) or several (indeterminate)."""
    if len(found) == 1:
        return ("finished", found[0][0]) if found[0][3] else ("inconsistent", found[0][0])
    return "indeterminate", None
