"""The model IR: a scene's modes, laws, states and parameters as plain data.

``build_model(scene)`` specialises the scene-independent mechanics to one scene: it picks
the modes the scene declares, substitutes the scene's slope and friction symbols, and
attaches the drive, load and friction laws. Code generation and the LaTeX writer both
read this object, so the document and the code cannot drift apart.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import sympy as sp

from derivation import laws, mechanics, paper
from derivation.mechanics import F1, F2, S1, a1, t, v1, x1
from derivation.scene import Param, Scene

DIRECTIONS = {"forward": ("fwd", 1), "backward": ("bwd", -1)}
REGIMES = {(1, "a"): "tractive", (1, "b"): "inverse-tractive",
           (-1, "a"): "backward on flank a", (-1, "b"): "backward on flank b"}
T_TRIP = sp.Symbol("t_trip", real=True)
T_PICKUP = sp.Symbol("t_pickup", real=True)      # lost motion: the first pickup of the stem
T_ENGAGED = sp.Symbol("t_engaged", real=True)    # lost motion: since when the stem is carried (+inf: apart)
M2_CARRIED = sp.Symbol("m2_carried", real=True)  # lost motion: m2, plus m3 while the stem is carried
F2_CARRIED = sp.Symbol("F2_carried", real=True)  # lost motion: the load on body 2 while the stem is carried


@dataclass(frozen=True)
class Slide:
    """Filippov sliding along phi = 0 between fwd_a (valid where phi > 0) and fwd_b (phi < 0)."""

    rate: sp.Expr                # d phi/dt along a mode, in terms of its a1 (the symbol a1)
    rate_a: sp.Expr              # d phi/dt along fwd_a
    rate_b: sp.Expr              # d phi/dt along fwd_b; sliding persists while rate_a < 0 < rate_b


@dataclass(frozen=True)
class Latch:
    """A time parameter the runtime sets when the guard ``name`` fires (+inf until then): once for
    the torque switch; the stem's pickup and carry times at each pickup and release."""

    symbol: sp.Symbol            # read from p after the free parameters
    name: str                    # its guard
    guard: sp.Expr               # falls through 0 when the latch fires; may use S1, S2 of the mode
    armed: sp.Expr               # the guard is computed while this holds
    doc: str


@dataclass(frozen=True)
class Quantity:
    """A named intermediate (a law, or x2) with its defining expression."""

    symbol: sp.Symbol
    expr: sp.Expr
    doc: str


@dataclass(frozen=True)
class Mode:
    """One mode: sliding on a flank in a direction, or stick."""

    name: str
    regime: str
    flank: str                   # "a", "b", or "" for stick (the flank follows from statics)
    direction: int               # +1, -1, 0 for stick
    accel: sp.Expr               # a1
    S1: sp.Expr
    S2: sp.Expr
    psi: sp.Expr | None = None   # FTF of a sliding mode
    denominator: sp.Expr | None = None   # D: the mode is consistent while D > 0
    normal: sp.Expr | None = None        # contact normal force N (>= 0 while the flank holds)
    jam: sp.Expr | None = None           # cos(gamma + f s rho) (> 0, else the wedge jams)
    slide: Slide | None = None           # the sliding mode along phi = 0 (literal equations only)
    declared: bool = True                # False: generated, but the scene does not let a run enter it
    gap_accel: sp.Expr | None = None     # d gap_rate/dt with a clearance: 0 in contact, own in free flight
    mesh: tuple[sp.Expr, ...] = ()       # compliant contact's guards: (N, slip) sliding, (N, cones) stick
    stem_accel: sp.Expr | None = None    # d v3/dt with lost motion: held, own (F2/m3) or carried (a2)


@dataclass(frozen=True)
class StickConditions:
    """Statics at v1 = 0 with the friction angle at zero speed."""

    flank_normal: sp.Expr        # f N: > 0 holds on flank a, < 0 on flank b
    tangential: sp.Expr          # friction force the stick needs
    cone_forward: sp.Expr        # >= 0 while no breakaway forward
    cone_backward: sp.Expr       # >= 0 while no breakaway backward


