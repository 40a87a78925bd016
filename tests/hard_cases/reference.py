"""An independent reference for the paper's gear: hand-written formulas and scipy.

Nothing here comes from derivation/ or generated/: the hand formulas of
``tswm_runtime.apps.paper_gear`` (force balance of a sliding wedge, Kloss' motor curve,
the paper's friction law) and scipy's DOP853 at tight tolerance with its own event
location for phi = 0.
"""
import math

import numpy as np
from scipy.integrate import solve_ivp

from tswm_runtime.apps.paper_gear import M1, accel, phi

TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-14)


def printed(f, F1, F2, rho, m1, m2, gamma):
    """(a1, S1, S2) of the paper's eqs. (6), (8), (9) as printed: flank a with Psi_1, b with Psi_2."""
    psi = math.tan(gamma + f * rho)
    a = (F1 - F2 * psi) / (m1 - m2 * psi * math.tan(gamma))
    S1 = F1 - m1 * a
    return a, S1, S1 / psi


def printed_phi(F1, F2, m1, m2, gamma):
    """The paper's eq. (7) as printed: phi = F1/m1 - F2 tan(gamma)/m2."""
    return F1 / m1 - F2 * math.tan(gamma) / m2


def run_flanks(v0, t0, t_end, F2, m2, m1=M1, t_eval=None, switches=True):
    """Forward sliding from (t0, v0) with flank switches at phi = 0 (DOP853, event location).

    Returns (t, v, switch times) sampled at t_eval. switches=False integrates without the
    phi event, for cases where phi provably keeps its sign (F2 = 0 below V0: phi =
    F1 tan(gamma) / m1 > 0); DOP853 would report spurious crossings in its noise there.
    """
    t_eval = np.asarray(t_eval if t_eval is not None else [t_end], dtype=float)
    flank = 1 if phi(v0, F2, m2, m1) > 0 else -1
    found, t, v = [], t0, v0
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
        found.append(t)
        flank = -flank
        t_eval = t_eval[t_eval > t]
    return np.array(ts), np.array(vs), found
