"""An independent reference for the paper's gear: hand-written formulas and scipy.

Nothing here comes from derivation/ or generated/: the hand formulas of
``tswm_runtime.reference.paper_gear`` (force balance of a sliding wedge, Kloss' motor curve,
the paper's friction law) and scipy's DOP853 at tight tolerance with its own event
location for phi = 0.
"""
import math

import numpy as np
from scipy.integrate import solve_ivp

from tswm_runtime.reference.paper_gear import M1, accel, phi

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


def energy_residual(r, K, power_in, absorbed):
    """(residual, total |work|) of the energy balance work in = change of K + absorbed power,
    integrated by the trapezoidal rule segment by segment between the events of result ``r``
    (within a segment the balance is smooth; across an impact K jumps)."""
    cuts = [0.0, *[ev.t for ev in r.events], r.t_stop]
    residual, total = 0.0, 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        inside = (r.t > lo) & (r.t < hi)
        if inside.sum() < 3:
            continue
        t = r.t[inside]
        work = np.trapezoid(power_in[inside], t)
        residual += (K[inside][-1] - K[inside][0]) + np.trapezoid(absorbed[inside], t) - work
        total += abs(work)
    return residual, total


def impact_drops(r, K, net_power, impacts):
    """Per impact of result ``r``: (drop of K across its two output rows, its reported loss,
    slack). The rows are dt apart, so the smooth change over 2 dt is bounded by |net power| 2 dt."""
    slack = np.max(np.abs(net_power)) * (r.t[1] - r.t[0]) * 2
    for ev in impacts:
        before = np.searchsorted(r.t, ev.t) - 1
        yield K[before] - K[before + 1], ev.jump.energy_lost, slack
