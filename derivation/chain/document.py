"""The derivation document of a chain scene: stages as wedges, modes, rest, decision and audit.

Built from the same SymPy objects as derivation/chain/ computes with, as Sections of document.py,
and written through its templates (scene text only through their ``literal`` filter).
"""
from __future__ import annotations

import math

import sympy as sp

from derivation import mechanics as mech
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
    first = dyn.sliding(*reachable[0])
    eom.text(f"Switching functions of the mode {first.name}: stage $k$'s normal force is "
             "$N_k = \\varphi_k \\cos\\rho_k / (D \\cos(\\gamma_k + f_k s \\rho_k))$, so the mode is consistent "
             "while every $\\varphi_k / D \\ge 0$ (each $\\varphi_k$ depends on the other stages' FTFs):")
    eom.math(*(f"\\varphi_{{{k + 1}}} = {_l(p)}" for k, p in enumerate(first.switching)))
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


def _decision(values: ChainValues) -> Section:
    s = Section("Decision at the scene's forces")
    for velocity, words in ((0.0, "at rest"), (AUDIT_SPEED, "moving forward"), (-AUDIT_SPEED, "moving backward")):
        d = decide(values, velocity)
        s.text(f"{words.capitalize()}: {d.outcome}, {', '.join(d.modes) or 'no mode'}"
               + (f", $a_0$ = {d.accel:.6g}" if d.accel is not None else "") + f". {d.reason}.")
    return s


def _audit(values: ChainValues, reachable: list) -> Section:
    """Checks at the scene's values: power balance and Coulomb's losses per mode; one stage equals mechanics."""
    n_st = len(values.gamma)
    sym = dyn.symbols(n_st)
    at = {**dict(zip((*sym.gamma, *sym.rho, *sym.lever_in, *sym.lever_out, *sym.inertia, *sym.force),
                     values.args()))}
    rows = []
    for direction, regimes in reachable:
        mode = dyn.sliding(direction, regimes)
        point = {**at, dyn.v0: direction * AUDIT_SPEED}
        speed = dyn.speed_factors(sym)
        supplied = sum(sym.force[j] * speed[j] * dyn.v0 for j in range(n_st + 1))
        kinetic = sum(sym.inertia[j] * speed[j]**2 * mode.accel * dyn.v0 for j in range(n_st + 1))
        losses = sum(mode.friction_power)
        balance = float((supplied - kinetic - losses).subs(point))
        coulomb = float(sum(p - c for p, c in zip(mode.friction_power, mode.coulomb_power)).subs(point))
        rows.append([mode.name, f"{balance:.3g}", f"{coulomb:.3g}"])
    s = Section("Audit")
    s.text(f"At the scene's values and $v_0 = \\pm{AUDIT_SPEED:g}$: input power minus the rate of kinetic energy "
           "minus the stages' friction losses (from the forces), and the losses minus Coulomb's "
           "$\\tan\\rho\\,N|v_1|/\\cos\\gamma$; both vanish to rounding. tests/test_chain.py checks the same "
           "symbolically and against Newton written by hand, and that one stage is mechanics.py's wedge.")
    s.table("lll", ["mode", "power balance", "losses - Coulomb"], rows)
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
    sections = [_stages(chain), *_modes(len(chain.stages), reachable), _rest(len(chain.stages)),
                _decision(values), _audit(values, reachable)]
    return {"title": f"Derivation of the chain of stages for scene `{chain.name}`",
            "description": chain.description, "source": chain.source, "digest": chain.digest,
            "params": params, "sections": sections}


def write_chain_documents(chain: ChainScene, *, latex=None, markdown=None, pdf=None) -> list:
    """Write the chain's document as Markdown, LaTeX and a PDF, as document.write_documents does."""
    if not (latex or markdown or pdf):
        return []
    return write_built(build_chain_document(chain), chain.name, latex=latex, markdown=markdown, pdf=pdf)
