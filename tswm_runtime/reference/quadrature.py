"""An independent high-accuracy reference for the two-sided friction wedge: quadrature in v.

Written from first principles (force balance of the wedge); imports nothing from
derivation/, generated/ or the rest of tswm_runtime (the benchmark's reference).
Between events the load F2 is constant, so a sliding phase is the autonomous scalar ODE
v' = A(v) = N(v) / D(v) with

    Psi = tan(gamma + f s rho(v)),  N = F1(v) + Psi F2,  D = m1 + Psi m2 tan(gamma),

flank f (+1 a, -1 b), direction s = sign(v). v moves monotonically inside a phase, so
time is a function of v: t(v) = t_a + int_{v_a}^{v} D/N dv. Events are roots of known
functions of v (phi = 0 flank switch, v = 0, D = 0 Painleve blow-up) and their times
are integrals; scheduled load times are found by inverting t(v).

Every phase integral is taken in the logarithmic variable w = ln|v_lim - v|, where
v_lim is the point the phase runs to (the event, or the equilibrium N = 0 that is
approached asymptotically): dt = e^w |D/N| dw. This turns the logarithmic divergence at
an equilibrium into a smooth, nearly constant integrand, makes the |v|^0.535 of the
friction law at v = 0 analytic in w, and the Painleve end point D = 0 a regular one.
Integrals are mpmath tanh-sinh at DPS digits, roots are bracketed and refined in mp.

For the documented accuracy F1 and rho must evaluate in mpmath arithmetic (accept an
mpf, return an mpf, using mp.tan / mp.power ...); ``paper_wedge`` builds the paper's
gear that way. Float callables work, limited to double precision.

API:
    Wedge(m1, m2, gamma, F1, rho): accel, reactions, phi, D, cones (mpf results)
    solve(wedge, schedule, v0, t_end, t0=0.0) -> Trajectory
    Trajectory: status, t_stop, events [Event], phases [Phase], v_at(t), x_at(t),
                S_extrema()
Known limitation: roots are found by a sign-change scan (128 cells per bracket), so two
roots of one function inside one cell (a tangency) are not seen.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import mpmath as mp
from scipy.optimize import minimize_scalar

DPS = 34  # working digits
FLOOR_DIGITS = DPS - 8  # an equilibrium counts as reached within 10^-FLOOR_DIGITS (relative)
TAIL = 70.0  # finite end points: integrate w down to ln(d_a) - TAIL (e^-70 ~ 4e-31)
PIECE = 8.0  # quadrature pieces in w at most this long
SCAN = 128  # cells of the sign-change scan


def _mode(f, s):
    return ("fwd" if s > 0 else "bwd") + ("_a" if f > 0 else "_b")


def _sgn(x):
    return 1 if x > 0 else (-1 if x < 0 else 0)


@dataclass
class Wedge:
    """Two bodies on a wedge: body 1 along x1 (velocity v), body 2 along x2 = x1 tan(gamma).

    F1(v): drive force on body 1; rho(v) >= 0: friction angle in radians. All methods
    return mpf; f = +1 flank a, -1 flank b; s = +1 forward, -1 backward."""
    m1: float
    m2: float
    gamma: float
    F1: Callable
    rho: Callable

    def _g(self):  # (gamma, tan(gamma)) at the working precision, cached
        c = self.__dict__.get("_gcache")
        if c is None or c[0] != mp.mp.prec:
            g = mp.mpf(self.gamma)
            c = self.__dict__["_gcache"] = (mp.mp.prec, g, mp.tan(g))
        return c[1], c[2]

    def _tg(self):
        return self._g()[1]

    def psi(self, v, f, s):
        return mp.tan(self._g()[0] + f * s * mp.mpf(self.rho(mp.mpf(v))))

    def DN(self, v, f, s, F2):
        """(D, N) with one evaluation of rho and F1."""
        psi = self.psi(v, f, s)
        return mp.mpf(self.m1) + psi * self.m2 * self._tg(), mp.mpf(self.F1(mp.mpf(v))) + psi * F2

    def D(self, v, f, s):
        return mp.mpf(self.m1) + self.psi(v, f, s) * self.m2 * self._tg()

    def N(self, v, f, s, F2):
        return mp.mpf(self.F1(mp.mpf(v))) + self.psi(v, f, s) * F2

    def accel(self, v, f, s, F2):
        D, N = self.DN(v, f, s, F2)
        return N / D

    def reactions(self, v, f, s, F2):
        """(S1, S2) = (F1 - m1 a1, F2 - m2 tan(gamma) a1)."""
        a1 = self.accel(v, f, s, F2)
        return mp.mpf(self.F1(mp.mpf(v))) - self.m1 * a1, F2 - self.m2 * self._tg() * a1

    def phi(self, v, F2):
        """Switching function: flank a while phi > 0, flank b while phi < 0."""
        return mp.mpf(self.F1(mp.mpf(v))) * self._tg() / self.m1 - mp.mpf(F2) / self.m2

    def cones(self, F2):
        """(cone_forward, cone_backward) at rest; stick holds while both are >= 0."""
        g, F1 = mp.mpf(self.gamma), mp.mpf(self.F1(mp.mpf(0)))
        normal = F1 * mp.sin(g) - F2 * mp.cos(g)
        tangential = F1 * mp.cos(g) + F2 * mp.sin(g)
        mu = mp.tan(mp.mpf(self.rho(mp.mpf(0))))
        return mu * abs(normal) - tangential, mu * abs(normal) + tangential


def paper_wedge(m2, m1=11.8, gamma_deg=4.76, Fmax=2178.0, V0=7.85, Vmax=6.5,
                a=0.161, b=0.535, c=0.088):
    """The paper's worm gear with Kloss' drive and the paper's friction law, in mp arithmetic
    (the formulas of tswm_runtime/reference/paper_gear.py; gamma is the double radians(4.76))."""
    gamma = math.radians(gamma_deg)
    cg = mp.cos(mp.mpf(gamma))
    Fmax, V0, Vmax, a, b, c = (mp.mpf(x) for x in (Fmax, V0, Vmax, a, b, c))
    sk = V0 - Vmax

    def kloss(v):
        s = V0 - v
        return 2 * Fmax * s * sk / (s * s + sk * sk)

    def rho(v):
        return mp.radians(1 / (a * mp.power(abs(v) / cg, b) + c))
    return Wedge(m1, m2, gamma, kloss, rho)


class Event(NamedTuple):
    t: object
    kind: str  # 'phi', 'v1', 'D', 'load', 'breakaway'
    v: object
    mode_before: str
    mode_after: str


class Phase(NamedTuple):
    mode: str
    t_start: object
    t_end: object
    v_start: object
    v_end: object
    F2: object


@dataclass
class _Seg:
    """One phase with what it takes to evaluate it. kind: 'slide' or 'rest' (v constant:
    stick, or sliding at an exact equilibrium)."""
    kind: str
    f: int
    s: int
    F2: object
    t_a: object
    v_a: object
    t_b: object = None
    v_b: object = None
    v_lim: object = None  # the point the phase runs to
    lim: str = ""  # 'eq', 'phi', 'v1', 'D'
    sigma: int = 0  # direction of motion of v: sign(A)
    w_a: object = None
    w_lo: object = None  # lower end of the w range integrated
    I_lo: object = None  # int_{w_lo}^{w_a} g
    X_lo: object = None  # int_{w_lo}^{w_a} v g: x1 travelled until the equilibrium (once asked for)
    cache: list = field(default_factory=list)

    @property
    def mode(self):
        return "stick" if (self.kind == "rest" and self.s == 0) else _mode(self.f, self.s)


def _pieces(a, b):
    n = max(1, int(mp.ceil(abs(b - a) / PIECE)))
    return [a + (b - a) * k / n for k in range(n + 1)]


class _Phase:
    """Phase maths in w = ln|v_lim - v| (v = v_lim - sigma e^w, t increases as w decreases)."""

    def __init__(self, wedge, seg):
        self.W, self.g = wedge, seg

    def v(self, w):
        return self.g.v_lim - self.g.sigma * mp.exp(w)

    def dtdw(self, u):  # e^u / |A|, kept signed (D/N) so it stays smooth
        g = self.g
        e = mp.exp(u)
        D, N = self.W.DN(g.v_lim - g.sigma * e, g.f, g.s, g.F2)
        return g.sigma * e * D / N

    def integral(self, w1, w2, weight=None):
        """int_{w1}^{w2} dt/dw (times v if weight) dw."""
        if w1 == w2:
            return mp.mpf(0)
        fn = self.dtdw if weight is None else (lambda u: self.v(u) * self.dtdw(u))
        return mp.quad(fn, _pieces(w1, w2))

    def w_of(self, v):
        return mp.log(abs(self.g.v_lim - v))

    def t_of_v(self, v):
        g = self.g
        if v == g.v_a:
            return g.t_a
        return g.t_a + self.integral(self.w_of(v), g.w_a)

    def invert(self, t):
        """w with t(w) = t (safeguarded Newton in w); None if t is beyond the integrated range."""
        g = self.g
        dt = t - g.t_a
        if dt <= 0:
            return g.w_a
        if dt >= g.I_lo:
            return None
        lo, hi = g.w_lo, g.w_a
        # start from the nearest cached point (w, I(w))
        w, I = g.w_a, mp.mpf(0)
        for wc, Ic in g.cache:
            if Ic <= dt and Ic > I:
                w, I = wc, Ic
        hi = w
        tol = mp.mpf(10) ** (-(DPS - 6)) * (1 + abs(t))
        for _ in range(200):
            G = I - dt
            if abs(G) <= tol:
                break
            if G < 0:
                hi = w
            else:
                lo = w
            step = G / self.dtdw(w)
            w_new = w + step
            if not (lo < w_new < hi):
                w_new = (lo + hi) / 2
            I = I + self.integral(w_new, w)
            w = w_new
            if hi - lo < mp.mpf(10) ** (-(DPS - 4)):
                break
        g.cache.append((w, I))
        return w


class Trajectory:
    """Result of ``solve``. status: 'finished' or 'inconsistent'; t_stop; events; phases."""

    def __init__(self, wedge, segs, events, status, t_stop):
        self.wedge, self._segs, self.events, self.status, self.t_stop = wedge, segs, events, status, t_stop
        self.phases = [Phase(s.mode, s.t_a, s.t_b, s.v_a, s.v_b, s.F2) for s in segs]
        self._x0 = None

    def _seg_at(self, t):
        if t < self._segs[0].t_a or t > self.t_stop:
            raise ValueError(f"t = {t} outside [{self._segs[0].t_a}, {self.t_stop}]")
        for k, s in enumerate(self._segs):
            if t <= s.t_b:
                return k, s
        return len(self._segs) - 1, self._segs[-1]

    def v_at(self, t):
        """v(t) (mpf), by inverting the phase's quadrature."""
        with mp.workdps(DPS):
            t = mp.mpf(t)
            _, s = self._seg_at(t)
            if s.kind == "rest":
                return s.v_a
            if t >= s.t_b:
                return s.v_b
            P = _Phase(self.wedge, s)
            w = P.invert(t)
            return s.v_lim if w is None else P.v(w)

    def _x_in(self, s, t):
        """x1(t) - x1(t_a) inside segment s."""
        if s.kind == "rest":
            return s.v_a * (t - s.t_a)
        P = _Phase(self.wedge, s)
        w = P.invert(t)
        if w is None:  # at the equilibrium (to 10^-FLOOR_DIGITS) from t_a + I_lo on
            if s.X_lo is None:
                s.X_lo = P.integral(s.w_lo, s.w_a, weight=1)
            return s.X_lo + s.v_lim * (t - s.t_a - s.I_lo)
        return P.integral(w, s.w_a, weight=1)

    def x_at(self, t):
        """x1(t) - x1(t0) = int v dt (integral of v D/N dv within a phase)."""
        with mp.workdps(DPS):
            t = mp.mpf(t)
            k, s = self._seg_at(t)
            if self._x0 is None:
                x, self._x0 = mp.mpf(0), []
                for seg in self._segs:
                    self._x0.append(x)
                    x += self._x_in(seg, seg.t_b)
            return self._x0[k] + self._x_in(s, t)

    def S_extrema(self):
        """{'S1': (value at max |S1|, time), 'S2': (...)} over all phases, one-sided limits at
        events; +-inf at t_stop after a Painleve (D -> 0) end."""
        W = self.wedge
        best = {"S1": (mp.mpf(0), None), "S2": (mp.mpf(0), None)}

        def offer(name, val, t):
            if best[name][1] is None or abs(val) > abs(best[name][0]):
                best[name] = (val, t)
        with mp.workdps(DPS):
            for s in self._segs:
                if s.kind == "rest":
                    if s.s == 0:
                        S = (mp.mpf(W.F1(mp.mpf(0))), mp.mpf(s.F2))
                    else:
                        S = W.reactions(s.v_a, s.f, s.s, s.F2)
                    offer("S1", S[0], s.t_a)
                    offer("S2", S[1], s.t_a)
                    continue
                if s.lim == "D" and self.status == "inconsistent" and s is self._segs[-1]:
                    inf = mp.inf * (-s.sigma)  # a1 -> sigma * inf
                    offer("S1", inf, s.t_b)
                    offer("S2", inf, s.t_b)
                P = _Phase(W, s)
                for i, name in enumerate(("S1", "S2")):
                    def val(v):
                        return W.reactions(v, s.f, s.s, s.F2)[i]
                    cand = [s.v_a, s.v_b]
                    grid = [s.v_a + (s.v_b - s.v_a) * k / 40 for k in range(41)]
                    if s.lim == "D" and s is self._segs[-1]:
                        grid = grid[:-1]
                        cand = [s.v_a]
                    vals = [abs(val(v)) for v in grid]
                    k = max(range(len(grid)), key=lambda j: vals[j])
                    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
                    if lo != hi:
                        a, b = sorted((float(lo), float(hi)))
                        r = minimize_scalar(lambda x: -float(abs(val(x))), bounds=(a, b),
                                            method="bounded", options={"xatol": 1e-13 * max(1, abs(b))})
                        cand.append(mp.mpf(r.x))
                    cand.append(grid[k])
                    for v in cand:
                        t = s.t_b if v == s.v_b else P.t_of_v(v)
                        offer(name, val(v), t)
        return best


