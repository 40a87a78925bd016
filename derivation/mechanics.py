"""First-principles kinetostatics of the wedge: geometry, contact force, force balance.

Everything here is scene-independent and symbolic. Body 1 moves along x1, body 2 along
x2 (perpendicular guides). Flank ``f`` (+1 for flank a, where body 1 pushes body 2; -1
for flank b, where body 2 pushes body 1) is a line at the slope ``gamma`` to x1. Sliding
runs in the direction ``s = sign(v1)``. Each step below is a SymPy computation; nothing
downstream of the geometry and Coulomb's law is typed in.

The steps use targeted operations only, never SymPy's general ``simplify``: linear systems by
LU decomposition, rational functions by cancel/factor, sin^2 + cos^2 = 1 where a balance needs
it (``on_circle``), angle sums by Fu's trigsimp on two short sums. Flank a sliding forward is
derived once; the other flanks and directions are its mirror images (``_mirror``). Each
derivation is cached per process, so a scene's model takes well under a second of SymPy.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

FLANK_SIGN = {"a": 1, "b": -1}

t = sp.Symbol("t", real=True)
m1, m2 = sp.symbols("m1 m2", positive=True)
gamma = sp.Symbol("gamma", positive=True)
rho = sp.Symbol("rho", nonnegative=True)
F1, F2 = sp.symbols("F1 F2", real=True)
x1, v1, a1 = sp.symbols("x1 v1 a1", real=True)
x2, v2, a2 = sp.symbols("x2 v2 a2", real=True)
Q = sp.Symbol("Q", nonnegative=True)          # magnitude of the contact resultant
N = sp.Symbol("N", real=True)                 # normal contact force (>= 0 when valid)
T = sp.Symbol("T", real=True)                 # tangential contact force in stick
fN = sp.Symbol("fN", real=True)               # normal contact force times the flank sign: along n on body 2
Psi = sp.Symbol("Psi", real=True)             # force transfer function, as an unknown
S1, S2 = sp.symbols("S1 S2", real=True)
phi = sp.Symbol("phi", real=True)             # switching function, as an unknown

E1 = sp.Matrix([1, 0])                        # direction of x1
E2 = sp.Matrix([0, 1])                        # direction of x2
TANGENT = sp.Matrix([-sp.cos(gamma), sp.sin(gamma)])   # contact line, seen from body 1
NORMAL = sp.Matrix([sp.sin(gamma), sp.cos(gamma)])     # flank a normal, body 1 -> body 2

@dataclass(frozen=True)
class Kinematics:
    """Constraint of one flank on position, velocity and acceleration level."""

    gap: sp.Expr                 # signed distance along the flank normal
    position: sp.Eq
    velocity: sp.Eq
    acceleration: sp.Eq
    x2_of_x1: sp.Expr            # solved position constraint
    ratio: sp.Expr               # v2 / v1
    sliding_speed: sp.Expr       # relative speed along the contact line, per unit v1


@dataclass(frozen=True)
class SlidingMode:
    """Force balance of one flank sliding in one direction, solved."""

    flank: str
    direction: int
    R1: sp.Expr                  # contact force on body 1 along x1 (in terms of N)
    R2: sp.Expr                  # contact force on body 2 along x2
    psi: sp.Expr                 # FTF: S1 = -psi S2
    accel_in_psi: sp.Expr        # reduced EOM with psi kept as a symbol
    accel: sp.Expr               # reduced EOM
    accel_direct: sp.Expr        # the same, solved directly for (a1, N) without the FTF
    denominator: sp.Expr         # D = m1 + psi m2 tan(gamma)
    S1: sp.Expr
    S2: sp.Expr
    switching: sp.Expr           # phi, with S2 = -m1 m2 phi / D
    normal: sp.Expr              # N in terms of phi
    jam_factor: sp.Expr          # cos(gamma + f s rho): must stay > 0
    friction_power: sp.Expr      # power the contact absorbs, from the force balance
    friction_power_coulomb: sp.Expr   # tan(rho) N |v1| / cos(gamma), Coulomb's law directly
    efficiency: sp.Expr          # power delivered to body 2 / power taken from body 1


@dataclass(frozen=True)
class Stick:
    """Statics at v1 = 0: the contact force that holds both bodies at rest."""

    normal_times_flank: sp.Expr  # f N: positive on flank a, negative on flank b
    tangential: sp.Expr          # T: friction force the stick needs (along the line)
    cone_forward: sp.Expr        # tan(rho) |f N| - T >= 0: no breakaway forward
    cone_backward: sp.Expr       # tan(rho) |f N| + T >= 0: no breakaway backward


def _contact_forces(force_on_body2: sp.Matrix) -> tuple[sp.Expr, sp.Expr]:
    """Components along each body's guide: R1 on body 1 (reaction), R2 on body 2."""
    return (-force_on_body2).dot(E1), force_on_body2.dot(E2)


