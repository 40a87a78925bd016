"""What the chain tests share: scene texts of plain wedges (the worm gear and stem nut's is the chain
bench's, tswm_runtime/bench/chain.py ``worm_and_nut``), the examples' folder, and the hand reference:
Newton per body with Coulomb per stage integrated by scipy's DOP853 at rtol 1e-12, its modes found by
enumerating every flank combination at each event."""
from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

DEG = math.pi / 180
TIGHT = {"rtol": 1e-11, "atol": 1e-13}
EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"


def wedges(name: str, gammas, mus, masses, forces, spring: float = 0.0, v0: float = 1.0, t_end: float = 0.5) -> str:
    """A chain scene of plain wedges (levers 1), a spring on the last body."""
    text = f'name = "{name}"\n'
    for g, mu in zip(gammas, mus):
        text += f'[[stage]]\nkind = "wedge"\ngamma = "{g!r} deg"\nmu = {mu!r}\n'
    for j, (m, f) in enumerate(zip(masses, forces)):
        text += f'[[body]]\nmass = "{m!r} kg"\nforce = "{f!r} N"\n'
        if j == len(masses) - 1 and spring:
            text += f'stiffness = "{spring!r} N/m"\n'
    return text + f"[run]\nt_end = {t_end!r}\nv0 = {v0!r}\n"


class HandChain:
    """Wedges in series: body i-1 moves x1 = r_in q_{i-1}, body i x2 = r_out q_i = tan(gamma_i) x1. Stage i's flank
    has the normal n = (sin g, cos g) and the slip direction t = (-cos g, sin g) in (x1, x2); its force on
    body i is sigma N n - mu N s t (sigma = +1 flank a, -1 flank b, N >= 0, s = sign of the slip = sign
    v0), on body i-1 the opposite; a body feels the force along its motion times its lever. ``mus`` are
    the coefficients in the wedge plane (a helical flank's mu / cos(alpha_n), typed in by the caller)."""

    def __init__(self, gammas, mus, masses, forces, spring=0.0, levers=None, motor=None):
        self.g = np.radians(gammas)
        self.mu, self.m, self.F = np.array(mus), np.array(masses), np.array(forces, dtype=float)
        self.n = len(gammas)
        self.r_in, self.r_out = np.array(levers or [(1.0, 1.0)] * self.n).T   # x1 = r_in q_{i-1}, x2 = r_out q_i
        self.c = np.cumprod([1.0, *(self.r_in * np.tan(self.g) / self.r_out)])   # v_j / v_0
        self.k = np.zeros(self.n + 1)
        self.k[-1] = spring
        self.motor = motor            # (speeds, torques, U / U_n) on body 0: np.interp of the table times (U/U_n)^2

    def forces(self, q0, v0):
        F = self.F - self.k * self.c * q0
        if self.motor:
            speeds, torques, voltage = self.motor
            F[0] += voltage**2 * np.interp(v0, speeds, torques)
        return F

    def solve(self, q0, s, sigma, v0=0.0):
        """(a_0, N_1..N_n): Newton for every body, with a_j = c_j a_0."""
        A = np.zeros((self.n + 1, self.n + 1))
        A[:, 0] = self.m * self.c
        for i in range(self.n):
            g, mu = self.g[i], self.mu[i]
            A[i + 1, 1 + i] = -self.r_out[i] * (sigma[i] * math.cos(g) - mu * s * math.sin(g))   # x2 part, body i
            A[i, 1 + i] = self.r_in[i] * (sigma[i] * math.sin(g) + mu * s * math.cos(g))   # minus the x1 part, i-1
        x = np.linalg.solve(A, self.forces(q0, v0))
        return x[0], x[1:]

    def consistent(self, q0, s, at_rest, noise=1e-9, v0=0.0):
        """Flank combinations with every N >= 0, within ``noise`` [N] of the event's location (from rest:
        leaving it in direction s)."""
        found = []
        for sigma in itertools.product((1, -1), repeat=self.n):
            a, N = self.solve(q0, s, sigma, v0)
            if np.all(N >= -noise) and (not at_rest or s * a > 0):
                found.append(sigma)
        return found

    def run(self, v0, t_end):
        """[(t, s, sigma)] of each sliding phase, or (t, 0, None) for rest; and the final (t, y)."""
        t, y, log = 0.0, np.array([0.0, v0]), []
        while t < t_end:
            if y[1] == 0.0:
                moves = [(s, sg) for s in (1, -1) for sg in self.consistent(y[0], s, True)]
                if not moves:
                    log.append((t, 0, None))
                    return log, t_end, y
                assert len(moves) == 1, moves
                s, sigma = moves[0]
            else:
                s = 1 if y[1] > 0 else -1
                found = self.consistent(y[0], s, False, v0=y[1])
                sigma = found[0] if len(found) == 1 else [f for f in found if f != log[-1][2]][0]
            log.append((t, s, sigma))
            events = [self._normal(i, s, sigma) for i in range(self.n)] + [self._stop(s)]
            sol = solve_ivp(lambda t, y: [y[1], self.solve(y[0], s, sigma, y[1])[0]], (t, t_end), y, method="DOP853",
                            rtol=1e-12, atol=1e-14, events=events)
            t, y = sol.t[-1], sol.y[:, -1].copy()
            if sol.status == 1 and len(sol.t_events[-1]):
                y[1] = 0.0
        return log, t, y

    def _normal(self, i, s, sigma):
        def event(t, y):
            return self.solve(y[0], s, sigma, y[1])[1][i]
        event.terminal, event.direction = True, -1
        return event

    @staticmethod
    def _stop(s):
        def event(t, y):
            return y[1]
        event.terminal, event.direction = True, -s
        return event


def regimes(hand_log, stage):
    """(t, regime, flank) of a stage from the hand log: tractive where sigma s = +1."""
    out = []
    for t, s, sigma in hand_log:
        entry = ("resting", "") if sigma is None else (
            "tractive" if sigma[stage] * s > 0 else "inverse-tractive", "a" if sigma[stage] > 0 else "b")
        if not out or out[-1][1:] != entry:
            out.append((t, *entry))
    return out


def assert_like_hand(result, hand: HandChain, v0: float, t_end: float, tol: float = 1e-9):
    log, t_stop, y = hand.run(v0, t_end)
    for k in range(hand.n):
        expected = regimes(log, k)
        got = [(p.t_start, p.regime, p.flank) for p in result.stages[k].phases]
        assert [g[1:] for g in got] == [e[1:] for e in expected], (k, got, expected)
        assert np.allclose([g[0] for g in got], [e[0] for e in expected], rtol=tol, atol=tol), (got, expected)
    assert result.status == "finished"
    assert result.q0[-1] == pytest.approx(y[0], rel=tol, abs=tol)
    assert result.v0[-1] == pytest.approx(y[1], rel=tol, abs=tol)
    return log
