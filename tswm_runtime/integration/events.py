"""Event location on a step's dense output, shared by all integration methods.

Both methods describe an accepted step [t_a, t_b = t_a + h] by its dense output
y(t_a + theta h) = y_a + h sum_j Q[:, j] theta^(j+1), j = 0..3 (``dense_eval``).

Rules (lessons from the peers' issue trackers: scipy 9228, 17066, 18039):

* Guard k fires when it changes sign in its direction d_k: +1 rising (- to +),
  -1 falling (+ to -), 0 both. Values with |g| <= gtol count as zero and carry
  no sign, so touching zero without changing sign (grazing) is no event.
* Sampling: the guards are evaluated at GUARD_SUBINTERVALS - 1 interior points of
  the dense output and at the step end, so two crossings inside one step (or a
  sign change and back) are seen when they fall in different subintervals
  (scipy issue 9228; DifferentialEquations.jl's interpolation points).
* Steps that no guard can cross are not sampled inside. Each guard's rate along the
  flow, dg/dt = g_t + g_y f, is taken at every step end by one forward difference
  (``guard_rates``: one guard call, instead of the three interior samples). A step is
  left unsampled when every guard is armed, on its side by more than gtol at both
  ends, and the cubic Hermite interpolant of its end values and rates (exact for a
  cubic in t) stays on that side: its lowest point on the step (at an end or where
  its derivative vanishes) lies below the nearer end value by at most CLEAR_MARGIN of
  that value (``clear_of_zero``). A double crossing or a dip to zero inside the step
  shows in the end rates (g heads for zero at t_a and comes back from it at t_b), so
  such a step is sampled as before. Most guards pass a cheaper sufficient test first
  (``_dip_bound``: the interpolant's dip is at most 4/27 of the end slopes that point
  to zero); only the others have the interpolant's lowest point computed.
* A guard that is zero at the segment start (|g| <= gtol) is disarmed until it
  has left zero; so a restart on a switching surface does not fire again. If it
  leaves zero to the side its direction leads to (a restart on the surface in
  the wrong mode), that is an event at once.
* Noise band (``band`` on): a sign change counts only if the new value exceeds
  the guard's own integration noise, sum_i |g(y + tol_i e_i) - g(y)| with
  tol_i = atol_i + rtol |y_i| (the guard's change under a state error at the
  tolerance). A guard dithering about zero within the accuracy asked for, as phi
  does when v1 settles at the no-load speed, then reports no switches; a real
  crossing is still located at its root. The band is computed only at samples
  where a sign change was seen.
* The root is located by the Illinois method (modified regula falsi, here with a
  bisection safeguard; also used by SUNDIALS CVODE's rootfinder) to the relative
  time tolerance (4 eps + ttol) max(1, |t|), and the end of the final bracket on
  the far side of the crossing is returned, as CVODE does. The reported event is thus
  never before the crossing, and a restart from it cannot find the same crossing
  again (scipy issue 17066; an absolute tolerance would repeat it).
* A guard that reaches zero exactly at the segment end (where no later sample
  can show whether it crosses) is reported as an event at the end time.

The Illinois iteration is written as pure state-update functions (``bracket_*``)
so that ``segment`` runs the same iteration on the re-taken full-order step.
"""
import math

import numpy as np
from tswm_runtime.jit.arrays import copy_into
from tswm_runtime.jit.cache_guard import njit

GUARD_SUBINTERVALS = 4  # Guard samples per step: 3 interior points + the step end.
RATE_STEP = 1e-6  # The guard rates' difference step, relative to the step size (at least 64 ulp of t).
CLEAR_MARGIN = 0.5  # An unsampled step's predicted dip uses at most half the guards' distance to zero.
ROOT_EPS_FACTOR = 4.0  # Root time tolerance floor: 4 eps, relative to max(1, |t|).
_EPS = np.finfo(np.float64).eps


@njit(error_model="numpy")
def dense_eval(y_a, h, Q, theta, out):
    """out = y_a + h * sum_j Q[:, j] theta^(j+1) (Horner); theta = (t - t_a) / h."""
    for i in range(out.size):
        poly = Q[i, 3]
        for j in range(2, -1, -1):
            poly = poly * theta + Q[i, j]
        out[i] = y_a[i] + h * theta * poly


@njit(error_model="numpy")
def time_tolerance(t, ttol):
    """Width to which event times are located: (4 eps + ttol) * max(1, |t|)."""
    return (ROOT_EPS_FACTOR * _EPS + ttol) * max(1.0, abs(t))


