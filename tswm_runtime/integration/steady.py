"""Equilibrium tails: a state at rest in its own dynamics is held, not stepped through.

On an equilibrium of an autonomous scalar segment (one state, v1; the laws latched, so
the right-hand side has df/dt = 0) where f is within half the tolerance of 0
relative to J = df/dy < 0, the solution stays that close to the true, stable equilibrium
for all later times (its offset |f|/|J| decays). An explicit method would keep stepping
at its stability limit (|h J| about 3) for the rest of the run, so the cost would grow
with the simulated time. ``hold`` instead keeps the state and finds the first time at
which a guard changes sign with it held: with the state fixed only an explicit time
dependence can move a guard (a scheduled law time), and such a crossing is located on
t alone, exactly. The held state is the equilibrium itself, one Newton step from the
integrated one (y - f/J, its error quadratic in |f/J|): the transient's remaining decay,
below half the tolerance, is what holding gives up.
"""
from tswm_runtime.jit.cache_guard import njit

from tswm_runtime.integration import events

OFFSET_FRACTION = 0.5  # hold when |f| / |J| is below this fraction of the tolerance
STEP_FRACTION = 10.0  # look (one Jacobian) when the last step moved the state by less than this many tolerances


@njit(error_model="numpy")
def worth_checking(f, h, tol, y):
    """Cheap filter: a scalar state that the last step moved by a few tolerances at most (an
    explicit method on a stable equilibrium moves it by about 3 |f / J|, its stability limit)."""
    return y.size == 1 and abs(f[0]) * h < STEP_FRACTION * (tol.atol[0] + tol.rtol * abs(y[0]))


@njit(error_model="numpy")
def at_stable_rest(f, J, dfdt, tol, y, quad):
    """True at a stable equilibrium of an autonomous scalar segment, close enough that
    holding it moves the state by less than OFFSET_FRACTION of its tolerance, and its
    integral (x1, by quadrature) by less than that of its own: the offset f/J would decay
    like exp(J t), adding (f/J)/|J| to the integral."""
    if not (dfdt[0] == 0.0 and J[0, 0] < 0.0):
        return False
    offset = abs(f[0] / J[0, 0])
    held = offset < OFFSET_FRACTION * (tol.atol[0] + tol.rtol * abs(y[0]))
    if quad.size > 0:
        held = held and offset / abs(J[0, 0]) < OFFSET_FRACTION * (tol.atol[0] + tol.rtol * abs(quad[0]))
    return held


@njit(error_model="numpy", refcounted=True)
def hold(guards, mode, t, y, p, t_end, g_now, ev, g_tmp):
    """(time, guard) up to which the held state lasts: the earliest guard sign change in
    (t, t_end] with y fixed (guard -1: none, the time is t_end). The time is the far end
    of the final bracket, as for every located event."""
    guards(mode, t_end, y, p, g_tmp)
    g_end = g_tmp.copy()
    k_best, t_best = -1, t_end
    for k in range(g_now.size):
        g0, g1 = g_now[k], g_end[k]
        if abs(g0) <= ev.gtol or (g0 > 0.0) == (g1 > 0.0) or g1 == 0.0:
            continue
        if ev.directions[k] != 0 and (ev.directions[k] > 0) != (g1 > 0.0):
            continue
        state = events.bracket_start(t, g0, t_end, g1)
        ttol = events.time_tolerance(t_end, ev.ttol)
        while not events.bracket_done(state, ttol):
            c = events.bracket_next(state, ttol)
            guards(mode, c, y, p, g_tmp)
            state = events.bracket_update(state, c, g_tmp[k])
        if k_best < 0 or state[2] < t_best:
            k_best, t_best = k, state[2]
    return t_best, k_best