def _root(h, a, b, ha=None, hb=None):
    """A root of h in the bracket [a, b] (ha, hb of opposite signs): Illinois + bisection."""
    ha = h(a) if ha is None else ha
    hb = h(b) if hb is None else hb
    tol = mp.mpf(10) ** (-(DPS - 2)) * max(1, abs(a), abs(b))
    side = 0
    for _ in range(400):
        if ha == 0:
            return a
        if hb == 0:
            return b
        if abs(b - a) <= tol:
            break
        c = (a * hb - b * ha) / (hb - ha)
        if not (min(a, b) < c < max(a, b)) or side == 3:
            c, side = (a + b) / 2, 0
        hc = h(c)
        if _sgn(hc) == _sgn(hb):
            b, hb = c, hc
            ha /= 2
            side = side + 1 if side >= 0 else 1
        else:
            a, ha = c, hc
            hb /= 2
            side = side - 1 if side <= 0 else -1
        side = 3 if abs(side) >= 3 else side
    return a if abs(ha) < abs(hb) else b


def _first_root(h, v_a, v_b):
    """First root of h from v_a towards v_b by a sign-change scan (None if none). A value
    ~0 at v_a (the event the phase starts at) is replaced by the value just after it."""
    grid = [v_a + (v_b - v_a) * k / SCAN for k in range(SCAN + 1)]
    vals = [h(v) for v in grid]
    scale = max(abs(x) for x in vals)
    if scale == 0:
        return None
    if abs(vals[0]) <= mp.mpf(10) ** (-(DPS - 14)) * scale:
        vals[0] = h(v_a + (v_b - v_a) * mp.mpf(10) ** -12)
    for k in range(SCAN):
        if vals[k + 1] == 0:
            return grid[k + 1]
        if _sgn(vals[k]) * _sgn(vals[k + 1]) < 0:
            return _root(h, grid[k], grid[k + 1], vals[k], vals[k + 1])
    return None


