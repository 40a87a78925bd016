"""Which mode a rigid chain of wedge stages is in, decided for all stages at once from numbers.

Shared by the derivation (derivation/chain/selector.py, which evaluates the derived expressions
with SymPy) and the runtime (tswm_runtime/chains/run.py, which evaluates the generated module's
functions at an event): one complementarity logic for both. A sliding candidate is consistent when
each stage's normal force is >= 0 and, from rest, the chain breaks away in the candidate's own
direction; resting is consistent when the statics admit internal forces inside every stage's stick
cone. Exactly one consistent candidate is the answer. None, or several (a Painleve-type ambiguity
of rigid contact with friction, where a reduced inertia D < 0), is reported with the reason, never
resolved by an order of preference.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

Intervals = tuple[tuple[float, float], ...]   # a closed set of the line: sorted, disjoint intervals
EVERYTHING: Intervals = ((-math.inf, math.inf),)
STUCK = "stuck"
SAME = 1e-12                                  # relative: candidates with the same a_0 agree


@dataclass(frozen=True)
class Decision:
    """The outcome ("unique", "none", "several", "critical") and the consistent modes, with the reason."""

    outcome: str
    modes: tuple[str, ...]
    accel: float | None                       # a_0 of the unique (or agreeing) mode
    reason: str
    internal: tuple[Intervals, ...] = ()      # all stuck, N >= 2: the admissible X_1 .. X_{N-1}


@dataclass(frozen=True)
class Candidate:
    """A sliding mode's numbers at one state: its direction, a_0, D and each stage's normal force."""

    name: str
    direction: int
    accel: float
    denominator: float
    normal: tuple[float, ...]


@dataclass(frozen=True)
class Statics:
    """What the resting chain's decision needs: each stage's FTFs of forward sliding (Psi_t, Psi_i),
    its levers, the generalized force on every body and the magnitude of a Coulomb friction on the last
    body (a valve's packing), which at rest takes any value up to it; ``flanks``: each stage with a clearance closed on
    one flank, (its index from 0, +1 flank a or -1 flank b), which pushes its output body on that side only."""

    psi: tuple[tuple[float, float], ...]
    lever_in: tuple[float, ...]
    lever_out: tuple[float, ...]
    force: tuple[float, ...]
    slack: float = 0.0
    flanks: tuple[tuple[int, int], ...] = ()


def decide_numbers(candidates: list[Candidate], velocity: float, statics: Statics) -> Decision:
    """The chain's mode at speed ``velocity`` of body 0 from the candidates in its direction(s)."""
    consistent, rejected = [], []
    for c in candidates:
        why = [f"stage {i + 1} would need N_{i + 1} = {n:.6g} N < 0" for i, n in enumerate(c.normal) if n < 0]
        if velocity == 0 and not c.direction * c.accel > 0:
            why.append(f"it would not leave rest in its direction (a_0 = {c.accel:.6g})")
        if why:
            rejected.append(f"{c.name}: {'; '.join(why)} (D = {c.denominator:.6g})")
        else:
            consistent.append((c.name, c.accel, c.denominator))
    internal: tuple[Intervals, ...] = ()
    if velocity == 0:
        internal, why_not = rest(statics)
        if why_not:
            rejected.append(f"{STUCK}: {why_not}")
        else:
            consistent.append((STUCK, 0.0, math.nan))
    return _verdict(consistent, rejected, internal, len(statics.psi))


def _verdict(consistent: list, rejected: list, internal: tuple[Intervals, ...], stages: int) -> Decision:
    names = tuple(name for name, _, _ in consistent)
    if not consistent:
        return Decision("none", (), None, "no mode is consistent (a Painleve-type inconsistency: rigid "
                        "contact with friction has no solution here): " + " | ".join(rejected))
    if len(consistent) == 1:
        name, accel, _ = consistent[0]
        reason = f"the only consistent mode; rejected: {' | '.join(rejected) or 'none'}"
        if name == STUCK and stages > 1:
            reason = f"all stuck: {internal_forces(internal)}; {reason}"
        return Decision("unique", names, accel, reason, internal if name == STUCK else ())
    accels = [a for _, a, _ in consistent]
    if STUCK not in names and max(accels) - min(accels) <= SAME * max(1.0, *map(abs, accels)):
        return Decision("critical", names, accels[0], "several modes are consistent and give the same a_0: "
                        "the stages where they differ carry no contact force (a kink, not an ambiguity)")
    negative = [f"{n} (D = {d:.6g})" for n, _, d in consistent if d < 0]
    if STUCK in names and not negative:
        return Decision("several", names, None, "several modes are consistent: resting with internal forces "
                        + admissible(internal) + " and breaking away as " + ", ".join(n for n in names if n != STUCK)
                        + ("; the rigid chain does not decide" if all(map(determined, internal)) else
                           "; the internal force split is statically undetermined, so the rigid chain does not "
                           "decide (the prestress its stages' compliance holds does)"), internal)
    return Decision("several", names, None, "several modes are consistent (a Painleve-type ambiguity: "
                    f"rigid contact with friction does not decide); reduced inertia D < 0 in: "
                    f"{', '.join(negative) or 'none'}; consistent: {', '.join(names)}", internal)


def rest(statics: Statics) -> tuple[tuple[Intervals, ...], str]:
    """Admissible internal forces X_j of the resting chain, or why none exist.

    Each stage holds while (p + Psi_t q)(p + Psi_i q) <= 0 for p, q its forces over its levers: for a
    given p, q lies in p T with a fixed set T (and for a given q, p in q [-Psi_t, -Psi_i]), so the
    X_j each side of a body allows are propagated stage by stage from both ends and intersected. The last
    body's friction widens what the last stage must exert on it to [-F_N - slack, -F_N + slack]."""
    psi, lever_in, lever_out, force = statics.psi, statics.lever_in, statics.lever_out, statics.force
    load: Intervals = ((-force[-1] - statics.slack, -force[-1] + statics.slack),)
    stages = len(psi)

    def one_side(xs: Intervals, i: int) -> Intervals:   # what stage i exerts on its output body, on its flank's side
        side = dict(statics.flanks).get(i)
        if side is None:
            return xs
        return _intersect(xs, ((0.0, math.inf),) if side > 0 else ((-math.inf, 0.0),))
    forward: list[Intervals] = []
    p_set: Intervals = ((-force[0] / lever_in[0],) * 2,)
    for i in range(stages):
        q_set = _scaled(p_set, _forward_cone(*psi[i]))
        w_set = one_side(_affine(q_set, 0.0, lever_out[i]), i)
        if i == stages - 1:
            if not _intersect(w_set, load):
                return (), (f"holding body {stages}'s load needs stage {stages} to exert {show(load)} on it, "
                            f"outside what the stages can hold against the other forces: {show(w_set)}")
            break
        forward.append(w_set)
        # body i + 1: stage i + 2 pushes it with -F_{i+1} - X_{i+1}; its lever turns that into p
        p_set = _affine(w_set, -force[i + 1] / lever_in[i + 1], -1.0 / lever_in[i + 1])
    backward: list[Intervals] = [()] * (stages - 1)
    q_set = _affine(one_side(load, stages - 1), 0.0, 1.0 / lever_out[-1])
    for i in range(stages - 1, 0, -1):
        p_set = _scaled(q_set, _backward_cone(*psi[i]))
        u_set = _affine(p_set, 0.0, lever_in[i])
        backward[i - 1] = _affine(u_set, -force[i], -1.0)      # X_i = -F_i - u_{i+1}
        q_set = _affine(one_side(backward[i - 1], i - 1), 0.0, 1.0 / lever_out[i - 1])
    internal = tuple(_intersect(f, b) for f, b in zip(forward, backward))
    return internal, ""


def _forward_cone(psi_t: float, psi_i: float) -> Intervals:
    """T = {t : (1 + Psi_t t)(1 + Psi_i t) <= 0}; Psi_t > 0 (no jam); Psi_i <= 0 self-locks: T unbounded."""
    if psi_i > 0:
        return ((-1 / psi_i, -1 / psi_t),)
    if psi_i == 0:
        return ((-math.inf, -1 / psi_t),)
    return ((-math.inf, -1 / psi_t), (-1 / psi_i, math.inf))


def _backward_cone(psi_t: float, psi_i: float) -> Intervals:
    return ((-psi_t, -psi_i),)


def _mul(x: float, t: float) -> float:
    return 0.0 if x == 0 or t == 0 else x * t


def _scaled(xs: Intervals, ts: Intervals) -> Intervals:
    """The union of x T over x in xs."""
    unbounded = any(math.isinf(lo) or math.isinf(hi) for lo, hi in ts)
    out = []
    for lo, hi in xs:
        if lo <= 0 <= hi and unbounded:
            return EVERYTHING
        for part in ((lo, min(hi, 0.0)), (max(lo, 0.0), hi)):
            if part[0] > part[1]:
                continue
            for t_lo, t_hi in ts:
                corners = [_mul(x, t) for x in part for t in (t_lo, t_hi)]
                out.append((min(corners), max(corners)))
    return _merged(out)


def _affine(xs: Intervals, offset: float, scale: float) -> Intervals:
    """{offset + scale x : x in xs}."""
    return _merged([tuple(sorted((offset + _mul(scale, lo), offset + _mul(scale, hi)))) for lo, hi in xs])


def _intersect(a: Intervals, b: Intervals) -> Intervals:
    return _merged([(max(p, r), min(q, s)) for p, q in a for r, s in b if max(p, r) <= min(q, s)])


def _merged(parts: list) -> Intervals:
    out: list[list[float]] = []
    for lo, hi in sorted(parts):
        if out and lo <= out[-1][1]:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return tuple((lo, hi) for lo, hi in out)


def show(intervals: Intervals) -> str:
    return " u ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in intervals) or "the empty set"


def determined(intervals: Intervals) -> bool:
    """The set is one point: the statics fix that internal force."""
    return len(intervals) == 1 and intervals[0][0] == intervals[0][1]


def admissible(internal: tuple[Intervals, ...]) -> str:
    """"X_1 = 0, X_2 in [a, b]": a point as its value, a wider set as its intervals."""
    return ", ".join(f"X_{j + 1} = {xs[0][0]:.6g}" if determined(xs) else f"X_{j + 1} in {show(xs)}"
                     for j, xs in enumerate(internal))


def internal_forces(internal: tuple[Intervals, ...]) -> str:
    """What the statics say of a resting chain's internal forces, true also when they fix them."""
    if all(determined(xs) for xs in internal):
        return f"the statics determine the internal forces: {admissible(internal)}"
    return f"internal force split statically undetermined; admissible {admissible(internal)}"
