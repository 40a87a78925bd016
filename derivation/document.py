"""The derivation document, built from the same objects that feed code generation.

``build_document(model)`` returns a list of sections of text, equations and tables;
``render(doc, "latex" | "markdown")`` writes it through a Jinja2 template, ``write_documents``
writes the files. Text uses
``$...$`` for inline math, which both targets understand; that text is tswm's own. Text from
the scene (its description, its file's path) goes through the ``literal`` filter, which
escapes everything TeX or Markdown would read as markup: maths in the document comes
from SymPy, never from a scene string.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import jinja2
import sympy as sp

from derivation import audit, mechanics as M
from derivation.model import Model, param_symbol

FLANK_WORDS = {"a": "flank a (body 1 pushes body 2)", "b": "flank b (body 2 pushes body 1)"}


@dataclass
class Section:
    title: str
    blocks: list[tuple] = field(default_factory=list)

    def text(self, text: str) -> None:
        self.blocks.append(("text", text))

    def math(self, *lines: str) -> None:
        self.blocks.append(("math", list(lines)))

    def table(self, spec: str, header: list[str], rows: list[list[str]]) -> None:
        self.blocks.append(("table", spec, header, rows))


_SHORT_NAME = re.compile(r"([A-Za-z]|alpha|beta|gamma|delta|epsilon|mu|phi|psi|Psi|rho|tau|omega)(\d*)")


STATE_LATEX = {"gap": "g", "gap_rate": "\\dot g"}   # the clearance's states, as the text names them


def symbol_latex(name: str) -> str | None:
    """LaTeX for a parameter name with underscores that SymPy would typeset badly, else None.

    A name led by one letter or a Greek letter gets a subscript: ``F2_after`` ->
    F_{2,after}, ``gamma_a`` -> gamma_{a}. A name led by a word (``friction_rho``,
    ``load_piece``) is set as the identifier itself, as in the parameter table."""
    if name in STATE_LATEX:
        return STATE_LATEX[name]
    if "_" not in name:
        return None
    head, *rest = name.split("_")
    short = _SHORT_NAME.fullmatch(head)
    if short and all(rest):
        letter = f"\\{short[1]}" if len(short[1]) > 1 else short[1]
        parts = [short[2]] if short[2] else []
        parts += [p if p.isdigit() or len(p) == 1 else f"\\mathrm{{{p}}}" for p in rest]
        return f"{letter}_{{{','.join(parts)}}}"
    return "\\mathtt{" + name.replace("_", "\\_") + "}"


def _l(expr) -> str:
    names = {}
    for symbol in getattr(expr, "free_symbols", ()):
        text = symbol_latex(symbol.name) if isinstance(symbol, sp.Symbol) else None
        if text is not None:
            names[symbol] = text
    return sp.latex(expr, symbol_names=names)


def _eq(lhs, rhs) -> str:
    return f"{_l(lhs)} = {_l(rhs)}"


def _assumptions() -> Section:
    s = Section("Assumptions")
    s.text("Two rigid bodies on frictionless guides: body 1 (the worm, reduced to its pitch line) moves along "
           "$x_1$, body 2 (the wheel, reduced likewise) along $x_2$, perpendicular to $x_1$. Body 1 carries two "
           "flanks, straight contact lines at the slope $\\gamma$ to $x_1$, with no clearance between them.")
    s.text("Flank a transmits when body 1 pushes body 2 ($f = +1$), flank b when body 2 pushes body 1 "
           "($f = -1$). The contact force has a normal part $N \\ge 0$ and Coulomb friction $N\\tan\\rho$ against "
           "the sliding, so the resultant leans by the friction angle $\\rho$ from the normal. Sliding runs in the "
           "direction $s = \\operatorname{sign} v_1$. Applied forces $F_1$, $F_2$ act along the coordinates; a "
           "negative $F_2$ resists forward motion.")
    s.text("Reactions are defined alike for both bodies, $S_i = F_i - m_i \\ddot x_i$ (eq. 8): minus the contact "
           "force on body $i$ along its guide.")
    return s


def _kinematics() -> Section:
    k = M.kinematics()
    s = Section("Geometry and kinematic constraint (eq. 1)")
    s.text("Unit vectors of the contact line (seen from body 1) and of the flank-a normal (from body 1 into body 2):")
    s.math(f"\\mathbf t = {_l(M.TANGENT)}, \\qquad \\mathbf n = {_l(M.NORMAL)}")
    s.text("Non-penetration: the gap along the normal between the two bodies' reference points stays zero. "
           "Differentiated twice with respect to time:")
    s.math(f"g = {_l(k.gap)} = 0", _l(k.position), _l(k.velocity), _l(k.acceleration))
    s.text("Body 2 is slower than body 1 by $\\tan\\gamma$. The relative sliding speed along the contact line is")
    s.math(f"v_s = (\\dot{{\\mathbf r}}_2 - \\dot{{\\mathbf r}}_1)\\cdot\\mathbf t = {_l(k.sliding_speed * M.v1)}")
    return s


def _sliding_sections(flank_dirs) -> list[Section]:
    modes = [M.sliding(f, d) for f, d in flank_dirs]
    force = Section("Contact force and force transfer functions (eqs. 2, 3)")
    force.text("Contact resultant on body 2: $\\mathbf R = Q\\,(f\\cos\\rho\\,\\mathbf n - s\\sin\\rho\\,\\mathbf t)$, "
               "$Q = N/\\cos\\rho$; body 1 takes $-\\mathbf R$. The guides take the components across them, so")
    for m in modes:
        force.math(f"f={M.FLANK_SIGN[m.flank]:+d},\\ s={m.direction:+d}:\\quad R_1 = {_l(m.R1)}, \\quad R_2 = {_l(m.R2)}")
    force.text("With $S_i = -R_i$ the ratio of the reactions does not depend on $N$; SymPy's trigsimp gives the "
               "force transfer function $\\Psi = -S_1/S_2$:")
    force.table("llll", ["flank", "direction", "$\\Psi$", "regime"],
                [[FLANK_WORDS[m.flank], "forward" if m.direction > 0 else "backward", f"${_l(m.psi)}$",
                  "tractive" if (m.flank, m.direction) == ("a", 1) else
                  "inverse-tractive" if (m.flank, m.direction) == ("b", 1) else "reverse drive"] for m in modes])
    force.math("S_1 = -\\Psi\\, S_2")

    m = modes[0]
    eom = Section("Reduced equation of motion (eq. 6)")
    eom.text("Newton for each body, $S_1 = F_1 - m_1 a_1$, $S_2 = F_2 - m_2 a_2$, with $a_2 = a_1\\tan\\gamma$ "
             "and $S_1 = -\\Psi S_2$, solved for $a_1$:")
    eom.math(_eq(M.a1, m.accel_in_psi), f"D = {_l(sp.fraction(sp.together(m.accel_in_psi))[1])}")
    eom.text("Solving Newton's equations for $(a_1, Q)$ directly, without the FTF, gives the same $a_1$ (a test "
             "checks this for every flank and direction). The mode is consistent while $D > 0$; with $\\Psi < 0$ "
             "(self-locking) and a heavy body 2, $D \\le 0$: rigid contact with friction has no solution there "
             "(a Painleve-type case), which tswm reports instead of integrating through.")

    reac = Section("Reactions (eqs. 8, 9) and the switching function (eq. 7)")
    reac.text("Substituting $a_1$ back:")
    reac.math(_eq(M.S1, sp.factor(m.S1.subs(m.psi, M.Psi))), _eq(M.S2, sp.factor(m.S2.subs(m.psi, M.Psi))))
    reac.text("Both reactions are proportional to one function that does not depend on $\\Psi$ (so it is the "
              "same for both flanks):")
    reac.math(f"\\varphi = {_l(m.switching)}",
              "S_2 = -\\frac{m_1 m_2\\,\\varphi}{D}, \\qquad S_1 = \\Psi\\,\\frac{m_1 m_2\\,\\varphi}{D}")
    reac.text("$\\varphi$ is body 1's own acceleration mapped onto $x_2$ minus body 2's own acceleration: the "
              "residual of the acceleration constraint when each body is left to its own force. It is zero "
              "exactly when $S_1 = S_2 = 0$. The normal force follows from $R_2$:")
    for mm in modes:
        reac.math(f"f={M.FLANK_SIGN[mm.flank]:+d},\\ s={mm.direction:+d}:\\quad N = {_l(mm.normal)}")
    reac.text("So, while $D > 0$ and $\\cos(\\gamma + f s\\rho) > 0$ (else the wedge jams), flank a carries the "
              "load for $\\varphi \\ge 0$ and flank b for $\\varphi < 0$.")
    kink = sp.factor(m.accel_in_psi - M.F1 / M.m1)
    reac.text("Continuity at the flank switch: both flanks give the same acceleration on $\\varphi = 0$, "
              "because")
    reac.math(f"a_1 - \\frac{{F_1}}{{m_1}} = {_l(kink)} = -\\frac{{\\Psi m_2\\,\\varphi}}{{D}}")
    reac.text("vanishes there for any $\\Psi$. The flank switch is a kink in the right-hand side, not a jump; the "
              "genuine discontinuity is at $v_1 = 0$, where friction reverses.")

    power = Section("Power balance and efficiency")
    power.text("The contact absorbs $P = -(R_1 v_1 + R_2 v_2)$. From the force balance, and from Coulomb's law "
               "directly (friction force times sliding speed):")
    for mm in modes:
        power.math(f"f={M.FLANK_SIGN[mm.flank]:+d},\\ s={mm.direction:+d}:\\quad P = {_l(mm.friction_power)} "
                   f"= {_l(mm.friction_power_coulomb)} \\ge 0")
    power.text("Efficiency of the tractive mode (power into body 2 over power out of body 1):")
    power.math(f"\\eta = {_l(M.sliding('a', 1).efficiency)}")
    return [force, eom, reac, power]


def _stick_section() -> Section:
    st = M.stick()
    s = Section("Stick and breakaway")
    s.text("At $v_1 = 0$ with both bodies at rest the contact force on body 2 is $f N\\,\\mathbf n - T\\,\\mathbf t$. "
           "Statics gives")
    s.math(f"f N = {_l(st.normal_times_flank)}, \\qquad T = {_l(st.tangential)}")
    s.text("and $S_1 = F_1$, $S_2 = F_2$. The bodies stay stuck while $|T| \\le \\tan\\rho_0\\,|fN|$ with the "
           "friction angle at zero speed $\\rho_0$:")
    s.math(f"{_l(st.cone_forward)} \\ge 0", f"{_l(st.cone_backward)} \\ge 0")
    s.text("When the first condition fails the drive breaks away forward, when the second fails backward; the "
           "sign of $fN$ tells which flank holds.")
    return s


def _clearance_sections(model: Model) -> list[Section]:
    """Free flight, separation, the impact law and its energy, for a scene with a clearance."""
    ff = M.free_flight()
    fly = Section("Clearance and free flight")
    fly.text("With a clearance $c$ between the flanks along the normal, the normal gap from flank a, $g$, is a "
             "state of its own: flank a touches at $g = 0$, flank b at $g = c$. From the positions of both "
             "bodies, and back:")
    fly.math(f"g = {_l(M.kinematics().gap)}, \\qquad x_2 = {_l(ff.x2_of)}, \\qquad v_2 = {_l(ff.v2_of)}")
    fly.text("When neither flank touches, each body moves under its own force:")
    fly.math(_eq(M.a1, ff.accel1), _eq(M.a2, ff.accel2),
             f"\\ddot g = {_l(ff.gap_accel)} = {_l(ff.gap_accel_phi)}")
    fly.text("So the gap's acceleration in free flight is $-\\cos\\gamma$ times the switching function. On a "
             "flank the normal force is proportional to $\\varphi$ (section on reactions): flank a holds while "
             "$\\varphi \\ge 0$, which is exactly when free flight would press the bodies together "
             "($\\ddot g \\le 0$). Separation is therefore the zero crossing of $\\varphi$: the normal force "
             "reaches 0 and the own accelerations pull the flanks apart with zero relative speed. In contact the "
             "gap and its rate stay constant ($\\dot g = 0$, $\\ddot g = 0$). A clearance of zero lets the "
             "flanks part and meet at once: the zero-clearance model.")
    if any(m.mesh for m in model.modes):
        return [fly, _mesh_section()]
    law = Section("Impact law and energy")
    frame = M.impact_frame("a")
    law.text("When the gap closes on flank $f$ with approach speed $\\nu = f\\,\\dot g < 0$, an impulse "
             "$\\mathbf P = P_n f\\,\\mathbf n + P_t\\,\\mathbf t$ acts on body 2 and $-\\mathbf P$ on body 1; the "
             "guides take the rest. The velocity jumps, and the relative velocity $u = (\\nu, s)$ in the flank's "
             "frame ($s$ the slip along $\\mathbf t$) changes by $W\\mathbf P$:")
    law.math(f"\\Delta v_1 = {_l(frame.jump_v1)}, \\qquad \\Delta v_2 = {_l(frame.jump_v2)}",
             f"W = {_l(frame.W)}")
    law.text("(for flank a; flank b flips the sign of $W_{nt}$). The impulse grows with $P_n$ (Routh's process). "
             "While the slip has a direction $\\sigma$, Coulomb's law gives $dP_t = -\\mu\\sigma\\,dP_n$ with "
             "$\\mu = \\tan\\rho$ of the flank at the impact; when the slip stops it stays zero if the stick ratio "
             "$|W_{nt}|/W_{tt} \\le \\mu$ (the impulse stays in the friction cone), else it reverses. Compression "
             "ends at $\\nu = 0$; restitution ends when the normal impulse has returned $e^2$ of the work done on "
             "it in compression (the energetic coefficient). While the slip keeps one direction this is Newton's "
             "law $\\nu^+ = -e\\,\\nu^-$. Where the slip stops inside the impact, Newton's law with a stick impulse "
             "loses the energy")
    law.math(f"\\Delta K = {_l(sp.factor(frame.newton_stick_loss))}")
    law.text("which is negative for some approach: Newton's law would create energy (the test suite shows one at "
             "the paper gear's masses). The energetic form never does: the normal impulse does "
             "$(1 - e^2)$ times the compression work ($\\le 0$), and friction works against the slip ($\\le 0$), "
             "so the kinetic energy lost is never negative; it is reported with each impact. If "
             "$W_{nn} - \\mu\\sigma W_{nt} \\le 0$ the sliding impulse cannot stop the approach: the impact has "
             "no solution (the impulsive counterpart of $D \\le 0$) and the run stops as inconsistent.")
    law.text("After an impact the flanks stay together (persistent contact) when the rebound speed is within the "
             "velocity tolerance or when the next bounce, under the present free-flight acceleration, would rise "
             "less than the gap's tolerance above the flank: every later bounce is smaller still, so this ends a "
             "sequence of bounces at its accumulation point instead of following it into ever smaller steps.")
    return [fly, law]


def _lost_motion_section() -> Section:
    """The stem: held, struck, flying on its own or carried; the pickup impulse through the wedge."""
    pk = M.pickup()
    s = Section("Lost motion: picking up the stem")
    s.text("Body 2 runs free over the travel $L$ before it reaches the stem (body 3, mass $m_3$, on body 2's "
           "guide, resting until then); $x_3$ is the stem's travel from rest, $v_3$ its speed, and the gap "
           "between them is $L + x_3 - x_2$. The load acts on the stem from the first pickup on. While body 2 "
           "carries the stem, the load $F_2$ and the mass $m_3$ act on body 2 in every mode; apart, the stem "
           "moves under $\\dot v_3 = F_2/m_3$. Newton for the carried stem, $m_3 a_2 = F_2 + N_3$, with body 2's "
           "reaction $S_2 = F_2 - (m_2 + m_3) a_2$, gives the contact force")
    s.math(_eq(M.N3, pk.stem_force.subs(M.F3, M.F2)))
    s.text("and the stem leaves body 2 where it falls to 0. At the pickup an impulse $P$ acts on the stem and "
           "$-P$ on body 2; the wedge passes it on like a force, with the resultant impulse leaning by $\\rho$ "
           "against the slip of the direction $s$ it slides in (flank a carries it). The impulse balance of "
           "worm and wheel gives")
    s.math(*(f"\\frac{{d v_1}}{{d P}}\\Big|_{{s = {d}}} = {_l(pk.jump_v1[d])}" for d in (1, -1)))
    s.text("(the sliding modes' $a_1$ for $F_1 = 0$, $F_2 = -1$), and $d(v_3 - v_2)/dP = 1/m_3 - "
           "\\tan\\gamma\\, dv_1/dP$. Where $v_1$ reaches 0 inside the impulse, the wedge locks if the statics of "
           "the impulse alone stay inside both friction cones,")
    s.math(f"{_l(pk.cone_forward)} \\ge 0, \\qquad {_l(pk.cone_backward)} \\ge 0,")
    s.text("that is if it is self-locking, and slides back otherwise. Compression ends at $v_3 = v_2$, and "
           "restitution returns $e^2$ of the compression work, as for the flanks. The loss is the drop of "
           "the kinetic energy $J v_1^2/2 + m_3 v_3^2/2$ with")
    s.math(f"J = {_l(pk.inertia)}.")
    s.text("A rebound within the tolerances is taken as plastic: body 2 carries the stem from then on, which ends "
           "a sequence of bounces at its accumulation point with the momentum kept.")
    return s


def _mesh_section() -> Section:
    """Compliant flanks: the spring-damper normal force, sliding and stick in contact."""
    slide, stick = M.mesh_contact("a", 1), M.mesh_contact("a", 0)
    s = Section("Compliant flanks")
    s.text("The flanks may overlap; on flank a the overlap is $-g$ (on flank b, $g - c$) and the mesh pushes "
           "back along the normal like a spring and damper, with Coulomb friction against the slip "
           "$s = v_1\\cos\\gamma + v_2\\sin\\gamma$ (sliding forward, flank a):")
    s.math(f"N = {_l(slide.normal)}, \\qquad T = {_l(slide.tangential)}",
           _eq(M.a1, slide.accel1), f"\\ddot g = {_l(slide.gap_accel)}")
    s.text("In stick the slip stays zero and the tangential force follows from the balance; the stick holds "
           "while it stays inside the friction cone:")
    s.math(f"T = {_l(stick.tangential)}", f"{_l(stick.cone_forward)} \\ge 0, \\qquad "
           f"{_l(stick.cone_backward)} \\ge 0")
    s.text("A contact ends where $N$ falls to zero (with damping before the overlap does) and begins where the "
           "gap closes, without an impulse. As the stiffness grows with the damping ratio held, the contact "
           "time shrinks like $1/\\sqrt{k}$ and the motion tends to that of rigid impacts with the "
           "spring-damper's restitution, while the peak force grows like $\\sqrt{k}$.")
    return s


def _laws_section(model: Model) -> Section:
    s = Section(f"Laws of scene `{model.scene.name}`")
    params = {p.name: p for p in model.scene.params()}
    for q in model.laws:
        if q.expr == q.symbol and q.symbol.name in params:   # a constant law: the parameter itself
            p = params[q.symbol.name]
            kind = f"free, default {p.value:g} {p.unit}" if p.free else f"fixed, {p.value:g} {p.unit}"
            s.text(f"{q.doc}: ${_l(q.symbol)}$ is the scene parameter `{p.name}` ({kind.rstrip()}).")
            continue
        s.text(q.doc + ":")
        s.math(_eq(q.symbol, q.expr))
    if model.scene.drive.kind == "kloss":
        s.text("The Kloss curve $2F_{max}/(s/s_{max} + s_{max}/s)$ is singular at synchronous speed ($s = 0$); "
               "brought over a common denominator, as above, it is regular there.")
    for pieces in model.pieces:
        s.text(f"The law is piecewise: ${_l(pieces.symbol)}$ is its {pieces.doc} ({pieces.count} pieces). The "
               "runtime latches it at the start and after each event of the law, so inside a segment the law is "
               "one smooth piece and no integration step sees it jump.")
        if pieces.schedule is not None:
            _schedule_text(s, pieces.schedule)
        e = pieces.event
        s.text(f"Event `{e.name}`: {e.doc}, where ${_l(e.expr)}$ falls through zero: it is $\\ge 0$ while the state "
               "lies in the latched piece, and the runtime latches the piece in which it is $\\ge 0$ again.")
    for latch in model.latches:
        s.text(f"Latch ${_l(latch.symbol)}$: {latch.doc}. While ${_l(latch.armed)}$ the guard ${_l(latch.guard)}$ "
               f"($S_1$ of the current mode) is watched; ${_l(latch.symbol)}$ is $+\\infty$ until it falls through "
               "zero, and that time from then on.")
    return s


def _schedule_text(s: Section, schedule) -> None:
    """What the schedule's piece symbols are: entries of its arrays at the latched piece."""
    lower, upper, level, slope, origin = (f"${_l(x)}$" for x in schedule.piece_symbols)
    at, values = (f"${_l(param_symbol(e[0]))}, \\dots, {_l(param_symbol(e[-1]))}$" if len(e) > 1
                  else f"${_l(param_symbol(e[0]))}$" for e in (schedule.breakpoints, schedule.values))
    s.text(f"The {schedule.owner} schedule's {len(schedule.breakpoints)} breakpoints ({at}) and "
           f"{len(schedule.values)} values ({values}) "
           f"are data, arrays of the generated module, not one expression per piece: {lower} and {upper} are the "
           f"breakpoints around the latched piece ($\\mp\\infty$ beyond the first and the last), {level} the force "
           f"at {origin} and {slope} its slope in the piece ({schedule.shape}: "
           + ("the piece's value, slope 0)." if schedule.shape == "steps" else
              "the line between the values at the two breakpoints, slope 0 before the first and after the last)."))


