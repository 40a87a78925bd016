"""Open stages of a chain (a clearance per stage, backlash) in SymPy: rigid groups, gap kinematics, impact.

A stage whose flanks do not touch transmits nothing: the chain splits there into rigid groups, each a
run of bodies joined by closed stages, with the coordinate and speed of its first body (q_j, v_j).
Within a group the speed factors are the rigid chain's (dynamics.speed_factors). Stage k's normal gap
g_k (0 on flank a, the clearance c_k on flank b) moves with the single-stage gap kinematics
(mechanics.free_flight: g' = v2 cos(gamma) - v1 sin(gamma)) at x1 = r_in_k q_{k-1}, x2 = r_out_k q_k.
Newton per body with each closed stage's forces tied by its FTF Psi_i (as dynamics._solved_in_psi)
gives each group's acceleration and each closed stage's force; a closed stage opens where its normal
force reaches 0 (dynamics.sliding's switching function, with the other groups cut off).

When an open stage's gap closes, the flanks collide: the impulse balance of the two groups, each
reduced to the stage's x1 and x2 (effective masses m1, m2, with the closed stages inside a group tied
by their FTFs), is mechanics.impact_frame's with those masses; its frame, inverse mass W and Routh's
process with Coulomb friction and restitution (tswm_runtime/hybrid/impact.py) apply unchanged.

A group at rest while a stage is open needs no expressions of its own: its statics are the resting chain's over its
own bodies and closed stages (each stage's stick cone from its FTFs Psi_t, Psi_i of forward sliding and its levers,
which the generated module's ``prepare`` derives), the open stage carrying nothing, decided from numbers at run time
(tswm_runtime/chains/rules.py, ``group_holds``); while it sticks the generated open phase holds its acceleration at 0
(latches held_in, held_out).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from derivation import mechanics as mech
from derivation.chain import dynamics as dyn


@dataclass(frozen=True)
class Groups:
    """The rigid groups of a chain of ``stages`` stages with the stages in ``open`` (1-based) open."""

    open: tuple[int, ...]
    first: tuple[int, ...]           # each group's first body: the group moves with its q, v
    of_body: tuple[int, ...]         # the group of each body
    factors: tuple[sp.Expr, ...]     # v_j / v_first for each body j, first the first body of j's group

    def speed(self, group: int) -> sp.Symbol:
        """The speed symbol of a group: v_j of its first body j (v_0 for the first group)."""
        return sp.Symbol(f"v_{self.first[group]}", real=True)

    def accel(self, group: int) -> sp.Symbol:
        return sp.Symbol(f"a_{self.first[group]}", real=True)


def _psi(stages: int) -> tuple[sp.Symbol, ...]:
    """The FTF of every stage as a symbol, Psi_1 .. Psi_N."""
    return tuple(sp.Symbol(f"Psi_{i + 1}", real=True) for i in range(stages))


def _wedge(stage: int) -> dict:
    """mechanics' wedge symbols renamed to stage ``stage`` (1-based)."""
    sym = dyn.symbols(stage)
    return {mech.gamma: sym.gamma[stage - 1], mech.rho: sym.rho[stage - 1]}


def groups(stages: int, open_stages: tuple[int, ...]) -> Groups:
    """Split the chain at its open stages: body k starts a group where stage k is open."""
    sym = dyn.symbols(stages)
    rigid = dyn.speed_factors(sym)       # v_j / v_0 of the rigid chain
    first, of_body, factors = [0], [], []
    for j in range(stages + 1):
        if j in open_stages:
            first.append(j)
        of_body.append(len(first) - 1)
        factors.append(sp.cancel(rigid[j] / rigid[first[-1]]))
    return Groups(tuple(sorted(open_stages)), tuple(first), tuple(of_body), tuple(factors))


@dataclass(frozen=True)
class OpenChain:
    """The motion of the groups while the stages ``groups.open`` are open, every closed stage i tied by an
    unknown FTF Psi_i (its force on its input body is -Psi_i times its force on its output body)."""

    groups: Groups
    psi: tuple[sp.Symbol, ...]                 # Psi_i of every stage (those of open stages unused)
    accel: tuple[sp.Expr, ...]                 # each group's acceleration, in the Psi_i of its closed stages
    stage_force: dict[int, sp.Expr]            # W_i = R2_i: closed stage i's force on its output body (x2)
    gap_rate: dict[int, sp.Expr]               # g_k' of each open stage, in its two groups' speeds
    gap_accel: dict[int, sp.Expr]              # g_k'' of each open stage while it stays open


