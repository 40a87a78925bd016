"""A two-stage drive train in the bench: worm gear and stem nut against a spring, tswm against scipy.

The case: a worm (lead angle 4.76 deg, mu 0.05) turns a wheel with a stem nut (Tr 18x4, mu 0.02;
neither stage self-locks) that drives a 20 kg stem against 2 kN and into a seat of 200 MN/m, coasting
from 150 rad/s. The seat stops the stem and drives the train back, both stages inverse-tractive;
past its balance point it brakes the train again, both stages change flank at once, and the train
swings to and fro, losing energy to friction in each swing: 7 events in the 5 s of the run.

The peer (``peer_run``) is the train as a careful scipy user writes it: Newton for every body with
Coulomb's law per stage, tan(rho') = mu / cos(alpha_n), in closed form per mode (the acceleration and
each normal force are affine in q0, their coefficients solved once per mode), solve_ivp with terminal
events on every normal force and on v0, and the next mode found at each event by trying every
flank combination. Its DOP853 run at rtol 1e-13 is the reference. tswm's cost is the whole
``simulate_chain`` call (the module generated and compiled before, untimed).
"""
from __future__ import annotations

import itertools
import math
import os
import random
import statistics
import time
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp


def worm_and_nut(name: str, *, worm_mu: float = 0.05, screw_mu: float = 0.15, drive: str = "",
                 load: str = 'force = "-20 kN"', run: str = "", description: str = "") -> str:
    """Chain scene text: the paper's worm (lead angle 4.76 deg, radii 25 and 80 mm, rotor 0.0069 kg m^2)
    turning a wheel (0.02 kg m^2) with a Tr 18x4 stem nut (d_m 18 mm) on a 20 kg stem. ``drive`` and
    ``load`` are TOML lines of body 0 and of the stem, ``run`` those of [run] (none: no [run] table)."""
    return (f'name = "{name}"\n' + (f'description = "{description}"\n' if description else "") +
            f'[[stage]]\nkind = "worm_gear"\nlead_angle = "4.76 deg"\npressure_angle = "20 deg"\n'
            f'worm_radius = "25 mm"\nwheel_radius = "80 mm"\nmu = {worm_mu!r}\n'
            f'[[stage]]\nkind = "power_screw"\nlead = "4 mm"\nflank_angle = "15 deg"\nmean_diameter = "18 mm"\n'
            f'mu = {screw_mu!r}\n'
            f'[[body]]\ninertia = "0.0069 kg m^2"\n{drive}' + ("\n" if drive else "") +
            f'[[body]]\ninertia = "0.02 kg m^2"\n[[body]]\nmass = "20 kg"\n{load}\n' +
            (f"[run]\n{run}\n" if run else ""))


SCENE = worm_and_nut("bench-worm-nut-spring", screw_mu=0.02, load='force = "-2 kN"\nstiffness = "2e8 N/m"',
                     run="t_end = 5.0\nv0 = 150.0",
                     description="Worm gear and stem nut driving a stem into a seat and swinging back and forth")
T_END, V0 = 5.0, 150.0
PEERS = ("RK45", "DOP853", "LSODA")
REFERENCE_RTOL, REFERENCE_ATOL = 1e-13, 1e-16
TOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11)
LEVELS = (1e-6, 1e-9)
TARGET = 20.0
MAX_EVENTS = 100       # a peer run with more is given up
SAME_ZERO = 1e-6       # relative: a normal force this close to 0 at an event is 0


@dataclass(frozen=True)
class Outcome:
    q_end: float                 # q0 at t_end, rad
    t_rest: float                # when the train came to rest for good, s (t_end if it did not, as in this case)
    events: int


