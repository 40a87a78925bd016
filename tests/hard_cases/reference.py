"""An independent reference for the paper's gear: hand-written formulas and scipy.

Nothing here comes from derivation/ or generated/: the force balance of a sliding
wedge (Psi = tan(gamma + f s rho), a1 = (F1 + Psi F2) / (m1 + Psi m2 tan gamma)),
Kloss' motor curve, the paper's friction law in degrees, and scipy's DOP853 at tight
tolerance with its own event location for phi = 0 and v1 = 0.
"""
import math

import numpy as np
from scipy.integrate import solve_ivp

GAMMA = math.radians(4.76)
M1 = 11.8
FMAX, V0, VMAX = 2178.0, 7.85, 6.5
TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-14)


def kloss(v):
    s, sk = V0 - v, V0 - VMAX
    return 2 * FMAX * s * sk / (s * s + sk * sk)


def rho_paper(v):
    """The paper's friction angle in radians; sliding speed |v1| / cos(gamma)."""
    return math.radians(1.0 / (0.161 * (abs(v) / math.cos(GAMMA)) ** 0.535 + 0.088))


def accel(v, flank, F2, m2, m1=M1, rho=rho_paper, direction=1):
    psi = math.tan(GAMMA + flank * direction * rho(v))
    return (kloss(v) + psi * F2) / (m1 + psi * m2 * math.tan(GAMMA))


def phi(v, F2, m2, m1=M1):
    return kloss(v) * math.tan(GAMMA) / m1 - F2 / m2


def S2(v, flank, F2, m2, m1=M1, rho=rho_paper):
    """S2 = F2 - m2 a2 with a2 = a1 tan(gamma) (Newton on body 2)."""
    return F2 - m2 * math.tan(GAMMA) * accel(v, flank, F2, m2, m1, rho)


def breakaway_F1(F2, rho0=None):
    """Drive force at which forward sliding starts from rest: T = tan(rho0) |f N|."""
    mu = math.tan(rho_paper(0.0) if rho0 is None else rho0)
    g = GAMMA
    # T = F1 cos g + F2 sin g, fN = F1 sin g - F2 cos g, with fN > 0 here (F2 < 0).
    return F2 * (-mu * math.cos(g) - math.sin(g)) / (math.cos(g) - mu * math.sin(g))


def run_flanks(v0, t0, t_end, F2, m2, m1=M1, t_eval=None, switches=True):
    """Forward sliding from (t0, v0) with flank switches at phi = 0 (DOP853, event location).

    Returns (t, v, switch times) sampled at t_eval. switches=False integrates without the
    phi event, for cases where phi provably keeps its sign (F2 = 0 below V0: phi =
    F1 tan(gamma) / m1 > 0); DOP853 would report spurious crossings in its noise there.
    """
    t_eval = np.asarray(t_eval if t_eval is not None else [t_end], dtype=float)
    flank = 1 if phi(v0, F2, m2, m1) > 0 else -1
    switches, t, v = [], t0, v0
    ts, vs = [], []
    while t < t_end:
        event = lambda _t, y: phi(y[0], F2, m2, m1)  # noqa: E731
        event.terminal = True
        inside = t_eval[(t_eval >= t) & (t_eval <= t_end)]
        sol = solve_ivp(lambda _t, y: [accel(y[0], flank, F2, m2, m1)], (t, t_end), [v],
                        events=event if switches else None, t_eval=inside, **TIGHT)
        assert sol.status >= 0, sol.message
        keep = sol.t <= (sol.t_events[0][0] if sol.status == 1 else t_end)
        ts.extend(sol.t[keep])
        vs.extend(sol.y[0][keep])
        if sol.status != 1:
            break
        t, v = sol.t_events[0][0], sol.y_events[0][0][0]
        switches.append(t)
        flank = -flank
        t_eval = t_eval[t_eval > t]
    return np.array(ts), np.array(vs), switches