def _slide_mode(s: Section, mode) -> None:
    """Filippov's sliding mode along phi = 0: the rate of phi, the weight, a1 and the reactions."""
    declared = "declared by the scene" if mode.declared else "not declared by the scene: a run stops there"
    s.text(f"Mode `{mode.name}` ({mode.regime}; {declared}). The literal $a_1$ jumps across $\\varphi = 0$ (see the "
           "audit), so `fwd_a` ($\\varphi > 0$) and `fwd_b` ($\\varphi < 0$) can both push the state onto it. "
           "Along a mode with acceleration $a_1$, with the laws composed into $\\varphi$:")
    s.math(f"\\dot\\varphi = {_l(mode.slide.rate)}")
    s.text("With $\\dot\\varphi_a$, $\\dot\\varphi_b$ the rates along `fwd_a` and `fwd_b`, the state slides while "
           "$\\dot\\varphi_a < 0 < \\dot\\varphi_b$, on Filippov's convex combination, which keeps "
           "$\\dot\\varphi = 0$:")
    s.math("\\lambda = \\frac{\\dot\\varphi_b}{\\dot\\varphi_b - \\dot\\varphi_a}, \\qquad "
           "S_i = \\lambda S_{i,a} + (1 - \\lambda) S_{i,b}",
           f"a_1 = \\lambda a_{{1,a}} + (1 - \\lambda) a_{{1,b}} = {_l(mode.accel)}")


