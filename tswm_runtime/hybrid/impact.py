"""A collision of the flanks: Routh's process with Coulomb friction and energetic restitution.

The relative velocity of body 2 against body 1 in the frame of the struck flank, u = (nu,
s) (nu the normal speed, < 0 while the flanks approach, s the slip along the contact line),
changes by W P under the impulse P = (P_n, P_t) on body 2 (W the inverse mass in that frame,
``mechanics.impact_frame``). The impulse grows with P_n as parameter: while the slip has a
direction sigma, dP_t = -mu sigma dP_n (Coulomb); when the slip stops it stays zero if the
stick impulse ratio |W_nt| / W_tt is inside the cone mu, else it reverses. Compression ends
at nu = 0; restitution then returns e^2 of the normal work done in compression (Stronge's
energetic coefficient). Where the slip keeps one direction throughout, this is exactly
Newton's law nu+ = -e nu-; where it stops inside the impact, Newton's law with a stick
impulse can create energy (the paper gear's masses do: tests/test_impact.py), the energetic
one never does: the normal work is (1 - e^2) times the compression work (<= 0) and friction
work opposes the slip (<= 0).
"""
import math

from numba import njit

OK, JAMMED = 0, 1     # JAMMED: the sliding impulse cannot stop the approach (W_nn - mu W_nt <= 0)
MAX_PHASES = 8        # slide, slip stops, stick or reverse, compression ends, restitution: at most 4


@njit(cache=True, error_model="numpy")
def _phase_end(nu, s, k_nu, k_s, sigma, compressing, remaining):
    """(length in P_n, what ends it: 0 slip stops, 1 compression ends, 2 restitution ends) of a phase."""
    length, end = math.inf, 2
    if sigma != 0 and k_s * sigma < 0.0:
        length, end = -s / k_s, 0
    if compressing:
        d = -nu / k_nu
    else:
        disc = nu * nu + 2.0 * k_nu * remaining
        d = 2.0 * remaining / (nu + math.sqrt(disc)) if disc >= 0.0 and nu + math.sqrt(disc) > 0.0 else (
            -nu / k_nu if k_nu < 0.0 else math.inf)
    if d <= length:
        length, end = d, 1 if compressing else 2
    return max(length, 0.0), end


@njit(cache=True, error_model="numpy")
def collide(nu, s, w_nn, w_nt, w_tt, mu, e):
    """Impulse of a collision: (P_n, P_t, nu after, s after, kinetic energy lost, OK or JAMMED).

    nu < 0 (approach) and s: relative velocity in the flank frame; W = [[w_nn, w_nt], [w_nt,
    w_tt]]; mu = tan(rho) >= 0; e in [0, 1]."""
    if not nu < 0.0:
        return 0.0, 0.0, nu, s, 0.0, OK
    p_n = p_t = work_n = work_t = 0.0
    compressing, target = True, 0.0
    stick_holds = abs(w_nt) <= mu * w_tt
    for _ in range(MAX_PHASES):
        if s != 0.0:
            sigma = 1 if s > 0.0 else -1
        elif stick_holds:
            sigma = 0
        else:
            sigma = 1 if w_nt > 0.0 else -1    # the slip starts where the normal impulse pushes it
        k_t = -w_nt / w_tt if sigma == 0 else -mu * sigma
        k_nu = w_nn + w_nt * k_t
        k_s = 0.0 if sigma == 0 else w_nt + w_tt * k_t
        if compressing and k_nu <= 0.0:
            return p_n, p_t, nu, s, -(work_n + work_t), JAMMED
        d, end = _phase_end(nu, s, k_nu, k_s, sigma, compressing, target - work_n)
        work_n += nu * d + 0.5 * k_nu * d * d
        work_t += k_t * (s * d + 0.5 * k_s * d * d)
        p_n += d
        p_t += k_t * d
        nu += k_nu * d
        s += k_s * d
        if end == 0:
            s = 0.0
        elif end == 1:
            nu, compressing = 0.0, False
            target = (1.0 - e * e) * work_n
            if e == 0.0:
                break
        else:
            break
    return p_n, p_t, nu, s, -(work_n + work_t), OK