def _resultant(f: int, s: int) -> sp.Matrix:
    """Coulomb: the contact resultant Q on flank f leans by rho from the normal, against body 2's
    sliding with sign(v1) = s (a force, or an impulse in a collision)."""
    return Q * (f * sp.cos(rho) * NORMAL - s * sp.sin(rho) * TANGENT)


@lru_cache(maxsize=None)
def _leaning() -> tuple[sp.Expr, sp.Expr]:
    """R1, R2 of flank a sliding forward with the angle sums found (Fu's trigsimp on two short sums):
    the resultant leans by rho from the normal, -Q sin(gamma + rho) on x1 and Q cos(gamma + rho) on x2."""
    return tuple(Q * sp.fu(r / Q) for r in _contact_forces(_resultant(1, 1)))


def _linear(equations: list, unknowns: list) -> dict:
    """The solution of linear equations (LU decomposition, no simplification)."""
    A, b = sp.linear_eq_to_matrix(equations, unknowns)
    return dict(zip(unknowns, A.LUsolve(b)))


_SIN, _COS = sp.symbols("sin_gamma cos_gamma", real=True)


def on_circle(expr: sp.Expr) -> sp.Expr:
    """A rational expression in sin(gamma), cos(gamma) (tan(gamma) too) over one fraction, numerator and
    denominator each in its shortest form of: as it is, cos^2 or sin^2 eliminated by sin^2 + cos^2 = 1;
    factored. This is the one trigonometric identity the wedge's balances need (no general simplify)."""
    plain = expr.subs(sp.tan(gamma), sp.sin(gamma) / sp.cos(gamma)).subs({sp.sin(gamma): _SIN, sp.cos(gamma): _COS})
    unit = _SIN**2 + _COS**2 - 1

    def shortest(poly: sp.Expr) -> sp.Expr:
        return sp.factor(min((poly, sp.rem(poly, unit, _COS), sp.rem(poly, unit, _SIN)), key=sp.count_ops))

    num, den = sp.fraction(sp.cancel(plain))
    return (shortest(num) / shortest(den)).subs({_SIN: sp.sin(gamma), _COS: sp.cos(gamma)})


@lru_cache(maxsize=None)
def kinematics() -> Kinematics:
    """Non-penetration of the flank, differentiated twice."""
    X1, X2 = sp.Function("x1")(t), sp.Function("x2")(t)
    gap = (X2 * E2 - X1 * E1).dot(NORMAL)
    plain = {X1.diff(t, 2): a1, X2.diff(t, 2): a2, X1.diff(t): v1, X2.diff(t): v2, X1: x1, X2: x2}
    as_tan = {sp.sin(gamma): sp.tan(gamma) * sp.cos(gamma)}
    level = [sp.Eq(sp.expand((gap.diff(t, k) / sp.cos(gamma)).subs(as_tan)).subs(plain), 0) for k in range(3)]
    x2_sol = _linear([level[0]], [x2])[x2]
    ratio = sp.cancel(_linear([level[1]], [v2])[v2] / v1)
    slide = on_circle((v2 * E2 - v1 * E1).dot(TANGENT).subs(v2, ratio * v1) / v1)
    return Kinematics(gap.subs({X1: x1, X2: x2}), *level, x2_sol, ratio, slide)