@njit(error_model="numpy")
def arm_guards(g, gtol, sgn):
    """Initial signs at a segment start: 0 (disarmed) for guards within gtol of zero."""
    for k in range(g.size):
        if abs(g[k]) <= gtol:
            sgn[k] = 0
        elif g[k] > 0.0:
            sgn[k] = 1
        else:
            sgn[k] = -1


@njit(error_model="numpy")
def guard_rates(guards, mode, t, y, f, p, g, h, y_tmp, g_tmp, rates):
    """rates = dg/dt along the flow at (t, y) with y' = f and g = g(t, y): one forward
    difference of length RATE_STEP h (at least 64 ulp of t), one guard call."""
    if g.size == 0:
        return
    t_d = t + max(RATE_STEP * h, 64.0 * (np.nextafter(t, np.inf) - t))
    d = t_d - t
    for i in range(y.size):
        y_tmp[i] = y[i] + d * f[i]
    guards(mode, t_d, y_tmp, p, g_tmp)
    for k in range(g.size):
        rates[k] = (g_tmp[k] - g[k]) / d


@njit(error_model="numpy")
def hermite_lowest(s, g_a, g_b, slope_a, slope_b):
    """Lowest value of s H(theta) on [0, 1], H the cubic with H(0) = g_a, H(1) = g_b,
    H'(0) = slope_a, H'(1) = slope_b (slopes per unit theta): its ends and the roots of H'.
    The coefficients are scaled by a power of two near their largest magnitude first (exact),
    so that the discriminant neither underflows for tiny guards nor overflows for huge ones."""
    largest = max(abs(g_a), abs(g_b), abs(slope_a), abs(slope_b))
    if largest > 0.0 and np.isfinite(largest):
        scale = math.ldexp(1.0, -math.frexp(largest)[1])
        return _hermite_lowest_scaled(s, g_a * scale, g_b * scale, slope_a * scale, slope_b * scale) / scale
    return _hermite_lowest_scaled(s, g_a, g_b, slope_a, slope_b)


@njit(error_model="numpy")
def _hermite_lowest_scaled(s, g_a, g_b, slope_a, slope_b):
    a2 = 3.0 * (g_b - g_a) - 2.0 * slope_a - slope_b
    a3 = 2.0 * (g_a - g_b) + slope_a + slope_b
    lowest = min(s * g_a, s * g_b)
    A, B, C = 3.0 * a3, 2.0 * a2, slope_a  # H'(theta) = A theta^2 + B theta + C
    r1, r2 = np.nan, np.nan
    if A == 0.0:
        if B != 0.0:
            r1 = -C / B
    else:
        disc = B * B - 4.0 * A * C
        if disc >= 0.0:
            q = -0.5 * (B + np.copysign(np.sqrt(disc), B))
            r1 = q / A
            if q != 0.0:
                r2 = C / q
    for theta in (r1, r2):
        if 0.0 < theta < 1.0:
            lowest = min(lowest, s * (g_a + theta * (slope_a + theta * (a2 + theta * a3))))
    return lowest


@njit(error_model="numpy")
def _dip_bound(s, slope_a, slope_b):
    """An upper bound of how far s H(theta) dips below the smaller end value on [0, 1] (H as in
    ``hermite_lowest``): with the Hermite basis, H = (1 - w) g_a + w g_b + slope_a theta (1 -
    theta)^2 - slope_b theta^2 (1 - theta), w in [0, 1], and both cubic weights are at most 4/27.
    NaN if a slope is (the caller then takes the full test)."""
    toward = 0.0  # the end slopes' parts that point to zero
    if not s * slope_a >= 0.0:
        toward -= s * slope_a
    if not s * slope_b <= 0.0:
        toward += s * slope_b
    return (4.0 / 27.0) * toward


@njit(error_model="numpy")
def clear_of_zero(g_a, g_b, rate_a, rate_b, h, sgn, gtol):
    """True if no guard can reach zero inside the step [t_a, t_a + h] (module docstring):
    each is armed and beyond gtol on its side at both ends, and the cubic Hermite
    interpolant of its end values and rates dips below the smaller end value by at
    most CLEAR_MARGIN of it."""
    for k in range(g_a.size):
        s = sgn[k]
        distance = min(s * g_a[k], s * g_b[k])
        if s == 0 or not distance > gtol:
            return False
        if _dip_bound(s, h * rate_a[k], h * rate_b[k]) <= CLEAR_MARGIN * distance:
            continue  # the cheap bound suffices: no need for the lowest point itself
        if not hermite_lowest(s, g_a[k], g_b[k], h * rate_a[k], h * rate_b[k]) >= (1.0 - CLEAR_MARGIN) * distance:
            return False
    return True


