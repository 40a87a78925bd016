"""The derivation document of a chain scene: stages as wedges, modes, rest, decision and audit.

Built from the same SymPy objects as derivation/chain/ computes with, as Sections of document.py,
and written through its templates (scene text only through their ``literal`` filter).
"""
from __future__ import annotations

import math

import sympy as sp

from derivation import mechanics as mech
from derivation.chain import clearance as cl
from derivation.chain import dynamics as dyn
from derivation.chain import stages as st
from derivation.chain.scene import ChainScene
from derivation.chain.selector import ChainValues, decide
from derivation.document import Section, _l, write_built

AUDIT_SPEED = 1.0           # v_0 of the audit's power balance, in the scene's units of body 0


def _stages(chain: ChainScene) -> Section:
    s = Section("Stages as equivalent wedges")
    s.text("Stage $k$ joins body $k-1$ (input, $x_1 = r_{\\mathrm{in},k}\\, q_{k-1}$) and body $k$ (output, "
           "$x_2 = r_{\\mathrm{out},k}\\, q_k$). A helical flank is tilted out of the wedge plane; its force "
           "$N\\mathbf n_3 + \\mu N \\mathbf t$ (Coulomb along the slip, which lies in the plane) resolved into the "
           "plane is a plane wedge's force with the friction coefficient $\\mu$ over the in-plane share of the "
           "unit normal:")
    for kind in dict.fromkeys(stage.kind for stage in chain.stages):
        w = st.equivalent_wedge(kind)
        s.text(f"`{kind}`: flank normal $\\mathbf n_3 = {_l(st.kinds()[kind].flank_normal)}$ in (x1, x2, radial).")
        s.math(f"\\tan\\gamma = {_l(w.tan_gamma)}, \\qquad \\tan\\rho' = {_l(w.tan_rho)}",
               f"r_{{\\mathrm{{in}}}} = {_l(w.lever_in)}, \\quad r_{{\\mathrm{{out}}}} = {_l(w.lever_out)}, \\quad "
               f"\\frac{{\\dot q_{{\\mathrm{{in}}}}}}{{\\dot q_{{\\mathrm{{out}}}}}} = {_l(w.ratio)}")
    values = chain.values()
    s.table("lllllll", ["stage", "kind", "$\\gamma$ [deg]", "$\\rho'$ [deg]", "$r_{in}$", "$r_{out}$", "self-locking"],
            [[str(k + 1), f"`{stage.kind}`", f"{math.degrees(values.gamma[k]):.6g}",
              f"{math.degrees(values.rho[k]):.6g}", f"{values.lever_in[k]:.6g}", f"{values.lever_out[k]:.6g}",
              "yes" if values.rho[k] >= values.gamma[k] else "no"] for k, stage in enumerate(chain.stages)])
    return s


def _kinetostatics() -> Section:
    """Each stage's kinematics and contact forces per flank and direction, from mechanics.py."""
    s = Section("Kinetostatics of a stage")
    s.text("Stage $k$ is mechanics.py's wedge with $\\gamma = \\gamma_k$, $\\rho = \\rho_k$: input $x_1$, output "
           "$x_2$, kinematics and contact forces along the guides in terms of the normal force $N \\ge 0$ on the "
           "loaded flank, and the FTF $\\Psi = -R_1 / R_2$ (tractive: $\\tan(\\gamma+\\rho)$, inverse-tractive: "
           "$\\tan(\\gamma-\\rho)$):")
    s.math(f"\\dot x_2 = {_l(mech.kinematics().ratio)}\\,\\dot x_1")
    rows = []
    for direction in (1, -1):
        for flank in ("a", "b"):
            m = mech.sliding(flank, direction)
            regime = dyn.TRACTIVE if dyn.flank(dyn.TRACTIVE, direction) == flank else dyn.INVERSE
            rows.append([f"{flank}, $s = {direction:+d}$", regime, f"${_l(m.R1)}$", f"${_l(m.R2)}$", f"${_l(m.psi)}$"])
    s.table("lllll", ["flank, direction", "regime", "$R_1$", "$R_2$", "$\\Psi$"], rows)
    return s