def _modes_section(model: Model) -> Section:
    s = Section(f"Modes of scene `{model.scene.name}`")
    s.text(f"Equations: {model.scene.equations}. States: " + ", ".join(f"${_l(x)}$" for x in model.states) + ".")
    s.math(f"\\varphi = {_l(model.switching)}")
    for mode in model.modes:
        if mode.slide is not None:
            _slide_mode(s, mode)
            continue
        s.text(f"Mode `{mode.name}` ({mode.regime}):")
        s.math(_eq(M.a1, mode.accel), _eq(M.S1, mode.S1), _eq(M.S2, mode.S2))
    if model.stick is not None:
        s.text("Stick conditions:")
        s.math(f"{_l(model.stick.cone_forward)} \\ge 0", f"{_l(model.stick.cone_backward)} \\ge 0")
    return s


def _load_factor_section() -> Section:
    s = Section("Dynamic load factors (eq. 10)")
    s.text("With the largest reactions $S_i^m$ over a run and the static tangential forces $F_{t1}$, $F_{t2}$:")
    s.math("K_{D1} = \\frac{|S_1^m|}{F_{t1}}, \\qquad K_{D2} = \\frac{|S_2^m|}{F_{t2}}")
    return s


def _audit_section() -> Section:
    entries = audit.audit()
    s = Section("Audit of the printed equations")
    s.text("Each printed equation of the paper against the derivation. \"checked\" means SymPy verified the "
           "agreement, or that the stated change turns one form into the other.")
    s.table("lllp{7.5cm}", ["eq.", "verdict", "checked", "reconciliation"],
            [[e.equation, "agrees" if e.agrees else "differs", "yes" if e.checked else "no", e.reconciliation]
             for e in entries])
    for e in entries:
        s.text(f"Eq. {e.equation}, {e.topic}: printed, then derived.")
        s.math(e.printed, e.derived)
    s.text("The literal equations jump across their own switching surface (printed $\\varphi = 0$) by")
    s.math(f"\\Delta a_1 = {_l(audit.literal_jump())}")
    s.text("which is nonzero whenever $\\rho > 0$: the printed model has a genuine discontinuity there and can "
           "slide along it (Filippov), unlike the consistent model.")
    s.text("Data remarks: \"$V_0 = \\omega_0/R_1^2$\" reads $\\omega_0 R_1 = 314.16 \\cdot 0.025 = 7.85$ m/s; "
           "\"$F_{t2} = 2T_1 u\\gamma/d_2$\" uses the efficiency $\\eta = 0.67$ where it prints $\\gamma$.")
    return s