@dataclass(frozen=True)
class Impact:
    """A collision on one flank, in that flank's normal/tangent frame (mechanics.impact_frame)."""

    flank: str
    frame: tuple[sp.Expr, ...]   # (nu, s, W_nn, W_nt, W_tt, mu, e, dv1/d gap_rate, dv1/ds)


@dataclass(frozen=True)
class Model:
    """Everything code generation and the document need, nothing more."""

    scene: Scene
    symbols: dict[str, sp.Symbol]        # parameter name -> symbol
    states: tuple[sp.Symbol, ...]        # (x1, v1), or (v1,) when no law reads x1
    laws: tuple[Quantity, ...]           # in evaluation order
    events: tuple[laws.LawEvent, ...]    # one per piecewise law: the state leaves the latched piece
    switching: sp.Expr                   # phi
    modes: tuple[Mode, ...]
    stick: StickConditions | None
    latches: tuple[Latch, ...] = ()      # p = (free parameters..., latches..., pieces...)
    pieces: tuple[laws.Pieces, ...] = () # latched piece indices of the piecewise laws
    clearance: sp.Symbol | None = None   # normal clearance (states gap, gap_rate), None: zero
    body2: tuple[sp.Expr, sp.Expr] = ()  # (x2, v2) in x1, v1 (and gap, gap_rate with a clearance)
    impacts: tuple[Impact, ...] = ()     # per flank, with a clearance
    pickup: tuple[sp.Expr, ...] = ()     # lost motion: the pickup's frame (codegen.PICKUP_FRAME)

    @property
    def params(self) -> tuple[Param, ...]:
        return self.scene.params()

    def mode(self, name: str) -> Mode:
        return next(m for m in self.modes if m.name == name)


def param_symbol(param: Param) -> sp.Symbol:
    """The SymPy symbol of a scene parameter (all real; ranges are the scene's job)."""
    return sp.Symbol(param.name, real=True)


def _friction_symbols(scene: Scene) -> dict[str, sp.Symbol]:
    shared = len({id(scene.friction[f]) for f in scene.flanks}) == 1
    return {f: sp.Symbol("rho" if shared else f"rho_{f}", real=True) for f in scene.flanks}


def compose_laws(quantities: tuple[Quantity, ...]) -> dict:
    """Each law symbol -> its expression in states, t and parameters only."""
    done: dict = {}
    for q in quantities:
        done[q.symbol] = q.expr.subs(done)
    return done


def switching_rate(switching: sp.Expr, composed: dict) -> sp.Expr:
    """d phi/dt along a mode, in terms of the mode's a1: the laws composed into phi, chain rule."""
    phi = switching.subs(composed)
    return sp.diff(phi, t) + sp.diff(phi, x1) * v1 + sp.diff(phi, v1) * a1


def _drive(scene: Scene, x2: sp.Symbol) -> tuple[sp.Expr, str, tuple[Latch, ...], laws.Pieces | None]:
    """F1, its description, the torque switch's latch (F1 is cut for good at t = t_trip), its pieces."""
    law, pieces = laws.drive_force(scene.drive, param_symbol, x2)
    if scene.torque_switch is None:
        return law, f"drive force ({scene.drive.kind})", (), pieces
    trip = Latch(T_TRIP, "torque_switch", param_symbol(scene.torque_switch) - S1, t < T_TRIP,
                 "the torque switch cuts the motor when S1 reaches S1_trip")
    return (sp.Piecewise((law, t < T_TRIP), (0, True)),
            f"drive force ({scene.drive.kind}, cut by the torque switch at t = t_trip)", (trip,), pieces)