@njit(error_model="numpy")
def bracket_start(a, fa, b, fb):
    """Illinois state (a, fa, b, fb, side, w1, w2) for a < b, fa pre-, fb post-crossing.

    side: which end moved last (+1 b, -1 a); w1, w2: the widths before the last
    two updates (for the bisection safeguard).
    """
    return (a, fa, b, fb, 0.0, np.inf, np.inf)


@njit(error_model="numpy")
def bracket_done(state, tol):
    """True when b is an exact zero or the bracket is narrower than tol."""
    a, b, fb = state[0], state[2], state[3]
    return fb == 0.0 or b - a <= tol


@njit(error_model="numpy")
def bracket_next(state, tol):
    """Next trial point: regula falsi, or bisection if two updates did not halve the
    bracket; kept tol/2 inside the bracket so every update shrinks it."""
    a, fa, b, fb, w2 = state[0], state[1], state[2], state[3], state[6]
    if b - a > 0.5 * w2:
        c = 0.5 * (a + b)
    else:
        c = b - fb * (b - a) / (fb - fa)
    return min(max(c, a + 0.5 * tol), b - 0.5 * tol)


@njit(error_model="numpy")
def bracket_update(state, c, fc):
    """Replace the end on c's side; halve the kept end's value if it was kept twice
    in a row (the Illinois modification, superlinear convergence). An exact zero
    counts as pre-crossing, so b stays strictly on the far side: a restart from it
    has the guard armed with its new sign and sees the next crossing."""
    a, fa, b, fb, side, w1 = state[0], state[1], state[2], state[3], state[4], state[5]
    width = b - a
    if fc != 0.0 and (fc > 0.0) == (fb > 0.0):
        if side > 0.0:
            fa *= 0.5
        return (a, fa, c, fc, 1.0, width, w1)
    if side < 0.0:
        fb *= 0.5
    return (c, fc, b, fb, -1.0, width, w1)


@njit(error_model="numpy")
def sample_time(t_a, t_b, j):
    """Time of guard sample j = 0..GUARD_SUBINTERVALS (exactly t_a and t_b at the ends)."""
    if j == GUARD_SUBINTERVALS:
        return t_b
    return t_a + (t_b - t_a) * (j / GUARD_SUBINTERVALS)


@njit(error_model="numpy")
def _sign_changes(G, j, directions, gtol, sgn, cand, ignore):
    """Update the guards' last signs with sample j; mark sign changes in an allowed
    direction in cand (their sgn is kept: the pre-crossing sign), and disarmed guards
    leaving zero to their post-event side. Guards in ``ignore`` are skipped. True if any."""
    found = False
    for k in range(G.shape[1]):
        g = G[j, k]
        if abs(g) <= gtol or ignore[k]:
            continue
        s = 1 if g > 0.0 else -1
        if sgn[k] == 0:
            if directions[k] == s:
                cand[k] = True
                found = True
            else:
                sgn[k] = s
        elif s != sgn[k]:
            if directions[k] == 0 or directions[k] == s:
                cand[k] = True
                found = True
            else:
                sgn[k] = s
    return found


@njit(error_model="numpy", refcounted=True)
def _drop_noise(guards, mode, p, t, y, g, atol, rtol, cand, y_tmp, g_tmp):
    """Unmark candidates whose value g[k] at (t, y) lies within the guard's noise band
    (module docstring); their sign stays the pre-crossing one. True if any is left."""
    band = np.zeros(g.size)
    for i in range(y.size):
        copy_into(y_tmp, y)
        y_tmp[i] += atol[i] + rtol * abs(y[i])
        guards(mode, t, y_tmp, p, g_tmp)
        for k in range(g.size):
            band[k] += abs(g_tmp[k] - g[k])
    found = False
    for k in range(g.size):
        if cand[k] and abs(g[k]) <= band[k]:
            cand[k] = False
        found = found or cand[k]
    return found