def build_document(model: Model) -> dict:
    """Title, parameter table and sections of the derivation of ``model``'s scene."""
    scene = model.scene
    flank_dirs = [(f, d) for d in (1, -1) for f in ("a", "b")]
    sections = [_assumptions(), _kinematics(), *_sliding_sections(flank_dirs), _stick_section(),
                *(_clearance_sections(model) if model.clearance is not None else []),
                *([_lost_motion_section()] if model.pickup else []),
                _load_factor_section(), _laws_section(model), _modes_section(model), _audit_section()]
    params = [[f"`{p.name}`", f"{p.value:.6g}", p.unit,
               "free" if p.free else "fixed"] for p in scene.params()]
    return {"title": f"Derivation of the wedge model for scene `{scene.name}`",
            "description": scene.description, "source": scene.source, "digest": scene.digest,
            "params": params, "sections": sections}


_MATH_OR_CODE = re.compile(r"(\$[^$]*\$|`[^`]*`)")
# Every character TeX gives a meaning to, for text that came from a scene file: nothing in it is markup.
_TEX_LITERAL = str.maketrans({**{c: "\\" + c for c in "&%#_{}$"}, "\\": "\\textbackslash{}",
                              "^": "\\textasciicircum{}", "~": "\\textasciitilde{}",
                              "<": "\\textless{}", ">": "\\textgreater{}", "|": "\\textbar{}"})