def _laws(scene: Scene, rho_of: dict[str, sp.Symbol]) -> tuple[tuple[Quantity, ...], tuple[laws.Pieces, ...],
                                                                 tuple[Latch, ...]]:
    """The laws in evaluation order (x2 first when a law reads it), their pieces, the latches."""
    slope = param_symbol(scene.gamma[scene.flanks[0]])
    x2 = sp.Symbol("x2", real=True)
    load, load_pieces = laws.load_force(scene.load, param_symbol, mechanics.x3 if scene.lost_motion else x2)
    drive, doc, latches, drive_pieces = _drive(scene, x2)
    quantities = []
    breakpoints = [p.event.expr for p in (load_pieces, drive_pieces) if p is not None]
    if scene.lost_motion or x2 in set().union(load.free_symbols, drive.free_symbols,
                                              *(e.free_symbols for e in breakpoints)):
        if scene.clearance is None:
            x2_expr = mechanics.kinematics().x2_of_x1.subs(mechanics.gamma, slope)
            quantities.append(Quantity(x2, x2_expr, "position of body 2 (kinematic constraint)"))
        else:
            x2_expr = mechanics.free_flight().x2_of.subs(mechanics.gamma, slope)
            quantities.append(Quantity(x2, x2_expr, "position of body 2 (from x1 and the normal gap)"))
    quantities.append(Quantity(F1, drive, doc))
    quantities.append(Quantity(F2, load, f"load force ({scene.load.kind})" + (
        ", on the stem from its first pickup" if scene.lost_motion else "")))
    if scene.lost_motion:
        stem_laws, stem_latches = _stem_laws(scene, x2)
        quantities += stem_laws
        latches += stem_latches
    done = set()
    for f in scene.flanks:
        if rho_of[f] not in done:
            done.add(rho_of[f])
            expr = laws.friction_angle(scene.friction[f], param_symbol, param_symbol(scene.gamma[f]))
            quantities.append(Quantity(rho_of[f], expr, f"friction angle ({scene.friction[f].kind})"))
    return tuple(quantities), tuple(p for p in (drive_pieces, load_pieces) if p is not None), latches


def _stem_laws(scene: Scene, x2: sp.Symbol) -> tuple[list[Quantity], tuple[Latch, ...]]:
    """Lost motion: while body 2 carries the stem, the load F2 acts on body 2 and the stem's mass
    moves with it; the latches of pickup and release."""
    lm = {k: param_symbol(v) for k, v in scene.lost_motion.items()}
    m2 = param_symbol(scene.m2)
    carried = t >= T_ENGAGED
    quantities = [
        Quantity(F2_CARRIED, sp.Piecewise((F2, carried), (0, True)),
                 "force on body 2: the load, through the stem while body 2 carries it"),
        Quantity(M2_CARRIED, sp.Piecewise((m2 + lm["stem_mass"], carried), (m2, True)),
                 "mass on body 2's guide: the stem's too while body 2 carries it"),
    ]
    release = mechanics.pickup().stem_force.subs({mechanics.m2: m2, mechanics.m3: lm["stem_mass"], mechanics.F3: F2})
    latches = (Latch(T_PICKUP, "stem_gap", lm["travel"] + mechanics.x3 - x2, sp.Not(carried),
                     "body 2 reaches the stem (gap travel + x3 - x2)"),
               Latch(T_ENGAGED, "stem_contact", release, carried,
                     "the stem's contact force N3 falls to 0: it leaves body 2"))
    return quantities, latches