def _stage_motion(sym: dyn.Symbols, grouping: Groups, i: int, level: str) -> tuple[sp.Expr, sp.Expr]:
    """(x1, x2) speeds (level "v") or accelerations ("a") of stage i (0-based) from its bodies' groups."""
    def of(j: int) -> sp.Expr:
        group = grouping.of_body[j]
        return grouping.factors[j] * (grouping.speed(group) if level == "v" else grouping.accel(group))
    return sym.lever_in[i] * of(i), sym.lever_out[i] * of(i + 1)


def _balance(stages: int, open_stages: tuple[int, ...], external: list[sp.Expr],
             unknown: str) -> tuple[tuple[sp.Expr, ...], dict[int, sp.Expr]]:
    """Newton for every body, M_j (v_j / v_first) u_group = external_j + the closed stages' forces, each
    closed stage i's tied by Psi_i (-Psi_i W_i r_in on its input body, W_i r_out on its output body), solved
    for each group's u (``unknown``: "a" accelerations under forces, "dv" speed jumps under impulses) and
    each closed stage's W_i."""
    sym = dyn.symbols(stages)
    grouping = groups(stages, open_stages)
    psi = _psi(stages)
    W = tuple(sp.Symbol(f"W_{i + 1}", real=True) for i in range(stages))
    closed = [i for i in range(stages) if i + 1 not in open_stages]
    on_body = list(external)
    for i in closed:
        on_body[i] += sym.lever_in[i] * (-psi[i] * W[i])
        on_body[i + 1] += sym.lever_out[i] * W[i]
    u = [sp.Symbol(f"{unknown}_{j}", real=True) for j in grouping.first]
    newton = [sp.Eq(sym.inertia[j] * grouping.factors[j] * u[grouping.of_body[j]], on_body[j])
              for j in range(stages + 1)]
    solved = sp.solve(newton, [*u, *(W[i] for i in closed)], dict=True)[0]
    return tuple(solved[x] for x in u), {i + 1: solved[W[i]] for i in closed}


@lru_cache(maxsize=None)
def open_chain(stages: int, open_stages: tuple[int, ...]) -> OpenChain:
    """Newton for every body, the open stages transmitting nothing, each closed stage's forces tied by Psi_i."""
    sym = dyn.symbols(stages)
    grouping = groups(stages, open_stages)
    accel, force = _balance(stages, open_stages, list(sym.force), "a")
    accels = {grouping.accel(g): a for g, a in enumerate(accel)}
    flight = mech.free_flight()
    rate, gap_accel = {}, {}
    for k in grouping.open:
        at = {mech.gamma: sym.gamma[k - 1]}
        v1, v2 = _stage_motion(sym, grouping, k - 1, "v")
        a1, a2 = _stage_motion(sym, grouping, k - 1, "a")
        rate[k] = flight.normal_speed.subs(at).subs({mech.v1: v1, mech.v2: v2}, simultaneous=True)
        gap_accel[k] = sp.together(flight.normal_speed.subs(at).subs({mech.v1: a1, mech.v2: a2}, simultaneous=True)
                                   .subs(accels))
    return OpenChain(grouping, _psi(stages), accel, force, rate, gap_accel)


def sliding_psi(stage: int, regime: str, direction: int) -> sp.Expr:
    """Stage ``stage``'s (1-based) FTF sliding in ``regime`` with its group moving in ``direction``."""
    return mech.sliding(dyn.flank(regime, direction), direction).psi.subs(_wedge(stage))


def normal_force(chain: OpenChain, stage: int, regime: str, direction: int) -> sp.Expr:
    """N of closed stage ``stage`` from its force on its output body (R2 is N times a factor), with
    every Psi still a symbol: the switching function of the stage's opening is its numerator."""
    mode = mech.sliding(dyn.flank(regime, direction), direction)
    return chain.stage_force[stage] / sp.diff(mode.R2, mech.N).subs(_wedge(stage))


