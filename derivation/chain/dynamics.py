"""A chain of N rigid wedge stages in SymPy: modes, reduced dynamics, reactions, consistency.

Body 0 (the drive) ... body N (the load); stage i joins body i-1 (its input, x1 = lever_in_i q_{i-1})
and body i (its output, x2 = lever_out_i q_i). Every stage reuses mechanics.py: its kinematics
(v2 = tan(gamma) v1), its contact force on each flank and sliding direction (R1, R2 in terms of the
normal force N) and its statics. Without clearance the chain has one coordinate, q_0: the sliding
speed of stage i is v1_i / cos(gamma_i), zero exactly when v_0 is, so either every stage slides
(each tractive or inverse-tractive) or every stage is stuck; a mix is kinematically impossible.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import product

import sympy as sp

from derivation import mechanics as mech

TRACTIVE, INVERSE = "tractive", "inverse-tractive"
REGIMES = (TRACTIVE, INVERSE)
MAX_STAGES = 4                 # 2 * 2^N sliding modes are derived: 32 for four stages
a0, v0 = sp.symbols("a_0 v_0", real=True)


@dataclass(frozen=True)
class Symbols:
    """The chain's symbols: per stage slope, friction angle, levers; per body inertia and force."""

    gamma: tuple[sp.Symbol, ...]
    rho: tuple[sp.Symbol, ...]
    lever_in: tuple[sp.Symbol, ...]
    lever_out: tuple[sp.Symbol, ...]
    inertia: tuple[sp.Symbol, ...]   # N + 1 bodies: mass or moment of inertia
    force: tuple[sp.Symbol, ...]     # generalized force on each body: force or torque


@lru_cache(maxsize=None)
def symbols(stages: int) -> Symbols:
    """Symbols of a chain of ``stages`` stages (indices from 1) and stages + 1 bodies (from 0)."""
    def each(name: str, first: int, count: int, **assumptions) -> tuple[sp.Symbol, ...]:
        return tuple(sp.Symbol(f"{name}_{i}", **assumptions) for i in range(first, first + count))
    return Symbols(each("gamma", 1, stages, positive=True), each("rho", 1, stages, nonnegative=True),
                   each("r_in", 1, stages, positive=True), each("r_out", 1, stages, positive=True),
                   each("M", 0, stages + 1, positive=True), each("F", 0, stages + 1, real=True))


def flank(regime: str, direction: int) -> str:
    """The flank a regime loads: tractive (input pushes output) is f s = +1, inverse-tractive f s = -1."""
    return "a" if (1 if regime == TRACTIVE else -1) * direction == 1 else "b"


def _stage(sym: Symbols, i: int) -> dict:
    """mechanics' wedge symbols renamed to stage i (0-based index)."""
    return {mech.gamma: sym.gamma[i], mech.rho: sym.rho[i]}


def speed_factors(sym: Symbols) -> tuple[sp.Expr, ...]:
    """v_j / v_0 for every body, from each stage's kinematics (v2 = ratio v1)."""
    ratio = mech.kinematics().ratio
    factors = [sp.Integer(1)]
    for i in range(len(sym.gamma)):
        factors.append(factors[-1] * sym.lever_in[i] * ratio.subs(_stage(sym, i)) / sym.lever_out[i])
    return tuple(factors)


@lru_cache(maxsize=None)
def _solved_in_psi(stages: int) -> tuple[dict, tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]]:
    """Newton for every body with each stage's forces tied by an unknown FTF Psi_i (R1_i = -Psi_i R2_i),
    solved once for a_0 and the stage forces W_i = R2_i on the output bodies."""
    sym = symbols(stages)
    psi = tuple(sp.Symbol(f"Psi_{i + 1}", real=True) for i in range(stages))
    W = tuple(sp.Symbol(f"W_{i + 1}", real=True) for i in range(stages))
    c = speed_factors(sym)
    on_body = [sym.force[j] for j in range(stages + 1)]
    for i in range(stages):
        on_body[i] += sym.lever_in[i] * (-psi[i] * W[i])
        on_body[i + 1] += sym.lever_out[i] * W[i]
    newton = [sp.Eq(sym.inertia[j] * c[j] * a0, on_body[j]) for j in range(stages + 1)]
    return sp.solve(newton, [a0, *W], dict=True)[0], psi, W