def _stem(scene: Scene, rho_of: dict[str, sp.Symbol], modes: list[Mode]) -> tuple[list[Mode], tuple[sp.Expr, ...]]:
    """Each mode's stem acceleration (held, own or carried) and the pickup's frame on flank a."""
    lm = {k: param_symbol(v) for k, v in scene.lost_motion.items()}
    m3 = lm["stem_mass"]
    ratio = mechanics.kinematics().ratio.subs(mechanics.gamma, param_symbol(scene.gamma["a"]))
    out = [dataclasses.replace(m, stem_accel=sp.Piecewise(
        (ratio * m.accel, t >= T_ENGAGED), (F2 / m3, t >= T_PICKUP), (0, True))) for m in modes]
    pk = mechanics.pickup()
    sub = {**_specialise(scene, "a", rho_of), mechanics.m2: param_symbol(scene.m2)}   # body 2 without the stem
    jump = {s: pk.jump_v1[s].subs(sub) for s in (1, -1)}
    frame = (mechanics.v3 - ratio * v1, v1, 1 / m3 - ratio * jump[1], jump[1], 1 / m3 - ratio * jump[-1], jump[-1],
             1 / m3, sp.Min(pk.cone_forward.subs(sub), pk.cone_backward.subs(sub)), lm["restitution"],
             pk.inertia.subs(sub), m3, ratio)
    return out, frame


def _specialise(scene: Scene, flank: str, rho_of: dict[str, sp.Symbol]) -> dict:
    return {mechanics.gamma: param_symbol(scene.gamma[flank]), mechanics.rho: rho_of[flank],
            mechanics.m1: param_symbol(scene.m1),
            **({mechanics.m2: M2_CARRIED, F2: F2_CARRIED} if scene.lost_motion
               else {mechanics.m2: param_symbol(scene.m2)})}


def _sliding_modes(scene: Scene, rho_of: dict[str, sp.Symbol]) -> list[Mode]:
    modes = []
    for word, (prefix, direction) in DIRECTIONS.items():
        if word not in scene.modes:
            continue
        for flank in scene.flanks:
            m = mechanics.sliding(flank, direction)
            sub = _specialise(scene, flank, rho_of)
            phi = m.switching.subs(sub)
            modes.append(Mode(
                name=f"{prefix}_{flank}",
                regime=REGIMES[direction, flank], flank=flank, direction=direction,
                accel=m.accel.subs(sub), S1=m.S1.subs(sub), S2=m.S2.subs(sub), psi=m.psi.subs(sub),
                denominator=m.denominator.subs(sub), normal=m.normal.subs(sub).subs(mechanics.phi, phi),
                jam=m.jam_factor.subs(sub)))
    return modes


def _stick(scene: Scene, rho_of: dict[str, sp.Symbol]) -> tuple[Mode, StickConditions]:
    st = mechanics.stick()
    sub = _specialise(scene, scene.flanks[0], rho_of)
    flank_normal = st.normal_times_flank.subs(sub)
    if len(set(rho_of.values())) > 1:
        sub[mechanics.rho] = sp.Piecewise((rho_of["a"], flank_normal >= 0), (rho_of["b"], True))
    conditions = StickConditions(flank_normal, st.tangential.subs(sub),
                                 st.cone_forward.subs(sub), st.cone_backward.subs(sub))
    mode = Mode(name="stick", regime="stick", flank="", direction=0, accel=sp.Integer(0), S1=F1, S2=F2.subs(sub))
    return mode, conditions


def _literal_modes(scene: Scene, rho_of: dict[str, sp.Symbol]) -> tuple[list[Mode], sp.Expr]:
    """The paper's eqs. (6), (7), (8), (9) verbatim, with Psi_1 on flank a and Psi_2 on b."""
    sub = _specialise(scene, "a", rho_of)
    modes = []
    for flank, psi in (("a", paper.PSI_TRACTIVE), ("b", paper.PSI_INVERSE)):
        psi = psi.subs(sub)
        accel = paper.EQ6_ACCEL.subs(sub).subs(mechanics.Psi, psi)
        s1 = paper.EQ8_S1.subs(sub).subs(mechanics.a1, accel)
        # eq. (9) divided through: S1 carries the factor psi, so psi = 0 (rho = gamma) is no singularity.
        s2 = sp.cancel(paper.EQ9_S2.subs({mechanics.S1: s1, mechanics.Psi: psi}))
        modes.append(Mode(name=f"fwd_{flank}", regime=REGIMES[1, flank], flank=flank, direction=1,
                          accel=accel, S1=s1, S2=s2,
                          psi=psi, denominator=sp.fraction(sp.together(accel))[1]))
    return modes, paper.EQ7_SWITCHING.subs(sub)


