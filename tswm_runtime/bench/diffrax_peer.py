"""An optional peer for sweeps: the paper gear's load step (scene paper-runup) as a vmapped
diffrax Dopri5 batch, written as a careful jax user writes it.

The physics is the hand-written force balance of ``reference.paper_gear`` (forward sliding on
flank a or b, stick), in jax.numpy; nothing from tswm's derivation or runtime. Per case
(m2, F2 after the step at ``t_step``), from rest at t = 0:

1. [0, t_step]: free run-up on flank a (F2 = 0; phi > 0 there, no event can happen);
2. [t_step, t_end]: the load; terminal events with a Newton root finder on the dense output:
   v1 = 0 falling and phi = 0 falling on the flank given by the sign of phi (armed only where
   phi can vanish, as ``peers.phi_can_vanish``);
3. after a flank switch, on the other flank to t_end with the v1 = 0 event; after v1 = 0,
   at rest while the static cones hold (the case is flagged when they do not, or when phase
   3 would need another switch).

max |S1| per phase: inside a phase S1 is a function of v1 alone and v1 is monotone, so it is
sampled over the phase's range of v1 and refined by golden-section search around the largest
sample; plus S1 at rest. jax runs in float64. ``batch()`` returns the jitted, vmapped
function of (m2[], F2[], rtol, atol) -> (S1, v1(t_end), x1(t_end), ok) arrays.

Needs jax and diffrax (``pip install -e '.[bench-jax]'``); ``available()`` says whether they import.
"""
from __future__ import annotations

import importlib.util
import math

from tswm_runtime.reference.paper_gear import FMAX, GAMMA, M1, V0, VMAX

SAMPLES = 17  # v1 samples per phase for max |S1|
GOLDEN_STEPS = 40  # golden-section steps around the largest sample
MAX_STEPS = 16384


def available() -> bool:
    """Whether jax and diffrax are importable."""
    return all(importlib.util.find_spec(name) is not None for name in ("jax", "diffrax", "optimistix"))