def _mirror(mode: SlidingMode, flank: str, direction: int) -> SlidingMode:
    """Flank ``flank`` sliding in ``direction`` from flank a sliding forward: the resultant on flank f
    with sign(v1) = s is f times flank a's forward one with f s rho for rho (_resultant), so each force
    (R1, R2, N) is f times, and each ratio of forces (psi, a1, S1, S2, D) equal to, flank a's with
    f s rho for rho; the power, a force times v1 = s |v1|, is f s times flank a's."""
    f, s = FLANK_SIGN[flank], direction
    lean = {rho: f * s * rho}
    force, ratio = (lambda e: f * e.subs(lean)), (lambda e: e.subs(lean))
    return SlidingMode(
        flank=flank, direction=direction, R1=force(mode.R1), R2=force(mode.R2), psi=ratio(mode.psi),
        accel_in_psi=mode.accel_in_psi, accel=ratio(mode.accel), accel_direct=ratio(mode.accel_direct),
        denominator=ratio(mode.denominator), S1=ratio(mode.S1), S2=ratio(mode.S2), switching=mode.switching,
        normal=force(mode.normal), jam_factor=ratio(mode.jam_factor), friction_power=f * s * ratio(mode.friction_power),
        friction_power_coulomb=mode.friction_power_coulomb, efficiency=ratio(mode.efficiency))


@lru_cache(maxsize=None)
def sliding(flank: str, direction: int) -> SlidingMode:
    """Solve the force balance of ``flank`` sliding with sign(v1) = ``direction`` (flank a forward;
    the others are its mirror images, _mirror)."""
    if (flank, direction) != ("a", 1):
        return _mirror(sliding("a", 1), flank, direction)
    kin = kinematics()
    R1, R2 = _contact_forces(_resultant(1, 1))
    lean_1, lean_2 = (r / Q for r in _leaning())       # -sin(gamma + rho), cos(gamma + rho)
    psi = sp.fu(-lean_1 / lean_2)
    # Newton for each body, reactions S_i = F_i - m_i a_i = -R_i, constraint a2 = ratio a1.
    eom = [sp.Eq(S1, F1 - m1 * a1), sp.Eq(S2, F2 - m2 * kin.ratio * a1), sp.Eq(S1, -Psi * S2)]
    sol = _linear(eom, [a1, S1, S2])
    accel_in_psi = sp.factor(sol[a1])
    accel = accel_in_psi.subs(Psi, psi)
    denominator = sp.fraction(sp.together(accel_in_psi))[1]
    direct = _linear([sp.Eq(m1 * a1, F1 + R1), sp.Eq(m2 * kin.ratio * a1, F2 + R2)], [a1, Q])
    switching = sp.expand(sp.cancel(-sol[S2] * denominator / (m1 * m2)))
    normal = (-S2 / lean_2 * sp.cos(rho)).subs(S2, -m1 * m2 * phi / denominator.subs(Psi, psi))
    power = -(lean_1 + lean_2 * kin.ratio) * v1 * N / sp.cos(rho)
    return SlidingMode(
        flank="a", direction=1, R1=R1.subs(Q, N / sp.cos(rho)), R2=R2.subs(Q, N / sp.cos(rho)),
        psi=psi, accel_in_psi=accel_in_psi, accel=accel, accel_direct=direct[a1],
        denominator=denominator.subs(Psi, psi), S1=sp.factor_terms(sp.cancel(sol[S1])).subs(Psi, psi),
        S2=sp.factor_terms(sp.cancel(sol[S2])).subs(Psi, psi), switching=switching, normal=normal,
        jam_factor=lean_2, friction_power=power.subs(v1, sp.Abs(v1)),
        friction_power_coulomb=sp.tan(rho) * N * sp.Abs(v1) * kin.sliding_speed,
        efficiency=(-S2 * kin.ratio / S1).subs(S1, -psi * S2),
    )