def _slide_mode(scene: Scene, switching: sp.Expr, composed: dict, fwd_a: Mode, fwd_b: Mode) -> Mode:
    """Filippov sliding along phi = 0, where the literal a1 jumps (audit.literal_jump).

    The consistent model needs no such mode: its a1 is continuous at phi = 0 (both flanks
    give F1/m1 there), so the rates along fwd_a and fwd_b agree and the state crosses.
    """
    rate = switching_rate(switching, composed)
    # Filippov's combination with the rates linear in a1, d phi/dt = drift + gain a1 along any mode.
    drift, gain, acc_a, acc_b = sp.symbols("drift gain acc_a acc_b", real=True)
    r_a, r_b = drift + gain * acc_a, drift + gain * acc_b
    lam = sp.factor(r_b / (r_b - r_a))
    combined = sp.cancel(lam * acc_a + (1 - lam) * acc_b)        # -drift/gain: d phi/dt = 0
    values = {drift: rate.subs(a1, 0), gain: sp.diff(rate, a1), acc_a: fwd_a.accel, acc_b: fwd_b.accel}
    weight, accel = lam.subs(values), combined.subs(values)
    return Mode(name="slide_fwd", regime="sliding along phi = 0", flank="", direction=1, accel=accel,
                S1=weight * fwd_a.S1 + (1 - weight) * fwd_b.S1, S2=weight * fwd_a.S2 + (1 - weight) * fwd_b.S2,
                slide=Slide(rate, rate.subs(a1, fwd_a.accel), rate.subs(a1, fwd_b.accel)),
                declared="sliding" in scene.modes)


def _with_clearance(scene: Scene, rho_of: dict[str, sp.Symbol], modes: list[Mode]) -> tuple[list[Mode],
                                                                                         tuple[Impact, ...]]:
    """The contact modes keep the gap (d gap_rate/dt = 0); free flight; the impact frames."""
    sub = _specialise(scene, "a", rho_of)
    ff = mechanics.free_flight()
    contact = [dataclasses.replace(m, gap_accel=sp.Integer(0)) for m in modes]
    free = Mode(name="free", regime="free flight", flank="", direction=0, accel=ff.accel1.subs(sub),
                S1=sp.Integer(0), S2=sp.Integer(0), gap_accel=ff.gap_accel.subs(sub))
    impacts = []
    for flank in scene.flanks:
        frame = mechanics.impact_frame(flank)
        f = mechanics.FLANK_SIGN[flank]
        sub_f = _specialise(scene, flank, rho_of)
        c_w, c_s = (sp.diff(frame.v1_of, mechanics.gap_rate), sp.diff(frame.v1_of, mechanics.slip_speed))
        values = (f * mechanics.gap_rate, ff.slip_of, frame.W[0, 0], frame.W[0, 1], frame.W[1, 1],
                  sp.tan(mechanics.rho), mechanics.e_r, c_w, c_s)
        restitution = {mechanics.e_r: param_symbol(scene.restitution)}
        impacts.append(Impact(flank, tuple(v.subs(sub_f).subs(restitution) for v in values)))
    return [*contact, free], tuple(impacts)


