"""Stage kinds as equivalent wedges: slope gamma, friction angle rho, levers of input and output.

A stage joins an input body (coordinate q_in) and an output body (q_out). Its wedge moves
x1 = lever_in q_in and x2 = lever_out q_out (lever: a pitch radius for a rotation, 1 for a
translation), so a generalized force Q on a body is Q / lever on the wedge and an inertia J is
J / lever^2. A helical flank (worm thread, screw thread) is tilted out of the wedge plane; the
bearings take the out-of-plane part of its force, and the in-plane part leans by an effective
friction angle derived below from the 3-D flank normal (Coulomb friction along the sliding
direction, which lies in the plane of motion).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from derivation import mechanics as mech

E3 = sp.Matrix([0, 0, 1])                     # out of the wedge plane (radial)
mu = sp.Symbol("mu", nonnegative=True)        # Coulomb coefficient on the real flank
alpha_n = sp.Symbol("alpha_n", positive=True)  # normal pressure angle (worm), in the normal section
alpha_ax = sp.Symbol("alpha", positive=True)  # thread flank angle in the axial section (screw)
lead, d_m = sp.symbols("L d_m", positive=True)  # screw lead and mean diameter
r_worm, r_wheel = sp.symbols("r_1 r_2", positive=True)  # pitch radii of worm and wheel

ROTATION, TRANSLATION = "rotation", "translation"


def _in_space(vector: sp.Matrix) -> sp.Matrix:
    """A vector of the wedge plane (mechanics' frame) in 3-D."""
    return sp.Matrix([vector[0], vector[1], 0])


@dataclass(frozen=True)
class Kind:
    """How a stage kind becomes a wedge: its slope, the 3-D normal of its flank, its levers and motions."""

    name: str
    slope: sp.Expr              # tan(gamma)
    flank_normal: sp.Matrix     # 3-D normal of the flank (any length), at gamma = atan(slope)
    lever_in: sp.Expr
    lever_out: sp.Expr
    motion_in: str
    motion_out: str
    keys: dict[str, sp.Symbol]  # the scene keys of the kind and the symbols they give values


def kinds() -> dict[str, Kind]:
    """The stage kinds: a plain wedge, a worm gear (worm -> wheel), a power screw (nut -> stem)."""
    normal, tangent = _in_space(mech.NORMAL), _in_space(mech.TANGENT)
    worm_normal = sp.cos(alpha_n) * normal + sp.sin(alpha_n) * E3        # tilted about the contact line
    axial_profile = sp.Matrix([0, sp.sin(alpha_ax), sp.cos(alpha_ax)])   # axial section: x2 and radial
    screw_normal = tangent.cross(axial_profile)                          # the flank holds both lines
    return {
        "wedge": Kind("wedge", sp.tan(mech.gamma), normal, sp.Integer(1), sp.Integer(1), TRANSLATION, TRANSLATION,
                      {"gamma": mech.gamma, "mu": mu}),
        "worm_gear": Kind("worm_gear", sp.tan(mech.gamma), worm_normal, r_worm, r_wheel, ROTATION, ROTATION,
                          {"lead_angle": mech.gamma, "pressure_angle": alpha_n, "worm_radius": r_worm,
                           "wheel_radius": r_wheel, "mu": mu}),
        "power_screw": Kind("power_screw", lead / (sp.pi * d_m), screw_normal, d_m / 2, sp.Integer(1),
                            ROTATION, TRANSLATION, {"lead": lead, "flank_angle": alpha_ax, "mean_diameter": d_m,
                                                    "mu": mu}),
    }


@dataclass(frozen=True)
class EquivalentWedge:
    """A stage kind's wedge: tan(gamma), tan(rho) and the transmission ratio q_in' / q_out'."""

    kind: str
    tan_gamma: sp.Expr
    tan_rho: sp.Expr            # effective friction: mu over the in-plane share of the flank normal
    ratio: sp.Expr
    lever_in: sp.Expr
    lever_out: sp.Expr
    normal_share: sp.Expr       # in-plane normal part of the unit flank normal: cos(alpha_n)


@lru_cache(maxsize=None)
def equivalent_wedge(name: str) -> EquivalentWedge:
    """Resolve the flank force N n + mu N (along the sliding) into the wedge plane and read off rho'.

    In the plane the force is N |n_plane| NORMAL -+ mu N TANGENT, the force of a plane wedge with
    normal force N' = N |n_plane| and friction coefficient mu N / N' = mu / |n_plane|."""
    kind = kinds()[name]
    unit_normal = kind.flank_normal / kind.flank_normal.norm()
    force = unit_normal + mu * _in_space(mech.TANGENT)                 # N = 1, friction mu N along the slip
    at_slope = {mech.gamma: sp.atan(kind.slope)}
    plane_normal = sp.simplify(force.dot(_in_space(mech.NORMAL)).subs(at_slope))
    plane_tangent = sp.simplify(force.dot(_in_space(mech.TANGENT)).subs(at_slope))
    ratio = sp.simplify(kind.lever_out / (kind.lever_in * kind.slope))
    return EquivalentWedge(name, sp.simplify(kind.slope), sp.simplify(plane_tangent / plane_normal), ratio,
                           kind.lever_in, kind.lever_out, plane_normal)