def _limit(W, f, s, F2, v_a, sigma):
    """(v_lim, kind) of a sliding phase from v_a moving in direction sigma: the first of
    N = 0 (equilibrium, 'eq'), D = 0 ('D'), phi = 0 ('phi'), v = 0 ('v1'); if none of them
    within |v - v_a| <= 4^10 max(1, |v_a|), that far point ('far', never to be reached)."""
    fns = {"eq": lambda v: W.N(v, f, s, F2), "D": lambda v: W.D(v, f, s),
           "phi": lambda v: W.phi(v, F2)}
    toward_zero = v_a * sigma < 0
    L = max(mp.mpf(1), abs(v_a))
    while True:
        v_b = mp.mpf(0) if toward_zero else v_a + sigma * L
        found = {}
        for kind, h in fns.items():
            r = _first_root(h, v_a, v_b)
            if r is not None:
                found[kind] = r
        if found:
            order = {"eq": 0, "D": 1, "phi": 2}
            tie = mp.mpf(10) ** (-(DPS - 12)) * max(1, abs(v_a))
            dist = {k: abs(r - v_a) for k, r in found.items()}
            dmin = min(dist.values())
            kind = min((k for k in found if dist[k] <= dmin + tie), key=order.get)
            return found[kind], kind
        if toward_zero:
            return mp.mpf(0), "v1"
        if L > 1e6:  # nothing up to there: a virtual end point, an error if reached
            return v_b, "far"
        L *= 4