@dataclass(frozen=True)
class SlidingMode:
    """Every stage slides with sign(v_0) = direction, stage i in regimes[i] on flanks[i]."""

    direction: int
    regimes: tuple[str, ...]
    flanks: tuple[str, ...]
    psi: tuple[sp.Expr, ...]            # each stage's FTF, from mechanics
    accel_in_psi: sp.Expr               # reduced EOM with the FTFs kept as symbols Psi_i
    accel: sp.Expr                      # reduced EOM: a_0 = numerator / D
    denominator: sp.Expr                # D: the reduced inertia on q_0, times a positive factor
    normal: tuple[sp.Expr, ...]         # N_i, each stage's normal contact force: must be >= 0
    switching: tuple[sp.Expr, ...]      # phi_i with N_i = phi_i cos(rho_i) / (D cos(gamma_i + f s rho_i))
    on_input: tuple[sp.Expr, ...]       # generalized force of stage i on body i-1 (lever_in R1)
    on_output: tuple[sp.Expr, ...]      # generalized force of stage i on body i (lever_out R2)
    friction_power: tuple[sp.Expr, ...]  # power stage i absorbs, -(R1 v1 + R2 v2), from the forces
    coulomb_power: tuple[sp.Expr, ...]   # tan(rho) N |v1| / cos(gamma): Coulomb's law directly

    @property
    def name(self) -> str:
        way = "forward" if self.direction == 1 else "backward"
        return f"{way}: " + ", ".join(f"{r} ({f})" for r, f in zip(self.regimes, self.flanks))


@lru_cache(maxsize=None)
def sliding(direction: int, regimes: tuple[str, ...]) -> SlidingMode:
    """Substitute each stage's FTF into the solved chain; recover each stage's normal force."""
    stages = len(regimes)
    sym = symbols(stages)
    solved, psi_sym, W = _solved_in_psi(stages)
    flanks = tuple(flank(r, direction) for r in regimes)
    modes = [mech.sliding(f, direction) for f in flanks]
    psi = tuple(m.psi.subs(_stage(sym, i)) for i, m in enumerate(modes))
    at_psi = dict(zip(psi_sym, psi))
    accel_in_psi = sp.factor(solved[a0])
    denominator = sp.fraction(sp.together(accel_in_psi))[1].subs(at_psi)
    c = speed_factors(sym)
    normal, switching, on_in, on_out, power, coulomb = [], [], [], [], [], []
    for i, m in enumerate(modes):
        ren = _stage(sym, i)
        n_i = sp.together(solved[W[i]].subs(at_psi) / sp.diff(m.R2, mech.N).subs(ren))   # R2 is N times a factor
        r1, r2 = m.R1.subs(ren).subs(mech.N, n_i), m.R2.subs(ren).subs(mech.N, n_i)
        v1 = sym.lever_in[i] * c[i] * v0
        v2 = mech.kinematics().ratio.subs(ren) * v1
        normal.append(n_i)
        jam = sp.expand_trig(m.jam_factor.subs(ren))      # > 0 unless the stage jams
        switching.append(sp.cancel(sp.expand_trig(n_i * denominator * jam / sp.cos(sym.rho[i]))))
        on_in.append(sym.lever_in[i] * r1)
        on_out.append(sym.lever_out[i] * r2)
        power.append(-(r1 * v1 + r2 * v2))
        coulomb.append(m.friction_power_coulomb.subs(ren).subs({mech.N: n_i, mech.v1: v1}))
    return SlidingMode(direction, regimes, flanks, psi, accel_in_psi, sp.together(accel_in_psi.subs(at_psi)),
                       denominator, tuple(normal), tuple(switching), tuple(on_in), tuple(on_out), tuple(power), tuple(coulomb))