class Train:
    """The case by hand: worm, wheel and nut, stem with its spring."""

    def __init__(self):
        lam = math.atan(0.004 / (math.pi * 0.018))
        self.gamma = (4.76 * math.pi / 180, lam)
        self.tan_rho = (0.05 / math.cos(20 * math.pi / 180),
                        0.02 / math.cos(math.atan(math.tan(15 * math.pi / 180) * math.cos(lam))))
        self.lever = ((0.025, 0.08), (0.009, 1.0))
        self.inertia = np.array((0.0069, 0.02, 20.0))
        ratios = [r_in * math.tan(g) / r_out for g, (r_in, r_out) in zip(self.gamma, self.lever)]
        self.speed = np.cumprod([1.0, *ratios])              # v_j / v_0
        self.stiffness, self.load = 2e8, -2000.0
        self.modes = {(s, sigma): self._affine(s, sigma) for s in (1, -1)
                      for sigma in itertools.product((1, -1), repeat=2)}

    def _solve(self, q0: float, s: int, sigma) -> np.ndarray:
        """(a_0, N_1, N_2): Newton for every body; stage k pushes body k with sigma N n - mu N s t."""
        A = np.zeros((3, 3))
        A[:, 0] = self.inertia * self.speed
        for k, (g, (r_in, r_out)) in enumerate(zip(self.gamma, self.lever)):
            mu = self.tan_rho[k]
            A[k + 1, 1 + k] = -r_out * (sigma[k] * math.cos(g) - mu * s * math.sin(g))
            A[k, 1 + k] = r_in * (sigma[k] * math.sin(g) + mu * s * math.cos(g))
        forces = np.array((0.0, 0.0, self.load - self.stiffness * self.speed[2] * q0))
        return np.linalg.solve(A, forces)

    def _affine(self, s: int, sigma) -> tuple[np.ndarray, np.ndarray]:
        at0 = self._solve(0.0, s, sigma)
        return at0, self._solve(1.0, s, sigma) - at0        # (a_0, N_1, N_2) = c + d q0

    def consistent(self, q0: float, s: int, from_rest: bool) -> list:
        out = []
        for sigma in itertools.product((1, -1), repeat=2):
            c, d = self.modes[(s, sigma)]
            a, *normal = c + d * q0
            if min(normal) >= -1e-9 * max(1.0, abs(d[1:]).max() * abs(q0)) and (not from_rest or s * a > 0):
                out.append(sigma)
        return out


def peer_run(method: str, rtol: float, atol: float, train: Train | None = None) -> Outcome:
    """The train integrated by scipy's ``method`` from q0 = 0, v0 = V0 to T_END."""
    train = train or Train()
    t, y, events, sigma, switched = 0.0, np.array([0.0, V0]), 0, None, []
    while t < T_END:
        if y[1] == 0.0:
            moves = [(s, sg) for s in (1, -1) for sg in train.consistent(y[0], s, True)]
            if not moves:
                return Outcome(y[0], t, events)
            s, sigma = moves[0]
        elif switched:                       # these stages' normal forces reached 0: they change flank
            sigma = tuple(-f if k in switched else f for k, f in enumerate(sigma))
        else:
            s = 1 if y[1] > 0 else -1
            (sigma,) = train.consistent(y[0], s, False)
        c, d = train.modes[(s, sigma)]

        def rhs(_t, y, a=c[0], b=d[0]):
            return (y[1], a + b * y[0])

        def stop(_t, y):
            return y[1]
        stop.terminal, stop.direction = True, -s
        guards = [stop]
        for k in (1, 2):
            def normal(_t, y, ck=c[k], dk=d[k]):
                return ck + dk * y[0]
            normal.terminal, normal.direction = True, -1
            guards.append(normal)
        sol = solve_ivp(rhs, (t, T_END), y, method=method, rtol=rtol, atol=atol, events=guards)
        t, y = float(sol.t[-1]), sol.y[:, -1].copy()
        if sol.status == 1:
            events += 1
            if events > MAX_EVENTS:
                raise RuntimeError(f"more than {MAX_EVENTS} events (chattering at t = {t:.9g} s)")
            # every stage whose normal force is 0 there (at the load's balance point both are at once)
            switched = [k for k in (0, 1) if abs(c[k + 1] + d[k + 1] * y[0]) <= SAME_ZERO * (abs(c[k + 1]) + abs(
                d[k + 1]) * max(1.0, abs(y[0])))] if not len(sol.t_events[0]) else []
            if len(sol.t_events[0]):
                y[1] = 0.0
    return Outcome(float(y[0]), T_END, events)


