"""The benchmark's peers: the paper gear solved as a careful user writes it with
scipy's solve_ivp (RK45, DOP853, Radau, BDF, LSODA) or SUNDIALS CVODE (scikit-sundae).

Hand formulas (``paper_gear``) for forward sliding and stick, nothing from tswm's
derivation or runtime. What the careful user does:

- splits the time span exactly at every scheduled load time (the load is constant, or
  linear in t, on each piece, so no step ever straddles a jump or a kink);
- uses terminal events with directions: v1 = 0 falling, and phi = 0 falling on flank a
  (phi > 0) or rising on flank b (phi < 0); after each event restarts with the flank
  given by the sign of phi (or sticks at v1 = 0 while the static friction cone holds);
- guards against phi chatter by arming the phi event only where phi can change sign:
  on flank a moving forward with F2 <= 0 and v1 <= V0, phi = F1 tan(gamma) / m1 - F2 / m2
  >= F1 tan(gamma) / m1 > 0, and v1 never passes V0 (a1 = (F1 + Psi F2) / D <= F1 / D),
  so no flank switch is possible there; the free run-up (F2 = 0) approaches the
  synchronous speed V0, where phi -> 0 from above, and an armed event would fire on
  rounding noise and chatter. Elsewhere the event is armed with its direction, which
  ignores the zero it starts on right after a switch;
- takes max |S1| over the accepted steps and one-sided at every event (at v1 = 0 the
  limit v1 -> 0+), refined around the largest: inside a phase S1 is a function of v1
  alone and v1 is monotone, so a bounded scalar maximisation over v1 between the
  neighbouring steps needs no dense output (the same for every method, CVODE included);
  under a load linear in t, where S1 depends on t as well, at the accepted steps (its largest
  value lies at a breakpoint, where every peer stops).

The state is (x1, v1): x1(t_end) is part of what a user wants and what tswm returns.
``peer_run`` is one whole call: problem set-up, integration, max |S1|, v1(t_end),
x1(t_end), events.
Backward sliding is not written (none of the benchmark's cases enters it): it raises.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tswm_runtime.reference.paper_gear import GAMMA, M1, V0, accel, cones, kloss, phi, reactions, rho

SCIPY_METHODS = ("RK45", "DOP853", "Radau", "BDF", "LSODA")
MAX_EVENTS = 100  # a run with more events is given up (chatter)


class PeerGaveUp(RuntimeError):
    """More than MAX_EVENTS events, or a regime the hand-written peer does not model."""


@dataclass
class Outcome:
    """What every solver in the benchmark delivers for one case."""

    S1: float  # S1 where |S1| is largest
    v_end: float  # v1(t_end)
    events: list = field(default_factory=list)  # [(kind, t)], kind 'load', 'phi' or 'v1'
    nfev: int = 0
    x_end: float = math.nan  # x1(t_end) - x1(0)
    steps: int = 0  # accepted steps


def available_methods() -> tuple[str, ...]:
    """The scipy methods, and CVODE if scikit-sundae is importable."""
    import importlib.util

    return SCIPY_METHODS + (("CVODE",) if importlib.util.find_spec("sksundae") else ())


def sticks(F2: float) -> bool:
    """At rest against F2: both static friction cones hold."""
    fwd, bwd = cones(kloss(0.0), F2, GAMMA, rho(0.0))
    return fwd >= 0.0 and bwd >= 0.0


def phi_can_vanish(flank: int, F2: float, v: float) -> bool:
    """Whether phi can reach zero in a forward phase from v (see the module docstring)."""
    return not (flank > 0 and F2 <= 0.0 and v <= V0)


class _Best:
    """The signed S1 with the largest |S1| offered so far."""

    def __init__(self):
        self.value = 0.0

    def offer(self, s1: float) -> None:
        if abs(s1) > abs(self.value):
            self.value = s1


def _solve_scipy(method, rtol, atol, t, t_to, y, rhs, events):
    from scipy.integrate import solve_ivp

    sol = solve_ivp(rhs, (t, t_to), y, method=method, rtol=rtol, atol=atol, events=events)
    if sol.status < 0:
        raise PeerGaveUp(f"{method}: {sol.message}")
    hit = None
    if sol.status == 1:
        which = next(i for i, te in enumerate(sol.t_events) if len(te))
        hit = (which, float(sol.t_events[which][0]), sol.y_events[which][0])
    return sol.t, sol.y, hit, sol.nfev


def _solve_cvode(rtol, atol, t, t_to, y, f_rhs, f_events, armed):
    from sksundae.cvode import CVODE

    def frhs(_t, y, yp):  # scikit-sundae counts arguments: no defaults here
        yp[:] = f_rhs(_t, y)

    def fev(_t, y, e):
        e[0] = f_events[0](_t, y) if armed else 1.0
        e[1] = f_events[1](_t, y)
    fev.terminal = [True, True]
    fev.direction = [f_events[0].direction if armed else 0, -1]
    sol = CVODE(frhs, rtol=rtol, atol=atol, method="BDF", eventsfn=fev, num_events=2,
                max_num_steps=1_000_000).solve([t, t_to], y)
    ys = np.asarray(sol.y).T
    hit = None
    if sol.status == 2 and len(sol.t_events):
        which = int(np.argmax(np.abs(np.asarray(sol.i_events)[0])))
        hit = (which, float(sol.t_events[0]), np.asarray(sol.y_events)[0])
    elif sol.status < 0:
        raise PeerGaveUp(f"CVODE: {sol.message}")
    return np.asarray(sol.t), ys, hit, int(sol.nfev)


def _refine_max(s1_of, vs, best: _Best) -> None:
    """Offer S1 at the step points (one-sided at both ends) and its maximum in v1 between
    the neighbours of the largest (S1 is a function of v1 within a phase)."""
    from scipy.optimize import minimize_scalar

    vals = np.array([s1_of(x) for x in vs])
    for s in vals:
        best.offer(float(s))
    if vs.size < 3:
        return
    k = int(np.argmax(np.abs(vals)))
    lo, hi = sorted((float(vs[max(k - 1, 0)]), float(vs[min(k + 1, vs.size - 1)])))
    if hi > lo:
        r = minimize_scalar(lambda x: -abs(s1_of(x)), bounds=(lo, hi), method="bounded",
                            options={"xatol": 1e-13 * max(1.0, hi)})
        best.offer(s1_of(float(r.x)))


def peer_run(method: str, rtol: float, atol: float, m2: float, loads, v0: float, t_end: float,
             m1: float = M1) -> Outcome:
    """One careful user's run. loads: [(t_from, F2) or (t_from, F2, dF2/dt), ...], piecewise
    constant or linear in t (F2 + dF2/dt (t - t_from) on the piece), t_from of the first 0.
    Returns max |S1| (signed), v1(t_end), x1(t_end), the events (load, phi, v1) and the rhs
    calls."""
    best, out = _Best(), Outcome(0.0, math.nan)
    x, v, flank, switched = 0.0, v0, 1, False
    bounds = [piece[0] for piece in loads[1:]] + [t_end]
    for (t_from, F2_from, *slope), t_to in zip(loads, bounds):
        if t_from > 0.0:
            out.events.append(("load", t_from))
        rate = slope[0] if slope else 0.0
        t = t_from
        while t < t_to:
            F2 = F2_from + rate * (t - t_from)  # the load now: at the piece's start or after an event
            F2_high = max(F2, F2_from + rate * (t_to - t_from))  # the largest load left on the piece
            if v == 0.0 and sticks(F2) and rate != 0.0:
                raise PeerGaveUp("sticking under a changing load is not modelled by the hand-written peer")
            if v == 0.0 and sticks(F2):
                best.offer(kloss(0.0))  # at rest S1 = F1 (a1 = 0)
                break
            if v < 0.0 or (v == 0.0 and cones(kloss(0.0), F2, GAMMA, rho(0.0))[0] >= 0.0):
                raise PeerGaveUp("backward sliding is not modelled by the hand-written peer")
            p = phi(v, F2, m2, m1)
            if not switched and p != 0.0:  # right after a switch phi is ~0: keep the new flank
                flank = 1 if p > 0 else -1
            f, switched = flank, False

            def load(_t, t_from=t_from, F2_from=F2_from, rate=rate):
                return F2_from + rate * (_t - t_from)

            def rhs(_t, y, f=f, load=load):
                return [y[1], accel(y[1], f, load(_t), m2, m1)]

            def ev_phi(_t, y, load=load):
                return phi(y[1], load(_t), m2, m1)

            def ev_v(_t, y):
                return y[1]
            armed = phi_can_vanish(flank, F2_high, v)
            ev_phi.terminal = ev_v.terminal = True
            ev_phi.direction, ev_v.direction = -flank, -1
            if method == "CVODE":
                ts, ys, hit, n = _solve_cvode(rtol, atol, t, t_to, [x, v], rhs, (ev_phi, ev_v), armed)
            else:
                events = [ev_phi, ev_v] if armed else [ev_v]
                ts, ys, hit, n = _solve_scipy(method, rtol, atol, t, t_to, [x, v], rhs, events)
                if hit is not None and not armed:
                    hit = (1, *hit[1:])
            out.nfev += n
            out.steps += len(ts) - 1

            def s1_of(speed, f=f, F2=F2):
                return reactions(speed, f, F2, m2, m1)[0]
            if rate == 0.0:
                _refine_max(s1_of, ys[1], best)
            else:  # S1 depends on t too: its values at the steps (the largest lies at a breakpoint)
                for t_i, v_i in zip(ts, ys[1]):
                    best.offer(reactions(float(v_i), f, load(float(t_i)), m2, m1)[0])
            if hit is None:
                t, x, v = t_to, float(ys[0][-1]), float(ys[1][-1])
                break
            which, t, (x, v) = hit[0], hit[1], map(float, hit[2])
            out.events.append(("phi" if which == 0 else "v1", t))
            if len(out.events) > MAX_EVENTS:
                raise PeerGaveUp(f"more than {MAX_EVENTS} events by t = {t:.9g} s (chatter)")
            if which == 0:
                flank, switched = -flank, True
                v = max(v, 0.0)
                best.offer(reactions(v, flank, load(t), m2, m1)[0])  # one-sided after the switch
            else:
                v = 0.0
                best.offer(reactions(0.0, f, load(t), m2, m1)[0])  # the limit v1 -> 0+ of the phase that stops
    out.S1, out.v_end, out.x_end = best.value, v, x
    return out