def reachable(flanks: tuple[tuple[str, ...], ...], directions: tuple[int, ...] = (1, -1)) -> list[tuple[int, tuple]]:
    """(direction, regimes) of every sliding mode the stages' modelled flanks allow."""
    return [(s, regimes) for s in directions for regimes in product(REGIMES, repeat=len(flanks))
            if all(flank(r, s) in allowed for r, allowed in zip(regimes, flanks))]


@dataclass(frozen=True)
class Stuck:
    """Every stage at rest. Statics give N + 1 equations for 2 N stage forces: the N - 1 internal forces
    X_j (stage j's generalized force on body j) stay free, statically undetermined for N >= 2."""

    internal: tuple[sp.Symbol, ...]     # X_1 .. X_{N-1}
    on_input: tuple[sp.Expr, ...]       # stage i's generalized force on body i-1, in the X_j
    on_output: tuple[sp.Expr, ...]      # stage i's generalized force on body i
    holds: tuple[sp.Expr, ...]          # stage i holds iff holds_i <= 0
    cone_identity: tuple[sp.Expr, ...]  # k_i < 0 with cone_fwd cone_bwd = k_i holds_i (the derivation)


def holding(stage_gamma: sp.Symbol, stage_rho: sp.Symbol) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """The stick cone of mechanics.stick() as one product: (F1 + Psi_t F2)(F1 + Psi_i F2) and the factor
    k with cone_forward * cone_backward = k * product. Both cones are >= 0 exactly when their product
    is (both negative would need tan(rho)|fN| < -|T|), so with k < 0 a stage holds iff product <= 0."""
    st = mech.stick()
    psi_t = mech.sliding("a", 1).psi
    psi_i = mech.sliding("b", 1).psi
    prod = (mech.F1 + psi_t * mech.F2) * (mech.F1 + psi_i * mech.F2)
    cones = sp.tan(mech.rho)**2 * st.normal_times_flank**2 - st.tangential**2
    k = sp.simplify(sp.cancel(sp.expand_trig(cones / prod).rewrite(sp.cos)))
    ren = {mech.gamma: stage_gamma, mech.rho: stage_rho}
    return prod.subs(ren), k.subs(ren), psi_t.subs(ren)


@lru_cache(maxsize=None)
def stuck(stages: int) -> Stuck:
    """Statics of the resting chain: each stage's forces (R1, R2) are unknowns, not tied by an FTF."""
    sym = symbols(stages)
    R1 = sp.symbols(f"R1_1:{stages + 1}", real=True)
    R2 = sp.symbols(f"R2_1:{stages + 1}", real=True)
    X = tuple(sp.Symbol(f"X_{j}", real=True) for j in range(1, stages))
    on_body = [sym.force[j] for j in range(stages + 1)]
    for i in range(stages):
        on_body[i] += sym.lever_in[i] * R1[i]
        on_body[i + 1] += sym.lever_out[i] * R2[i]
    internal = {R2[j]: X[j] / sym.lever_out[j] for j in range(stages - 1)}
    equations = [sp.Eq(e.subs(internal), 0) for e in on_body]
    solved = sp.solve(equations, [*R1, R2[-1]], dict=True)[0]
    r1 = [solved[R1[i]] for i in range(stages)]
    r2 = [internal.get(R2[i], solved.get(R2[i])) for i in range(stages)]
    holds, ks = [], []
    for i in range(stages):
        prod, k, _ = holding(sym.gamma[i], sym.rho[i])
        holds.append(prod.subs({mech.F1: -r1[i], mech.F2: -r2[i]}))   # stick: F1 + R1 = 0 on the stage
        ks.append(k)
    return Stuck(X, tuple(sym.lever_in[i] * r1[i] for i in range(stages)),
                 tuple(sym.lever_out[i] * r2[i] for i in range(stages)), tuple(holds), tuple(ks))