@lru_cache(maxsize=None)
def stick() -> Stick:
    """Both bodies at rest: solve the statics for the normal and tangential force."""
    R1, R2 = _contact_forces(fN * NORMAL - T * TANGENT)
    sol = _linear([sp.Eq(F1 + R1, 0), sp.Eq(F2 + R2, 0)], [fN, T])
    fn, tang = on_circle(sol[fN]), on_circle(sol[T])
    cone = sp.tan(rho) * sp.Abs(fn)
    return Stick(fn, tang, cone - tang, cone + tang)


# Clearance between the flanks (backlash): the relative motion along the flank normal is free.
gap, gap_rate = sp.symbols("gap gap_rate", real=True)   # normal gap from flank a, and its rate
Pn, Pt = sp.symbols("P_n P_t", real=True)               # impulse on body 2: normal (into it), tangential
e_r = sp.Symbol("e", nonnegative=True)                 # Newton's coefficient of restitution
nu, slip_speed = sp.symbols("nu s", real=True)          # impact frame: f gap_rate and the slip


@dataclass(frozen=True)
class FreeFlight:
    """Neither flank touches: each body moves under its own force (the "own accelerations")."""

    accel1: sp.Expr              # a1 = F1 / m1
    accel2: sp.Expr              # a2 = F2 / m2
    normal_speed: sp.Expr        # d gap/dt in terms of v1, v2
    slip: sp.Expr                # relative speed of body 2 along the contact line, in v1, v2
    slip_of: sp.Expr             # the same in v1 and gap_rate
    v2_of: sp.Expr               # v2 in terms of v1 and gap_rate
    x2_of: sp.Expr               # x2 in terms of x1 and gap
    gap_accel: sp.Expr           # d gap_rate/dt in free flight
    gap_accel_phi: sp.Expr       # the same, in terms of the switching function phi


@dataclass(frozen=True)
class ImpactFrame:
    """A collision on flank f, in the flank's normal/tangent frame (u = (f gap_rate, slip)).

    The impulse P = (P_n, P_t) acts on body 2 along f n and t (and -P on body 1); the guides
    take the rest. The relative velocity jumps by W P, W the inverse mass in that frame."""

    flank: str
    W: sp.Matrix                 # [[W_nn, W_nt], [W_nt, W_tt]]
    jump_v1: sp.Expr             # change of v1 for the impulse (P_n, P_t)
    jump_v2: sp.Expr             # change of v2
    v1_of: sp.Expr               # v1 from (gap_rate, slip): the inverse of the frame map
    energy_in_frame: sp.Expr     # m1 v1^2/2 + m2 v2^2/2 in terms of (f gap_rate, slip)
    newton_stick_loss: sp.Expr   # energy lost by Newton's law ending in stick: can be < 0


@lru_cache(maxsize=None)
def free_flight() -> FreeFlight:
    """Newton for each body without contact force, and the normal gap's motion."""
    kin = kinematics()
    sol = _linear([sp.Eq(m1 * a1, F1), sp.Eq(m2 * a2, F2)], [a1, a2])
    X1, X2 = sp.Function("x1")(t), sp.Function("x2")(t)
    gap_t = (X2 * E2 - X1 * E1).dot(NORMAL)
    plain = {X1.diff(t, 2): a1, X2.diff(t, 2): a2, X1.diff(t): v1, X2.diff(t): v2}
    normal_speed = gap_t.diff(t).subs(plain)
    slip = (v2 * E2 - v1 * E1).dot(TANGENT)
    accel = gap_t.diff(t, 2).subs(plain).subs(sol)
    phi_expr = sliding("a", 1).switching
    gap_accel_phi = on_circle(accel / phi_expr) * phi
    v2_of = sp.together(_linear([sp.Eq(gap_rate, normal_speed)], [v2])[v2])
    x2_of = sp.together(_linear([sp.Eq(gap, kin.gap)], [x2])[x2])
    return FreeFlight(sol[a1], sol[a2], normal_speed, slip, on_circle(slip.subs(v2, v2_of)), v2_of, x2_of,
                      accel, gap_accel_phi)