def _slide(W, f, s, F2, t_a, v_a):
    """A sliding segment from (t_a, v_a): its limit and the integrated w range."""
    A = W.accel(v_a, f, s, F2)
    scale = abs(mp.mpf(W.F1(v_a))) + abs(W.psi(v_a, f, s) * F2) + 1
    if abs(W.N(v_a, f, s, F2)) <= mp.mpf(10) ** (-(DPS - 6)) * scale:
        return _Seg("rest", f, s, F2, t_a, v_a)
    sigma = _sgn(A)
    v_lim, lim = _limit(W, f, s, F2, v_a, sigma)
    seg = _Seg("slide", f, s, F2, t_a, v_a, v_lim=v_lim, lim=lim, sigma=sigma)
    seg.w_a = mp.log(abs(v_lim - v_a))
    P = _Phase(W, seg)
    if lim == "eq":
        seg.w_lo = mp.log(mp.mpf(10) ** -FLOOR_DIGITS * max(1, abs(v_lim)))
        seg.I_lo = P.integral(seg.w_lo, seg.w_a)
        seg.t_b = mp.inf
    else:
        seg.w_lo = seg.w_a - TAIL
        seg.I_lo = P.integral(seg.w_lo, seg.w_a)
        seg.t_b = t_a + seg.I_lo + P.dtdw(seg.w_lo)  # + tail: int_{-inf}^{w_lo} ~ dt/dw(w_lo)
    return seg