def _modes(n_st: int, reachable: list) -> list[Section]:
    sym = dyn.symbols(n_st)
    kin = Section("One coordinate")
    kin.text("Each stage's kinematics ($v_2 = \\tan\\gamma\\, v_1$, sliding speed $v_1/\\cos\\gamma$) ties every "
             "body to body 0; a stage slides exactly when body 0 moves, so all stages slide or all rest:")
    kin.math(*(f"\\dot q_{{{j}}} = {_l(c)}\\,\\dot q_0" for j, c in enumerate(dyn.speed_factors(sym)) if j))
    eom = Section("Modes and reduced equation of motion")
    eom.text("Newton for every body, each stage's forces tied by its FTF ($R_1 = -\\Psi R_2$), solved once with "
             "the $\\Psi_k$ as symbols:")
    eom.math(f"a_0 = {_l(dyn.sliding(*reachable[0]).accel_in_psi)}")
    eom.text("Per mode, each stage's FTF from its flank and the direction (tractive: $\\tan(\\gamma+\\rho)$, "
             "inverse-tractive: $\\tan(\\gamma-\\rho)$) and $D$, the denominator: $D \\le 0$ marks a Painleve-type "
             "mode. Only the modes the stages' flanks allow are derived.")
    eom.table("lll", ["mode", "$\\Psi_k$", "$D$"],
              [[dyn.sliding(*r).name, ", ".join(f"${_l(p)}$" for p in dyn.sliding(*r).psi),
                f"${_l(dyn.sliding(*r).denominator)}$"] for r in reachable])
    eom.text("Switching functions: stage $k$'s normal force is "
             "$N_k = \\varphi_k \\cos\\rho_k / (D \\cos(\\gamma_k + f_k s \\rho_k))$, so a mode is consistent "
             "while every $\\varphi_k / D \\ge 0$ (each $\\varphi_k$ depends on the other stages' FTFs). Each "
             "reachable mode's reduced dynamics and switching functions:")
    for r in reachable:
        mode = dyn.sliding(*r)
        eom.text(f"Mode {mode.name}:")
        eom.math(f"a_0 = {_l(mode.accel)}", *(f"\\varphi_{{{k + 1}}} = {_l(p)}" for k, p in enumerate(mode.switching)))
    return [kin, eom]


def _rest(n_st: int) -> Section:
    rest = dyn.stuck(n_st)
    s = Section("Resting chain")
    s.text(f"Statics: {n_st + 1} equations for {2 * n_st} stage forces; the internal forces "
           + (", ".join(f"${_l(x)}$" for x in rest.internal) or "(none)")
           + " stay free (statically undetermined for two or more stages). Stage forces on their bodies:")
    s.math(*(f"\\text{{stage {k + 1}: }} {_l(i)} \\text{{ on body {k}}}, \\quad {_l(o)} \\text{{ on body {k + 1}}}"
             for k, (i, o) in enumerate(zip(rest.on_input, rest.on_output))))
    g, r = sp.symbols("gamma rho", positive=True)
    product, k, _ = dyn.holding(g, r)
    s.text("The stick cone of each stage ($|T| \\le \\tan\\rho\\,|fN|$) as one product: "
           "$c_+ c_- = k\\,(F_1 + \\Psi_t F_2)(F_1 + \\Psi_i F_2)$ with")
    s.math(f"k = {_l(k)} < 0 \\quad (\\gamma + \\rho < 90^\\circ)")
    s.text("so stage $k$ holds while")
    s.math(*(f"{_l(h)} \\le 0" for h in rest.holds))
    return s


OPEN_STAGE = "An open stage (clearance)"