@lru_cache(maxsize=None)
def impact_frame(flank: str) -> ImpactFrame:
    """Impulse balance of a collision on ``flank``: velocity jumps, inverse mass, energy."""
    f = FLANK_SIGN[flank]
    ff = free_flight()
    impulse = Pn * f * NORMAL + Pt * TANGENT            # on body 2
    R1, R2 = _contact_forces(impulse)                    # along the guides
    jump_v1, jump_v2 = sp.cancel(R1 / m1), sp.cancel(R2 / m2)
    u = sp.Matrix([f * ff.normal_speed, ff.slip])
    du = u.subs({v1: v1 + jump_v1, v2: v2 + jump_v2}) - u
    W = du.jacobian([Pn, Pt]).applyfunc(sp.factor)
    s = slip_speed
    frame = {k: on_circle(v) for k, v in _linear([sp.Eq(nu, u[0]), sp.Eq(s, u[1])], [v1, v2]).items()}
    kinetic = m1 * v1**2 / 2 + m2 * v2**2 / 2
    in_frame = kinetic.subs(frame)
    # Newton's law with a stick ending: (nu, s) -> (-e nu, 0). The energy it loses:
    newton_stick = in_frame - in_frame.subs({nu: -e_r * nu, s: 0})
    v1_of = frame[v1].subs(nu, f * gap_rate)
    return ImpactFrame(flank, W, jump_v1, jump_v2, v1_of, in_frame, newton_stick)


# Mesh compliance: the flanks may overlap; the overlap pushes them apart like a spring and damper.
k_mesh, c_mesh = sp.symbols("k_mesh c_mesh", nonnegative=True)   # stiffness, damping along the normal
clearance = sp.Symbol("clearance", nonnegative=True)


@dataclass(frozen=True)
class MeshContact:
    """A compliant flank contact: N = k overlap + c d(overlap)/dt, Coulomb friction against the
    slip (direction +-1), or stick (direction 0: the slip stays 0, T from the balance)."""

    flank: str
    direction: int
    normal: sp.Expr              # N = k overlap + c overlap' in terms of the states
    tangential: sp.Expr          # T, force on body 2 along t (stick: from the balance; slide: -s mu N)
    accel1: sp.Expr
    accel2: sp.Expr
    gap_accel: sp.Expr
    S1: sp.Expr                  # F1 - m1 a1
    S2: sp.Expr                  # F2 - m2 a2
    cone_forward: sp.Expr        # stick: mu N + T >= 0 while no slip forward
    cone_backward: sp.Expr       # stick: mu N - T >= 0 while no slip backward


@lru_cache(maxsize=None)
def _compliant_balance() -> tuple[tuple[sp.Expr, ...], tuple[sp.Expr, ...], sp.Expr]:
    """Newton for both bodies under a contact force fN n + T t on body 2 (and its opposite on body 1):
    (a1, a2, gap_accel, S1, S2) in fN and T; the same in stick, where T keeps the slip's rate 0; that T."""
    R1, R2 = _contact_forces(fN * NORMAL + T * TANGENT)
    acc = {a1: (F1 + R1) / m1, a2: (F2 + R2) / m2}
    ff = free_flight()
    forms = (acc[a1], acc[a2], ff.normal_speed.subs({v1: a1, v2: a2}).subs(acc), F1 - m1 * acc[a1], F2 - m2 * acc[a2])
    held = on_circle(_linear([ff.slip.subs({v1: a1, v2: a2}).subs(acc)], [T])[T])
    return forms, tuple(on_circle(e.subs(T, held)) for e in forms), held


def _in_normal(expr: sp.Expr) -> sp.Expr:
    """``expr`` over one denominator, its numerator's terms in N collected (N times its factored coefficient)."""
    num, den = sp.fraction(sp.together(expr))
    return sp.collect(sp.expand(num), N, sp.factor) / den