def tswm_run(module, rtol: float, atol: float) -> Outcome:
    """tswm's whole simulate_chain call on the case's module."""
    from tswm_runtime.simulation.chain import simulate_chain

    result = simulate_chain(module, rtol=rtol, atol=atol, points=2)
    if result.status != "finished":
        raise RuntimeError(f"tswm: {result.status}: {result.message}")
    rest = [e["t"] for e in result.events if e["to"] == "resting"]
    return Outcome(float(result.q0[-1]), rest[-1] if rest else T_END, len(result.events) - 1)


def error(outcome: Outcome, reference: Outcome) -> float:
    """The larger of q0(t_end)'s relative error and the rest time's error over t_end."""
    return max(abs(outcome.q_end - reference.q_end) / abs(reference.q_end),
               abs(outcome.t_rest - reference.t_rest) / T_END)


def run(rounds: int = 5, tols=TOLS, log=print) -> dict:
    """``measure`` on the case's module: SCENE written to a temporary file, its module generated and
    compiled by one untimed call."""
    import tempfile
    from pathlib import Path

    from tswm_runtime.model.scenes import load_chain_model

    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "bench-worm-nut-spring.toml"
        scene.write_text(SCENE)
        module = load_chain_model(scene)
        tswm_run(module, 1e-6, 1e-9)
        return measure(module, rounds, tols, log)


def measure(module, rounds: int = 5, tols=TOLS, log=print) -> dict:
    """Errors against the reference, then ``rounds`` interleaved shuffled rounds of every (solver, rtol),
    whole calls, one process; medians; the cost at equal error and tswm's factor over the fastest peer."""
    from tswm_runtime.bench.report import cost_at

    reference = peer_run("DOP853", REFERENCE_RTOL, REFERENCE_ATOL)
    calls = {("tswm", r): (lambda r=r: tswm_run(module, r, r * 1e-3)) for r in tols}
    calls.update({(p, r): (lambda p=p, r=r: peer_run(p, r, r * 1e-3)) for p in PEERS for r in tols})
    errors = {}
    for key, call in calls.items():
        try:
            errors[key] = error(call(), reference)
        except Exception as failure:  # noqa: BLE001 - a solver failing at a tolerance is left out there
            log(f"  {key[0]} rtol {key[1]:g}: {failure}")
    times: dict = {key: [] for key in errors}
    load_before = os.getloadavg()[0]
    for rep in range(rounds):
        order = list(errors)
        random.Random(rep).shuffle(order)
        for key in order:
            start = time.perf_counter()
            calls[key]()
            times[key].append(time.perf_counter() - start)
    median = {key: statistics.median(ts) for key, ts in times.items()}
    costs = {level: {solver: cost_at([(errors[k], median[k]) for k in errors if k[0] == solver], level)
                     for solver in ("tswm", *PEERS)} for level in LEVELS}
    verdicts = []
    for level, cost in costs.items():
        best = min((p for p in PEERS if math.isfinite(cost[p])), key=cost.get, default=None)
        factor = cost[best] / cost["tswm"] if best else math.nan
        verdicts.append({"level": level, "peer": best, "peer_s": cost[best] if best else math.nan,
                         "tswm_s": cost["tswm"], "factor": factor, "target": TARGET})
    return {"reference": reference, "errors": errors, "median_s": median, "verdicts": verdicts,
            "load": (load_before, os.getloadavg()[0]), "rounds": rounds}