@dataclass(frozen=True)
class Impact:
    """A collision in open stage k on ``flank``: the two groups reduced to the stage's x1 (input side) and x2
    (output side), with the closed stages inside each group tied by their FTFs Psi_i during the impulse."""

    stage: int
    flank: str
    m1: sp.Expr                  # effective mass of the input group at x1 = r_in_k q_{k-1}
    m2: sp.Expr                  # effective mass of the output group at x2 = r_out_k q_k
    W: sp.Matrix                 # inverse mass in the flank frame (normal, tangent): mechanics' with m1, m2
    jumps: tuple[sp.Expr, sp.Expr]   # change of the input and output groups' speeds for the impulse (P_n, P_t)


def _reduced_mass(stages: int, open_stages: tuple[int, ...], body: int, lever: sp.Expr) -> sp.Expr:
    """Effective mass of ``body``'s group at the point x = lever q_body: the speed change there under a
    unit impulse there alone (finite forces do not act during an impulse), the group's closed stages
    tied by Psi_i."""
    grouping = groups(stages, open_stages)
    unit = [lever if j == body else sp.Integer(0) for j in range(stages + 1)]
    jumps, _ = _balance(stages, open_stages, unit, "dv")
    return sp.together(1 / (lever * grouping.factors[body] * jumps[grouping.of_body[body]]))


@lru_cache(maxsize=None)
def impact(stages: int, open_stages: tuple[int, ...], stage: int, flank: str) -> Impact:
    """Open stage ``stage`` (in open_stages) closes on ``flank``: effective masses and the impulse's jumps."""
    sym = dyn.symbols(stages)
    grouping = groups(stages, open_stages)
    k = stage - 1
    m1 = _reduced_mass(stages, open_stages, k, sym.lever_in[k])
    m2 = _reduced_mass(stages, open_stages, stage, sym.lever_out[k])
    frame = mech.impact_frame(flank)
    at = {mech.m1: m1, mech.m2: m2, mech.gamma: sym.gamma[k]}
    jump_in = frame.jump_v1.subs(at) / (sym.lever_in[k] * grouping.factors[k])
    jump_out = frame.jump_v2.subs(at) / (sym.lever_out[k] * grouping.factors[stage])
    return Impact(stage, flank, m1, m2, frame.W.subs(at), (sp.together(jump_in), sp.together(jump_out)))


DIRECTION_IN, DIRECTION_OUT = sp.symbols("direction_in direction_out", real=True)   # the groups' signs of speed


def rho_sign(stage: int) -> sp.Symbol:
    """Stage ``stage``'s (1-based) regime as a sign: +1 tractive, -1 inverse-tractive (its friction angle's sign
    in its FTF: the inverse-tractive FTF is the tractive one with -rho)."""
    return sp.Symbol(f"rho_sign_{stage}", real=True)


@dataclass(frozen=True)
class OpenPhase:
    """Stage ``stage`` open in a chain of ``stages`` stages, each closed stage i sliding in the regime whose sign is
    rho_sign_i with its group moving in direction_in (the group before the open stage) or direction_out (after
    it). Every friction angle rho_i here stands for rho_sign_i rho_i (each stage's FTF is flank a forward's with
    that angle), so one set of expressions serves every regime and direction; each is checked against
    ``normal_force`` and ``sliding_psi`` per regime and direction in tests/test_chain_clearance.py."""

    stages: int
    stage: int
    accel: tuple[sp.Expr, sp.Expr]     # the input and output groups' accelerations (of bodies 0 and ``stage``)
    normal: dict[int, sp.Expr]         # each closed stage's normal force N_i: the switching function of its opening
    jam: sp.Expr                       # the closed stages' jam factors' product cos(gamma_i + rho_i): > 0
    stage_force: dict[int, sp.Expr]    # each closed stage's force on its output body x2 (W_i = R2_i)
    gap: sp.Expr                       # the open stage's normal gap from the coordinates (q_0, q_stage), g = gap_0 at 0
    gap_rate: sp.Expr
    gap_accel: sp.Expr


def signed_psi(stage: int) -> sp.Expr:
    """Flank a forward's FTF of stage ``stage``: with rho_i standing for rho_sign_i rho_i, every regime's."""
    return mech.sliding("a", 1).psi.subs(_wedge(stage))