def batch(t_step: float = 0.3, t_end: float = 1.0, m1: float = M1):
    """The jitted batch: (m2[], F2[], rtol, atol) -> arrays (S1 where |S1| is largest, v1(t_end),
    x1(t_end), ok); rtol, atol of diffrax's PID controller (Dopri5), traced: one compile for all."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import diffrax
    import jax.numpy as jnp
    import optimistix as optx

    tan_g = math.tan(GAMMA)

    def kloss(v):
        s, sk = V0 - v, V0 - VMAX
        return 2 * FMAX * s * sk / (s * s + sk * sk)

    def rho(v):
        return jnp.deg2rad(1.0 / (0.161 * (jnp.abs(v) / math.cos(GAMMA)) ** 0.535 + 0.088))

    def accel(v, flank, F2, m2):
        psi = jnp.tan(GAMMA + flank * rho(v))
        return (kloss(v) + psi * F2) / (m1 + psi * m2 * tan_g)

    def s1(v, flank, F2, m2):
        return kloss(v) - m1 * accel(v, flank, F2, m2)

    def phi(v, F2, m2):
        return kloss(v) * tan_g / m1 - F2 / m2

    def sticks(F2):
        mu, F1 = jnp.tan(rho(0.0)), kloss(0.0)
        normal = F1 * math.sin(GAMMA) - F2 * math.cos(GAMMA)
        tangential = F1 * math.cos(GAMMA) + F2 * math.sin(GAMMA)
        return (mu * jnp.abs(normal) - tangential >= 0) & (mu * jnp.abs(normal) + tangential >= 0)

    def rhs(t, y, args):
        flank, F2, m2, _ = args
        return jnp.stack([y[1], accel(y[1], flank, F2, m2)])

    def v_zero(t, y, args, **kwargs):
        return y[1]

    def phi_zero(t, y, args, **kwargs):
        flank, F2, m2, armed = args
        return jnp.where(armed, flank * phi(y[1], F2, m2), 1.0)

    term = diffrax.ODETerm(rhs)
    solver = diffrax.Dopri5()
    event = diffrax.Event((v_zero, phi_zero), root_finder=optx.Newton(rtol=1e-12, atol=1e-12),
                          direction=(False, False))

    def solve(t0, y0, args, with_events, controller):
        sol = diffrax.diffeqsolve(term, solver, t0, t_end if with_events else t_step, None, y0, args,
                                  saveat=diffrax.SaveAt(t1=True), stepsize_controller=controller,
                                  event=event if with_events else None, max_steps=MAX_STEPS, throw=False)
        mask = sol.event_mask if with_events else (False, False)
        ok = (sol.result == diffrax.RESULTS.successful) | (sol.result == diffrax.RESULTS.event_occurred)
        return sol.ts[-1], sol.ys[-1], mask, ok

    def largest(va, vb, flank, F2, m2):
        """S1 where |S1| is largest over v1 in [va, vb] (either order)."""
        vs = va + (vb - va) * jnp.linspace(0.0, 1.0, SAMPLES)
        values = s1(vs, flank, F2, m2)
        k = jnp.argmax(jnp.abs(values))
        lo, hi = vs[jnp.maximum(k - 1, 0)], vs[jnp.minimum(k + 1, SAMPLES - 1)]
        ratio = (math.sqrt(5.0) - 1.0) / 2.0

        def step(_, bracket):
            a, b = bracket
            c, d = b - ratio * (b - a), a + ratio * (b - a)
            left = jnp.abs(s1(c, flank, F2, m2)) >= jnp.abs(s1(d, flank, F2, m2))
            return jnp.where(left, a, c), jnp.where(left, d, b)
        a, b = jax.lax.fori_loop(0, GOLDEN_STEPS, step, (lo, hi))
        inner = s1(0.5 * (a + b), flank, F2, m2)
        best = values[k]
        return jnp.where(jnp.abs(inner) > jnp.abs(best), inner, best)

    def pick(current, candidate):
        return jnp.where(jnp.abs(candidate) > jnp.abs(current), candidate, current)

    def one(m2, F2, rtol, atol):
        controller = diffrax.PIDController(rtol=rtol, atol=atol)
        zero = jnp.zeros((), jnp.float64)
        _, y1, _, ok1 = solve(0.0, jnp.stack([zero, zero]), (1.0, 0.0, m2, False), False, controller)
        best = largest(zero, y1[1], 1.0, 0.0, m2)
        flank = jnp.where(phi(y1[1], F2, m2) >= 0, 1.0, -1.0)
        armed = ~((flank > 0) & (F2 <= 0) & (y1[1] <= V0))
        t2, y2, (stop2, switch2), ok2 = solve(t_step, y1, (flank, F2, m2, armed), True, controller)
        # a phase that stops ends at v1 = 0 exactly (S1 is steep there: rho has |v1|^0.535)
        best = pick(best, largest(y1[1], jnp.where(stop2, 0.0, y2[1]), flank, F2, m2))
        # phase 3: the other flank after a switch; nothing to integrate otherwise (t0 = t_end)
        t3_0 = jnp.where(switch2, t2, t_end)
        t3, y3, (stop3, switch3), ok3 = solve(t3_0, y2, (-flank, F2, m2, True), True, controller)
        best = pick(best, jnp.where(switch2, largest(y2[1], jnp.where(stop3, 0.0, y3[1]), -flank, F2, m2), best))
        stopped = stop2 | (switch2 & stop3)
        at_rest_ok = ~stopped | sticks(F2)
        best = pick(best, jnp.where(stopped, kloss(0.0), best))
        y_end = jnp.where(switch2, y3, y2)
        v_end = jnp.where(stopped, 0.0, y_end[1])
        ok = ok1 & ok2 & ok3 & at_rest_ok & ~(switch2 & switch3)
        return best, v_end, y_end[0], ok

    return jax.jit(jax.vmap(one, in_axes=(0, 0, None, None)))


def run(jobs: list[dict]) -> list[dict]:
    """Each job {"m2": [...], "F2": [...], "rtol": r, "atol": a, "repeats": n} through one jitted
    batch: the outcome per case, the seconds of the first call (the jit compile, in the first job
    and for each new number of cases) and the wall and CPU seconds of ``repeats`` more whole calls
    (results on the host)."""
    import time

    import numpy as np

    solve, out = batch(), []
    for job in jobs:
        m2, F2 = np.asarray(job["m2"], np.float64), np.asarray(job["F2"], np.float64)
        t0 = time.perf_counter()
        S1, v_end, x_end, ok = (np.asarray(x) for x in solve(m2, F2, job["rtol"], job["atol"]))
        first = time.perf_counter() - t0
        seconds, cpu = [], []
        for _ in range(job.get("repeats", 0)):
            t0, c0 = time.perf_counter(), time.process_time()
            [np.asarray(x) for x in solve(m2, F2, job["rtol"], job["atol"])]
            seconds.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out.append({"S1": S1.tolist(), "v_end": v_end.tolist(), "x_end": x_end.tolist(), "ok": ok.tolist(),
                    "first_call_s": first, "seconds": seconds, "cpu_seconds": cpu, "rtol": job["rtol"],
                    "atol": job["atol"]})
    return out


def versions() -> dict:
    """The versions of jax, jaxlib, diffrax and optimistix ('' for one not installed)."""
    from importlib import metadata

    out = {}
    for name in ("jax", "jaxlib", "diffrax", "optimistix"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = ""
    return out


def main() -> None:
    """``python -m tswm_runtime.bench.diffrax_peer`` in an interpreter with jax and diffrax: reads a
    list of ``run``'s jobs as JSON on stdin, writes {"runs": run(jobs), "versions": versions()}
    on stdout (how ``tswm bench`` uses jax installed in another environment)."""
    import json
    import sys

    json.dump({"runs": run(json.load(sys.stdin)), "versions": versions()}, sys.stdout)


if __name__ == "__main__":
    main()