@njit(error_model="numpy")
def _root_on_dense(guards, mode, p, k, step, G, j, tol, y_tmp, g_tmp):
    """Crossing time of guard k, which has its new sign at sample j of ``step``.

    The bracket starts at the last sample before j that is not yet on the new
    side; if the guard already had the new sign at t_a (it crossed inside the
    zero band in an earlier step), the crossing is reported at t_a.
    """
    post = G[j, k]
    i = j - 1
    while i >= 0 and G[i, k] * post > 0.0:
        i -= 1
    if i < 0:
        return step.t_a
    t_lo, t_hi = sample_time(step.t_a, step.t_b, i), sample_time(step.t_a, step.t_b, i + 1)
    state = bracket_start(t_lo, G[i, k], t_hi, G[i + 1, k])
    while not bracket_done(state, tol):
        c = bracket_next(state, tol)
        dense_eval(step.y_a, step.h, step.Q, (c - step.t_a) / step.h, y_tmp)
        guards(mode, c, y_tmp, p, g_tmp)
        state = bracket_update(state, c, g_tmp[k])
    return state[2]


@njit(error_model="numpy")
def _zero_at_end(G, directions, gtol, sgn, ignore):
    """Lowest armed guard that reached zero at the last sample in an allowed direction."""
    last = G.shape[0] - 1
    for k in range(G.shape[1]):
        arriving = directions[k] == 0 or directions[k] == -sgn[k]
        if sgn[k] != 0 and arriving and abs(G[last, k]) <= gtol and not ignore[k]:
            return k
    return -1


@njit(error_model="numpy")
def _earliest_root(guards, mode, p, step, G, j, ttol, cand, y_tmp, g_tmp):
    """Locate every candidate's crossing before sample j; the earliest wins (ties: lowest k)."""
    tol = time_tolerance(step.t_b, ttol)
    k_best = -1
    t_best = step.t_b
    for k in range(cand.size):
        if cand[k]:
            t_k = _root_on_dense(guards, mode, p, k, step, G, j, tol, y_tmp, g_tmp)
            if k_best < 0 or t_k < t_best:
                k_best = k
                t_best = t_k
    return k_best, t_best, j


@njit(error_model="numpy")
def find_event(guards, mode, p, step, G, ev, tol, sgn, at_end, cand, y_tmp, g_tmp, y_pert,
               j_start, ignore):
    """Earliest event in the accepted ``step`` (structures.Step); returns (k, t_event, j).

    G[0] (guards at t_a) and G[-1] (at t_b, from the step's own y_b) are given; the
    interior rows are filled here from the dense output. ev: the EventSettings
    (directions, gtol, ttol, noise_band: apply the noise band of the module docstring
    with tol's atol, rtol). sgn carries each guard's last sign across steps. k = -1: no
    event. j is the sample at which guard k was seen on its new side (the far end of
    the bracket). at_end: t_b is the segment end, where a guard that reaches zero
    counts as an event. The scan starts at sample j_start and skips the guards in
    ``ignore`` (crossings already found false in this step).
    """
    cand[:] = False
    for j in range(j_start, GUARD_SUBINTERVALS + 1):
        t_j = sample_time(step.t_a, step.t_b, j)
        if j < GUARD_SUBINTERVALS:
            dense_eval(step.y_a, step.h, step.Q, (t_j - step.t_a) / step.h, y_tmp)
            guards(mode, t_j, y_tmp, p, G[j])
        else:
            copy_into(y_tmp, step.y_b)
        if _sign_changes(G, j, ev.directions, ev.gtol, sgn, cand, ignore) and (not ev.noise_band or _drop_noise(
                guards, mode, p, t_j, y_tmp, G[j], tol.atol, tol.rtol, cand, y_pert, g_tmp)):
            return _earliest_root(guards, mode, p, step, G, j, ev.ttol, cand, y_tmp, g_tmp)
    if at_end:
        return _zero_at_end(G, ev.directions, ev.gtol, sgn, ignore), step.t_b, GUARD_SUBINTERVALS
    return -1, step.t_b, GUARD_SUBINTERVALS


@njit(error_model="numpy")
def dense_integral(y_a, h, Q, theta, out):
    """out = integral of the dense output from t_a to t_a + theta h (exact for the polynomial)."""
    for i in range(out.size):
        poly = Q[i, 3] / 5.0
        for j in range(2, -1, -1):
            poly = poly * theta + Q[i, j] / (j + 2.0)
        out[i] = h * theta * (y_a[i] + h * theta * poly)