def _mesh_modes(scene: Scene, rho_of: dict[str, sp.Symbol]) -> list[Mode]:
    """Free flight and compliant contact on each flank: sliding with the slip's sign, or stick."""
    ff = mechanics.free_flight()
    sub = _specialise(scene, "a", rho_of)
    sub.update({mechanics.k_mesh: param_symbol(scene.mesh["stiffness"]),
                mechanics.c_mesh: param_symbol(scene.mesh["damping"]),
                mechanics.clearance: param_symbol(scene.clearance)})
    modes = [Mode(name="free", regime="free flight", flank="", direction=0, accel=ff.accel1.subs(sub),
                  S1=sp.Integer(0), S2=sp.Integer(0), gap_accel=ff.gap_accel.subs(sub))]
    wanted = [(word, d) for word, (_, d) in DIRECTIONS.items() if word in scene.modes]
    wanted += [("stick", 0)] if "stick" in scene.modes else []
    slip = ff.slip_of.subs(sub)
    for word, direction in wanted:
        for flank in scene.flanks:
            c = mechanics.mesh_contact(flank, direction)
            sub_f = {**sub, mechanics.rho: rho_of[flank]}
            accel, s1, s2, gap_accel = (e.subs(sub_f) for e in (c.accel1, c.S1, c.S2, c.gap_accel))
            prefix = DIRECTIONS[word][0] if direction else "stick"
            guards = (c.normal, slip) if direction else (c.normal, c.cone_forward, c.cone_backward)
            modes.append(Mode(name=f"mesh_{prefix}_{flank}", regime=REGIMES[direction, flank] if direction else "stick",
                              flank=flank, direction=direction, accel=accel, S1=s1, S2=s2,
                              normal=c.normal.subs(sub_f), gap_accel=gap_accel,
                              mesh=tuple(g.subs(sub_f) for g in guards)))
    return modes


def build_model(scene: Scene) -> Model:
    """Specialise the mechanics to ``scene``."""
    rho_of = _friction_symbols(scene)
    quantities, pieces, latches = _laws(scene, rho_of)
    stick = None
    if scene.equations == "literal":
        modes, switching = _literal_modes(scene, rho_of)
        modes.append(_slide_mode(scene, switching, compose_laws(quantities), *modes))
    else:
        modes = _sliding_modes(scene, rho_of)
        switching = mechanics.sliding(scene.flanks[0], 1).switching.subs(_specialise(scene, scene.flanks[0], rho_of))
        if "stick" in scene.modes:
            stick_mode, stick = _stick(scene, rho_of)
            modes.append(stick_mode)
    reads_x1 = any(x1 in q.expr.free_symbols for q in quantities)
    states = (x1, v1) if reads_x1 else (v1,)
    impacts: tuple[Impact, ...] = ()
    slope = {mechanics.gamma: param_symbol(scene.gamma[scene.flanks[0]])}
    kin = mechanics.kinematics()
    body2 = (kin.x2_of_x1.subs(slope), (kin.ratio * v1).subs(slope))
    if scene.clearance is not None:
        if scene.mesh is not None:
            modes, stick = _mesh_modes(scene, rho_of), None
        else:
            modes, impacts = _with_clearance(scene, rho_of, modes)
        states = (x1, mechanics.gap, mechanics.gap_rate, v1)   # x1 too: body 2's position needs it
        ff = mechanics.free_flight()
        body2 = (ff.x2_of.subs(slope), ff.v2_of.subs(slope))
    pickup: tuple[sp.Expr, ...] = ()
    if scene.lost_motion:
        modes, pickup = _stem(scene, rho_of, modes)
        states = (x1, mechanics.x3, mechanics.v3, v1)   # x1 too: the pickup's gap needs x2
    symbols = {p.name: param_symbol(p) for p in scene.params()}
    for q in quantities:     # a parameter may carry a law's name only if it is that law (constant F1, F2)
        assert str(q.symbol) not in symbols or q.expr == q.symbol, f"parameter {q.symbol} shadows the law {q.doc}"
    return Model(scene=scene, symbols=symbols, states=states,
                 laws=quantities, events=tuple(p.event for p in pieces), switching=switching,
                 modes=tuple(modes), stick=stick, latches=latches, pieces=pieces,
                 clearance=param_symbol(scene.clearance) if scene.clearance else None, impacts=impacts,
                 body2=body2, pickup=pickup)