@lru_cache(maxsize=None)
def mesh_contact(flank: str, direction: int) -> MeshContact:
    """Newton for both bodies under a spring-damper normal force and Coulomb friction."""
    f = FLANK_SIGN[flank]
    overlap = -gap if f == 1 else gap - clearance
    normal = k_mesh * overlap + c_mesh * sp.diff(overlap, gap) * gap_rate
    mu = sp.tan(rho)
    forms, held_forms, held = _compliant_balance()
    if direction == 0:
        tangential = held.subs(fN, f * normal)
        a1_, a2_, gap_accel, s1, s2 = (e.subs(fN, f * normal) for e in held_forms)
    else:
        tangential = -direction * mu * normal
        a1_, a2_, gap_accel, s1, s2 = (_in_normal(e.subs({fN: f * N, T: -direction * mu * N})).subs(N, normal)
                                       for e in forms)
    return MeshContact(flank, direction, normal, tangential, a1_, a2_, gap_accel, s1, s2,
                       mu * normal + tangential, mu * normal - tangential)


# Lost motion: a stem (body 3) on body 2's guide, which body 2 picks up after a free travel.
m3 = sp.Symbol("m3", positive=True)
F3 = sp.Symbol("F3", real=True)               # the load, acting on the stem
P = sp.Symbol("P", positive=True)             # pickup impulse: +P on the stem, -P on body 2, along x2
N3 = sp.Symbol("N3", real=True)               # contact force of body 2 on the stem (>= 0)
x3, v3 = sp.symbols("x3 v3", real=True)      # the stem's travel from its rest position, its speed


@dataclass(frozen=True)
class Pickup:
    """Body 2, held by the wedge on flank a, strikes the stem: an impulse P along x2 (the stem's
    contact is frictionless). The wedge passes the impulse on like a force: the same balance."""

    jump_v1: dict[int, sp.Expr]  # dv1/dP while the wedge slides with sign(v1) = s
    flank_impulse: dict[int, sp.Expr]  # the resultant impulse on flank a per unit P (> 0: flank a carries it)
    cone_forward: sp.Expr        # the wedge sticks under the impulse alone where both cones are >= 0
    cone_backward: sp.Expr       # (per unit P, from the statics with F1 = 0, F2 = -P)
    inertia: sp.Expr             # J in m1 v1^2/2 + m2 v2^2/2 = J v1^2/2
    stem_force: sp.Expr          # N3 while the stem moves with body 2, in S2 and F3


@lru_cache(maxsize=None)
def pickup() -> Pickup:
    """Impulse balance of the pickup on each sliding direction, the stick test, and the stem's
    contact force while it is carried (Newton for the stem, S2 with m2 + m3 and F2 = F3)."""
    kin = kinematics()
    dv1 = sp.Symbol("dv1", real=True)
    jumps, impulses = {}, {}
    for s in (1, -1):
        R1, R2 = (r.subs(rho, s * rho) for r in _leaning())     # flank a, sign(v1) = s: _mirror's rule
        sol = _linear([sp.Eq(m1 * dv1, R1), sp.Eq(m2 * kin.ratio * dv1, -P + R2)], [dv1, Q])
        jumps[s], impulses[s] = sp.factor(sol[dv1] / P), sp.factor(sol[Q] / P)
    unit = {F1: 0, F2: -1}
    st = stick()
    a2_ = sp.Symbol("a2_", real=True)
    carried = _linear([sp.Eq(m3 * a2_, F3 + N3), sp.Eq(S2, F3 - (m2 + m3) * a2_)], [N3, a2_])
    inertia = sp.expand(2 * (m1 * v1**2 / 2 + m2 * (kin.ratio * v1)**2 / 2) / v1**2)
    return Pickup(jumps, impulses, st.cone_forward.subs(unit), st.cone_backward.subs(unit), inertia,
                  sp.factor(carried[N3]))