def _open_stage(chain: ChainScene, clearance=None) -> Section:
    """Stage k open (the scene's ``clearance``; without one the last stage), from clearance.py: groups, gap
    kinematics, impact masses; one section per stage with a clearance, each open alone."""
    n_st = len(chain.stages)
    k = clearance.stage if clearance is not None else n_st
    opened = cl.open_chain(n_st, (k,))
    hit = cl.impact(n_st, (k,), k, "a")
    first = ", ".join(str(j) for j in opened.groups.first)
    s = Section(OPEN_STAGE if len(chain.clearances) < 2 else f"{OPEN_STAGE}: stage {k}")
    if clearance is None:
        s.text(f"Were stage {k} open (a clearance between its flanks), it would transmit nothing and the chain would "
               f"split into the groups that start at bodies {first}, each moving with its first body's coordinate.")
    else:
        c = clearance
        s.text(f"Stage {k} has a clearance of {c.clearance.value:.6g} m along its flanks' normal (restitution "
               f"{c.restitution.value:.6g}, gap {c.gap.value:.6g} m from flank a at the start). While its flanks are "
               f"apart it transmits nothing and the chain splits into the groups that start at bodies {first}, each "
               "moving with its first body's coordinate" + (" (the other stages with a clearance closed: one open "
                                                            "stage at a time is modelled)."
                                                            if len(chain.clearances) > 1 else "."))
    s.text("Newton for every body, each closed stage's forces tied by its FTF, gives each group's acceleration:")
    s.math(*(f"a_{{{j}}} = {_l(a)}" for j, a in zip(opened.groups.first, opened.accel)))
    s.text(f"Stage {k}'s normal gap $g_{{{k}}}$ (0 on flank a, the clearance on flank b) moves with the one-stage "
           "gap kinematics $\\dot g = \\dot x_2 \\cos\\gamma - \\dot x_1 \\sin\\gamma$:")
    s.math(f"\\dot g_{{{k}}} = {_l(opened.gap_rate[k])}")
    s.text("When the gap closes the flanks collide: each group reduced to the stage's $x_1$ and $x_2$ by its "
           "response to an impulse there (its closed stages tied by their FTFs) gives the effective masses of the "
           "one-stage impact (its inverse mass in the flank's frame, Coulomb friction and restitution):")
    s.math(f"m_1 = {_l(hit.m1)}", f"m_2 = {_l(hit.m2)}",
           f"W_{{nn}} = {_l(hit.W[0, 0])}")
    return s


def _decision(values: ChainValues) -> Section:
    s = Section("Decision at the scene's forces")
    for velocity, words in ((0.0, "at rest"), (AUDIT_SPEED, "moving forward"), (-AUDIT_SPEED, "moving backward")):
        d = decide(values, velocity)
        s.text(f"{words.capitalize()}: {d.outcome}, {', '.join(d.modes) or 'no mode'}"
               + (f", $a_0$ = {d.accel:.6g}" if d.accel is not None else "") + f". {d.reason}.")
    return s


def _at(values: ChainValues) -> dict:
    sym = dyn.symbols(len(values.gamma))
    return dict(zip((*sym.gamma, *sym.rho, *sym.lever_in, *sym.lever_out, *sym.inertia, *sym.force), values.args()))


def _uniform(n_st: int, forward: bool) -> tuple[int, tuple[str, ...]]:
    """The mode of steady driving (forward, every stage tractive) or back-driving (backward, inverse-tractive)."""
    return (1, (dyn.TRACTIVE,) * n_st) if forward else (-1, (dyn.INVERSE,) * n_st)


def _steady_force(values: ChainValues, forward: bool) -> float | None:
    """Body 0's force at which the uniform mode has a_0 = 0, from the derived reduced dynamics (None: not
    reachable, or a_0 does not depend on it)."""
    n_st = len(values.gamma)
    if _uniform(n_st, forward) not in dyn.reachable(values.flanks):
        return None
    f0 = dyn.symbols(n_st).force[0]
    numerator = sp.fraction(sp.together(dyn.sliding(*_uniform(n_st, forward)).accel))[0]
    at = {k: v for k, v in _at(values).items() if k != f0}
    roots = sp.solve(numerator.subs(at), f0)
    return float(roots[0]) if len(roots) == 1 else None


def _steady_force_by_hand(values: ChainValues, forward: bool) -> float:
    """The same, written by hand: each stage passes tan(g)/tan(g + r) of the power forward, or gives back
    tan(g - r)/tan(g) of it; every other body's force takes or gives its share at its speed ratio."""
    n_st = len(values.gamma)
    speed = [1.0]
    for k in range(n_st):
        speed.append(speed[-1] * values.lever_in[k] * math.tan(values.gamma[k]) / values.lever_out[k])
    out = -values.force[-1] * speed[-1]            # power per unit v_0 the last stage gives its output body
    for k in range(n_st - 1, -1, -1):
        g, r = values.gamma[k], values.rho[k]
        into = out * math.tan(g + r) / math.tan(g) if forward else out * math.tan(g - r) / math.tan(g)
        out = into - values.force[k] * speed[k]   # what stage k takes from body k, given by stage k - 1
    return into


