"""The paper's worm gear in closed form, written by hand from the force balance.

Independent of derivation/ and generated/: the benchmark's peer runner (what a user
would write for solve_ivp), the paper report's statics and the tests' reference use
these formulas, so the derived and generated model is checked against them.
"""
import math

GAMMA = math.radians(4.76)  # worm lead angle
M1 = 11.8  # kg, rotor inertia on the worm pitch line (paper's value)
FMAX, V0, VMAX = 2178.0, 7.85, 6.5  # Kloss' motor curve on the pitch line: N, m/s, m/s


def kloss(v):
    """Drive force F1(v1), Kloss' formula in its form that is safe at v1 = V0."""
    s, sk = V0 - v, V0 - VMAX
    return 2 * FMAX * s * sk / (s * s + sk * sk)


def rho(v):
    """The paper's friction angle in radians; sliding speed |v1| / cos(gamma)."""
    return math.radians(1.0 / (0.161 * (abs(v) / math.cos(GAMMA)) ** 0.535 + 0.088))


def accel(v, flank, F2, m2, m1=M1, direction=1):
    """a1 sliding on flank (+1 a, -1 b) in direction: Psi = tan(gamma + f s rho)."""
    psi = math.tan(GAMMA + flank * direction * rho(v))
    return (kloss(v) + psi * F2) / (m1 + psi * m2 * math.tan(GAMMA))


def reactions(v, flank, F2, m2, m1=M1, direction=1):
    """(S1, S2) by their definitions S1 = F1 - m1 a1, S2 = F2 - m2 a2, a2 = a1 tan(gamma)."""
    a1 = accel(v, flank, F2, m2, m1, direction)
    return kloss(v) - m1 * a1, F2 - m2 * math.tan(GAMMA) * a1


def phi(v, F2, m2, m1=M1):
    """Switching function F1 tan(gamma) / m1 - F2 / m2 (contact force zero where it is)."""
    return kloss(v) * math.tan(GAMMA) / m1 - F2 / m2


def cones(F1, F2, gamma, rho0):
    """(cone_forward, cone_backward) at rest: tan(rho0) |N| -/+ T with N = F1 sin g - F2 cos g,
    T = F1 cos g + F2 sin g; stick holds while both are >= 0."""
    normal = F1 * math.sin(gamma) - F2 * math.cos(gamma)
    tangential = F1 * math.cos(gamma) + F2 * math.sin(gamma)
    return math.tan(rho0) * abs(normal) - tangential, math.tan(rho0) * abs(normal) + tangential


def breakaway_F1(F2):
    """Drive force at which forward sliding starts from rest against F2 < 0 (N > 0 there)."""
    mu, g = math.tan(rho(0.0)), GAMMA
    return F2 * (-mu * math.cos(g) - math.sin(g)) / (math.cos(g) - mu * math.sin(g))