_MARKDOWN_SPECIAL = re.compile(r"([\\`*_\[\]<>#|$~&])")


def _plain(text: str) -> str:
    """Scene text on one line: control characters (line breaks, NUL, ...) become spaces."""
    return "".join(c if c.isprintable() else " " for c in str(text))


def latex_literal(text: str) -> str:
    """Text from a scene (its description, its file's path) as inert LaTeX: every special escaped."""
    return _plain(text).translate(_TEX_LITERAL)


def markdown_literal(text: str) -> str:
    """Text from a scene as inert Markdown: every character Markdown, HTML or $math$ reads is escaped."""
    return _MARKDOWN_SPECIAL.sub(r"\\\1", _plain(text))


def latex_prose(text: str) -> str:
    """Prose with $math$ and `code` as LaTeX: escape specials outside math, typeset code."""
    out = []
    for part in _MATH_OR_CODE.split(text):
        if part.startswith("$"):
            out.append(part)
        elif part.startswith("`"):
            out.append("\\texttt{" + latex_literal(part[1:-1]) + "}")
        else:
            out.append(re.sub(r'"([^"]*)"', r"``\1''", latex_literal(part)))
    return "".join(out)


def _environment(target: str) -> jinja2.Environment:
    loader = jinja2.FileSystemLoader(str(resources.files("derivation") / "templates"))
    options = dict(loader=loader, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    if target == "latex":
        env = jinja2.Environment(block_start_string="((*", block_end_string="*))", variable_start_string="(((",
                                 variable_end_string=")))", comment_start_string="((#", comment_end_string="#))",
                                 **options)
        env.filters["prose"] = latex_prose
        env.filters["literal"] = latex_literal
    else:
        env = jinja2.Environment(**options)
        env.filters["prose"] = lambda text: text
        env.filters["literal"] = markdown_literal
    return env


def render(doc: dict, target: str) -> str:
    """The document as a standalone LaTeX file or as Markdown with $$ math blocks."""
    name = {"latex": "derivation.tex.j2", "markdown": "derivation.md.j2"}[target]
    return _environment(target).get_template(name).render(**doc)


def write_documents(model: Model, *, latex=None, markdown=None, pdf=None) -> list[Path]:
    """Write the document of ``model`` as Markdown, LaTeX and a PDF (``pdf``: a path, or True for
    the LaTeX file's name, else SCENE-derivation.pdf; needs pdflatex); the paths written."""
    if not (latex or markdown or pdf):
        return []
    return write_built(build_document(model), model.scene.name, latex=latex, markdown=markdown, pdf=pdf)


def write_built(doc: dict, name: str, *, latex=None, markdown=None, pdf=None) -> list[Path]:
    """Write a built document (``build_document``'s shape) for scene ``name``; see write_documents."""
    from derivation.latex import build_pdf
    from tswm_common.files import write_atomic

    written = []
    if markdown:
        written.append(write_atomic(markdown, render(doc, "markdown")))
    if latex or pdf:
        tex = render(doc, "latex")
        if latex:
            written.append(write_atomic(latex, tex))
        if pdf:
            target = Path(pdf if not isinstance(pdf, bool) else (latex or f"{name}-derivation.tex"))
            written.append(build_pdf(tex, target.with_suffix(".pdf")))
    return written