def _band(values: ChainValues) -> Section:
    s = Section("Driving and holding torque")
    high, low = _steady_force(values, True), _steady_force(values, False)
    s.text("Body 0's force $F_0$ at which the chain runs steadily ($a_0 = 0$), the other bodies' forces as given: "
           "driving forward with every stage tractive, and driven back by the loads with every stage "
           "inverse-tractive; solved from the reduced dynamics of these two modes.")
    rows = [[words, "-" if f is None else f"{f:.6g}"] for words, f in
            (("forward, every stage tractive", high), ("backward, every stage inverse-tractive", low))]
    s.table("ll", ["steady mode", "$F_0$"], rows)
    if high is not None and low is not None and low < high:
        s.text(f"Started from rest with $F_0$ between {low:.6g} and {high:.6g}, neither of these breakaways is "
               "consistent (each would start with $a_0$ against its direction): the drive cannot lift the load "
               "through the forward losses, and the load cannot drive the chain back through the backward losses. "
               "Whether the chain then rests is the decision below: resting is consistent when the stages' stick "
               "cones admit an internal force split.")
    return s


def _switch_rows(values: ChainValues, reachable: list) -> list[list[str]]:
    """At the body-0 force where stage k's switching function vanishes: N_k in this mode and in the mode with
    stage k on its other regime (both 0), and the difference of their a_0 (0: the switch is smooth)."""
    n_st = len(values.gamma)
    f0 = dyn.symbols(n_st).force[0]
    at = {k: v for k, v in _at(values).items() if k != f0}
    rows = []
    for direction, regimes in reachable:
        mode = dyn.sliding(direction, regimes)
        for k in range(n_st):
            other = (*regimes[:k], dyn.INVERSE if regimes[k] == dyn.TRACTIVE else dyn.TRACTIVE, *regimes[k + 1:])
            roots = sp.solve(mode.switching[k].subs(at), f0)
            if (direction, other) not in reachable or len(roots) != 1:
                continue
            point = {**at, f0: roots[0]}
            neighbour = dyn.sliding(direction, other)
            normal = max(abs(float(mode.normal[k].subs(point))), abs(float(neighbour.normal[k].subs(point))))
            jump = abs(float((mode.accel - neighbour.accel).subs(point)))
            rows.append([mode.name, str(k + 1), f"{float(roots[0]):.6g}", f"{normal:.3g}", f"{jump:.3g}"])
    return rows