def _enter(W, v, F2, s_keep=None, f_keep=1):
    """Mode entered at speed v under load F2 -> (kind, f, s) with kind 'slide' or 'stick'."""
    if v == 0 and s_keep is None:
        fwd, bwd = W.cones(F2)
        if fwd >= 0 and bwd >= 0:
            return "stick", 0, 0
        s = 1 if fwd < 0 else -1
    else:
        s = s_keep if s_keep is not None else _sgn(v)
    p = W.phi(v, F2)
    f = f_keep if p == 0 else _sgn(p)
    return "slide", f, s


def solve(wedge: Wedge, schedule, v0, t_end, t0=0.0) -> Trajectory:
    """Simulate from (t0, v0) to t_end. schedule = [(t_k, F2_k), ...] sorted by t_k, with
    t_0 <= t0 (its F2 is the initial load); F2 jumps at later t_k (state v continuous)."""
    W = wedge
    with mp.workdps(DPS):
        t, v, t_end = mp.mpf(t0), mp.mpf(v0), mp.mpf(t_end)
        sched = [(mp.mpf(tk), mp.mpf(F)) for tk, F in schedule]
        F2 = [F for tk, F in sched if tk <= t][-1]
        loads = [(tk, F) for tk, F in sched if t < tk < t_end]
        segs, events = [], []
        kind, f, s = _enter(W, v, F2)

        def bad(f, s):
            return kind == "slide" and W.D(v, f, s) <= 0

        def stop(status, segs_, t_):
            return Trajectory(W, segs_, events, status, t_)

        if bad(f, s):
            segs.append(_Seg("rest", f, s, F2, t, v, t_b=t, v_b=v))
            return stop("inconsistent", segs, t)
        while True:
            t_next = loads[0][0] if loads else t_end
            if kind == "stick":
                seg = _Seg("rest", 0, 0, F2, t, mp.mpf(0), t_b=t_next, v_b=mp.mpf(0))
            else:
                seg = _slide(W, f, s, F2, t, v)
                if seg.kind == "rest":
                    seg.t_b, seg.v_b = t_next, v
            segs.append(seg)
            if seg.kind == "slide" and seg.t_b <= t_next:  # a v-event comes first
                if seg.lim == "far":
                    raise RuntimeError(f"v runs away from {v} in mode {_mode(f, s)}")
                seg.v_b = seg.v_lim
                t, v = seg.t_b, seg.v_lim
                before = _mode(f, s)
                if seg.lim == "D":
                    events.append(Event(t, "D", v, before, before))
                    return stop("inconsistent", segs, t)
                if seg.lim == "phi":
                    f = -f
                    events.append(Event(t, "phi", v, before, _mode(f, s)))
                    if W.D(v, f, s) <= 0:
                        return stop("inconsistent", segs, t)
                    continue
                # v = 0
                kind, f, s = _enter(W, mp.mpf(0), F2)
                v = mp.mpf(0)
                events.append(Event(t, "v1", v, before, "stick" if kind == "stick" else _mode(f, s)))
                if kind == "slide" and (W.D(v, f, s) <= 0 or _sgn(W.accel(v, f, s, F2)) != s):
                    return stop("inconsistent", segs, t)
                continue
            # the phase runs to the next scheduled time (or t_end)
            seg.t_b = t_next
            if seg.kind == "slide":
                P = _Phase(W, seg)
                w = P.invert(t_next)
                seg.v_b = seg.v_lim if w is None else P.v(w)
            t, v = t_next, seg.v_b
            if not loads:
                return stop("finished", segs, t)
            F2 = loads.pop(0)[1]
            before = seg.mode
            if kind == "stick":
                kind, f, s = _enter(W, v, F2)
                ev = "load" if kind == "stick" else "breakaway"
            else:
                kind, f, s = _enter(W, v, F2, s_keep=s, f_keep=f)
                ev = "load"
            events.append(Event(t, ev, v, before, "stick" if kind == "stick" else _mode(f, s)))
            if bad(f, s):
                return stop("inconsistent", segs, t)
