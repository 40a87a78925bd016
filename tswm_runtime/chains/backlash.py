"""The impact of a chain's stage with a clearance (the open one, the current clearance stage), in compiled code: its
flanks meet where the gap reaches 0 (flank a) or the clearance (flank b).

The generated module's ``impact`` writes the collision's frame (IMPACT_FRAME: the normal speed nu = f g' and the slip,
the inverse mass W of the two groups reduced to the stage, tan(rho_k), e, each group's speed change per unit impulse),
Routh's process with Coulomb friction and restitution (``hybrid/impact.py``, ``collide``) gives the impulse, and the
groups' speeds jump by it. The stage closes on that flank where the impact is plastic or its rebound lies within the
tolerances as the single-stage runtime's ``_settles`` judges it (tswm_runtime/hybrid/machine.py): its speed within
the velocity tolerance, or the height of the next bounce under the open phase's acceleration back onto the flank,
and so of every later one, within the gap's tolerance; this ends a sequence of ever smaller bounces at its
accumulation point, and the impact is then taken as plastic (e = 0: its loss is the whole normal speed's, as the
stem's pickup takes it). Then the output group's speed is the rigid chain's (vk = c_k v0, a change of rounding
size), and the mode logic decides all stages at once (``rules.decide``); else the stage stays open.
"""
import numpy as np

from tswm_runtime.chains.rules import UNIQUE, current_index, in_group, open_phase, open_stage, separating
from tswm_runtime.hybrid.impact import OK, collide
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit

IMPACT_COLUMNS = ("t", "flank", "nu before", "nu after", "energy lost", "closed", "v0 before", "vk before", "v0 after",
                  "vk after", "stage")


@njit(error_model="numpy")
def pushed(c, flank, p):
    """A group stuck at rest (latch held_in or held_out) takes the impulse on ``flank`` moving the way it pushes it
    (the output group forward on flank a, the input group backward), its closed stages driven from the open stage's
    side: the output group's tractive, the input group's inverse-tractive (their regimes in the impact's frame)."""
    k = open_stage(c, p)
    for g in range(2):
        if p[c.p_direction + 3 - g] > 0.0:
            p[c.p_direction + g] = float(flank if g == 1 else -flank)
            for i in range(c.stages):
                if in_group(k, i + 1, g):
                    p[c.p_rho_sign + i] = 1.0 if g == 1 else -1.0


@njit(error_model="numpy", refcounted=True)  # impact.collide (numba.njit: counted as its caller) allocates
def strike(fns, chain_fns, c, flank, t, y, p, tol, w, row):
    """The impact on ``flank`` (+1 a, -1 b) at (t, y): y's groups' speeds after it, the contact latch (``flank``: the
    stage closed, 0: it rebounds open); row = IMPACT_COLUMNS. Returns (False when the impulse cannot stop the
    approach, the flight time to the next impact on this flank if the open phase's accelerations stay: inf for
    none), so that the step after a rebound can be kept short enough for the gap's guard to see it return."""
    f, mode, contact = w.frame, c.open_mode + current_index(c, p), c.p_contact + current_index(c, p)
    pushed(c, flank, p)
    copy_into(w.before, p)   # the latches of the impact (the open phase's regimes), for a plastic one again
    chain_fns.impact(flank, t, y, p, f)
    nu_before = f[0]
    p_n, p_t, nu, s, lost, outcome = collide(f[0], f[1], f[2], f[3], f[4], f[5], f[6])
    row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7] = t, flank, nu_before, nu, lost, 0.0, y[1], y[3]
    flight = np.inf
    if outcome != OK:
        return False, flight
    y[1] += f[7] * p_n + f[8] * p_t
    y[3] += f[9] * p_n + f[10] * p_t
    fns.guards(mode, t, y, p, w.g)
    n = c.stages
    gap_tol = tol.atol[2] + tol.rtol * (abs(w.g[n + 3]) + abs(w.g[n + 4]))
    closes = nu <= tol.atol[3] + tol.rtol * abs(nu_before)
    if not closes:
        p[contact] = 0.0
        outcome_open, _ = open_phase(fns, chain_fns, c, t, y, p, w)
        if outcome_open == UNIQUE:
            fns.rhs(mode, t, y, p, w.f)
            toward = -separating(chain_fns, c, flank, t, y, p, w)
            closes = toward > 0.0 and nu * nu <= 2.0 * toward * gap_tol
            flight = 2.0 * nu / toward if toward > 0.0 else np.inf
    if closes:   # the impact taken as plastic: its loss the whole normal speed's, the flanks together after it
        if nu != 0.0:
            y[1], y[3] = row[6], row[7]
            copy_into(p, w.before)
            chain_fns.impact(flank, t, y, p, f)
            p_n, p_t, nu, s, lost, outcome = collide(f[0], f[1], f[2], f[3], f[4], f[5], 0.0)
            y[1] += f[7] * p_n + f[8] * p_t
            y[3] += f[9] * p_n + f[10] * p_t
            row[3], row[4] = nu, lost
        p[contact] = flank
        y[3] = p[c.p_speed_k] * y[1]
        row[5] = 1.0
    else:
        p[contact] = 0.0
    row[8], row[9], row[10] = y[1], y[3], open_stage(c, p)
    return True, flight