def _audit(values: ChainValues, reachable: list) -> Section:
    """Checks at the scene's values: the FTFs and steady forces against hand-written formulas, power balance
    per stage and of the chain, contact force 0 at every switch; one stage equals mechanics."""
    n_st = len(values.gamma)
    sym = dyn.symbols(n_st)
    at = _at(values)
    speed = dyn.speed_factors(sym)
    rows, ftf_same = [], True
    for direction, regimes in reachable:
        mode = dyn.sliding(direction, regimes)
        point = {**at, dyn.v0: direction * AUDIT_SPEED}
        supplied = sum(sym.force[j] * speed[j] * dyn.v0 for j in range(n_st + 1))
        kinetic = sum(sym.inertia[j] * speed[j]**2 * mode.accel * dyn.v0 for j in range(n_st + 1))
        balance = float((supplied - kinetic - sum(mode.friction_power)).subs(point))
        stages = max(abs(float((p - c).subs(point))) for p, c in zip(mode.friction_power, mode.coulomb_power))
        rows.append([mode.name, f"{balance:.3g}", f"{stages:.3g}"])
        hand = [sp.tan(sym.gamma[k] + (1 if r == dyn.TRACTIVE else -1) * sym.rho[k]) for k, r in enumerate(regimes)]
        ftf_same &= all(sp.simplify(sp.expand_trig(p - h)) == 0 for p, h in zip(mode.psi, hand))
    s = Section("Audit")
    s.text(f"At the scene's values and $v_0 = \\pm{AUDIT_SPEED:g}$: input power minus the rate of kinetic energy "
           "minus the stages' friction losses (from the forces), and per stage the largest difference between its "
           "loss $-(R_1 v_1 + R_2 v_2)$ and Coulomb's $\\tan\\rho\\,N|v_1|/\\cos\\gamma$; both vanish to "
           "rounding. tests/test_chain.py checks the same symbolically and against Newton written by hand, "
           "tests/test_chain_laws.py on simulated runs.")
    s.table("lll", ["mode", "power balance", "max over stages: loss - Coulomb"], rows)
    s.text("Every mode's FTFs against $\\tan(\\gamma_k \\pm \\rho_k)$ written by hand: "
           + ("agree exactly." if ftf_same else "DIFFER."))
    hand_rows = []
    for forward, words in ((True, "forward, every stage tractive"), (False, "backward, every stage inverse-tractive")):
        derived = _steady_force(values, forward)
        if derived is not None:
            by_hand = _steady_force_by_hand(values, forward)
            hand_rows.append([words, f"{derived:.9g}", f"{by_hand:.9g}",
                              f"{abs(derived - by_hand) / max(abs(by_hand), 1e-300):.2g}"])
    s.text("Steady $F_0$ from the reduced dynamics against the stages' efficiencies by hand "
           "($\\tan\\gamma/\\tan(\\gamma+\\rho)$ forward, $\\tan(\\gamma-\\rho)/\\tan\\gamma$ back, "
           "power passed stage by stage):")
    s.table("llll", ["steady mode", "derived", "by hand", "relative difference"], hand_rows)
    s.text("At each switch (the body-0 force where a stage's switching function vanishes, the other forces as "
           "given): the stage's normal force in the mode and in the mode with that stage on its other regime "
           "(both must be 0), and the difference of their $a_0$ (0: the regimes meet continuously):")
    s.table("lllll", ["mode", "stage", "$F_0$ at the switch", "$N_k$, largest magnitude", "$\\Delta a_0$, magnitude"],
            _switch_rows(values, reachable))
    one = dyn.sliding(1, (dyn.TRACTIVE,))
    ref = mech.sliding("a", 1)
    s1 = dyn.symbols(1)
    same = sp.simplify(one.accel.subs({s1.lever_in[0]: 1, s1.lever_out[0]: 1}) - ref.accel.subs(
        {mech.gamma: s1.gamma[0], mech.rho: s1.rho[0], mech.m1: s1.inertia[0], mech.m2: s1.inertia[1],
         mech.F1: s1.force[0], mech.F2: s1.force[1]})) == 0
    s.text("One stage with unit levers, tractive: $a_0$ equals mechanics.py's $a_1$: "
           + ("agrees exactly." if same else "DIFFERS."))
    return s


def build_chain_document(chain: ChainScene) -> dict:
    """Title, parameter table and sections, in document.py's shape."""
    values = chain.values()
    reachable = dyn.reachable(values.flanks)
    params = [[f"`{p.name}`", f"{p.value:.6g}", p.unit, "fixed"]
              for p in (*(q for s in chain.stages for q in s.params.values()),
                        *(q for b in chain.bodies for q in (b.inertia, b.force)))]
    sections = [_stages(chain), _kinetostatics(), *_modes(len(chain.stages), reachable), _rest(len(chain.stages)),
                *(_open_stage(chain, c) for c in chain.clearances or (None,)), _band(values), _decision(values), _audit(values, reachable)]
    return {"title": f"Derivation of the chain of stages for scene `{chain.name}`",
            "description": chain.description, "source": chain.source, "digest": chain.digest,
            "params": params, "sections": sections}


def write_chain_documents(chain: ChainScene, *, latex=None, markdown=None, pdf=None) -> list:
    """Write the chain's document as Markdown, LaTeX and a PDF, as document.write_documents does."""
    if not (latex or markdown or pdf):
        return []
    return write_built(build_chain_document(chain), chain.name, latex=latex, markdown=markdown, pdf=pdf)