@lru_cache(maxsize=None)
def open_phase(stages: int, stage: int) -> OpenPhase:
    """The open phase of a chain with one open stage, from ``open_chain``: each closed stage's Psi_i the FTF of
    flank a forward with rho_i for rho_sign_i rho_i, its normal force the stage force over dR2/dN of flank f =
    rho_sign_i direction (mechanics' mirror rule: f times flank a forward's with f s rho = rho_sign_i rho)."""
    chain = open_chain(stages, (stage,))
    grouping = chain.groups
    at_psi = {chain.psi[i - 1]: signed_psi(i) for i in chain.stage_force}
    a_in, a_out = (sp.together(a.subs(at_psi)) for a in chain.accel)
    forward = mech.sliding("a", 1)
    normal, force, jam = {}, {}, sp.Integer(1)
    for i, w in chain.stage_force.items():
        direction = DIRECTION_IN if grouping.of_body[i] == 0 else DIRECTION_OUT
        force[i] = sp.together(w.subs(at_psi))
        per_n = sp.diff(forward.R2, mech.N).subs(_wedge(i))
        normal[i] = sp.together(force[i] / (rho_sign(i) * direction * per_n))
        jam *= forward.jam_factor.subs(_wedge(i))
    q_in, q_out = sp.Symbol("q_0", real=True), sp.Symbol(f"q_{stage}", real=True)
    speeds = {grouping.speed(0): q_in, grouping.speed(1): q_out}
    rate = chain.gap_rate[stage]
    gap = sp.Symbol(f"gap_{stage}", real=True) + rate.subs(speeds, simultaneous=True)
    gap_accel = sp.together(chain.gap_accel[stage].subs(at_psi))
    return OpenPhase(stages, stage, (a_in, a_out), normal, jam, force, gap, rate, gap_accel)


@dataclass(frozen=True)
class OpenImpact:
    """The open stage's flanks meet on ``flank``: the relative velocity in the flank's frame, (nu, s) = (f g', slip),
    the inverse mass W with the groups' effective masses (their closed stages tied by their FTFs in the regimes
    rho_sign_i, as in ``OpenPhase``), the friction coefficient tan(rho_k) and each group's speed change per unit
    impulse (P_n, P_t) on the output side."""

    flank: str
    nu: sp.Expr
    slip: sp.Expr
    W: sp.Matrix
    mu: sp.Expr
    jump_in: tuple[sp.Expr, sp.Expr]     # d v_in / d P_n, d v_in / d P_t
    jump_out: tuple[sp.Expr, sp.Expr]    # d v_out / d P_n, d v_out / d P_t


@lru_cache(maxsize=None)
def open_impact(stages: int, stage: int, flank: str) -> OpenImpact:
    """``impact`` of the one open stage with each closed stage's Psi_i flank a forward's (rho_i for rho_sign_i rho_i),
    and the frame's speeds from ``mechanics.free_flight`` at the stage's x1 and x2."""
    chain = open_chain(stages, (stage,))
    grouping = chain.groups
    sym = dyn.symbols(stages)
    im = impact(stages, (stage,), stage, flank)
    at_psi = {chain.psi[i - 1]: signed_psi(i) for i in chain.stage_force}
    v1, v2 = _stage_motion(sym, grouping, stage - 1, "v")
    flight = mech.free_flight()
    speeds = {mech.v1: v1, mech.v2: v2, mech.gamma: sym.gamma[stage - 1]}
    f = mech.FLANK_SIGN[flank]
    nu = f * flight.normal_speed.subs(speeds, simultaneous=True)
    slip = flight.slip.subs(speeds, simultaneous=True)

    def per_impulse(jump: sp.Expr) -> tuple[sp.Expr, sp.Expr]:
        return tuple(sp.together(sp.diff(jump, p).subs(at_psi)) for p in (mech.Pn, mech.Pt))
    return OpenImpact(flank, nu, slip, im.W.subs(at_psi).applyfunc(sp.together), sp.tan(sym.rho[stage - 1]),
                      per_impulse(im.jumps[0]), per_impulse(im.jumps[1]))
