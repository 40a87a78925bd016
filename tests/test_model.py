"""Scene-specialised models: modes, laws, states, and variants that must reduce to each other."""
import math

import pytest
import sympy as sp

from derivation import laws, mechanics as M, paper
from derivation.model import T_TRIP, build_model, compose_laws, switching_rate
from derivation.scene import load_scene, parse_scene

BASE = """
name = "variant"
[wedge]
flanks = {flanks}
gamma = "6 deg"
m1 = "3 kg"
m2 = "40 kg"
{friction}
[drive]
law = "constant"
F1 = "400 N"
[load]
law = "constant"
F2 = "-900 N"
[modes]
include = ["forward", "backward", "stick"]
"""
SHARED = '[friction]\nlaw = "constant"\nrho = "4 deg"'
PER_FLANK = '[friction.a]\nlaw = "constant"\nrho = "4 deg"\n[friction.b]\nlaw = "constant"\nrho = "{rho_b}"'


def variant(flanks='["a", "b"]', friction=SHARED):
    return build_model(parse_scene(BASE.format(flanks=flanks, friction=friction)))


def test_paper_model_modes_states_and_laws():
    model = build_model(load_scene("paper"))
    assert [m.name for m in model.modes] == ["fwd_a", "fwd_b", "stick"]
    assert model.states == (M.v1,)                      # no law reads x1: position by quadrature
    assert [q.symbol for q in model.laws] == [M.F1, M.F2, sp.Symbol("rho", real=True)]
    assert model.mode("fwd_a").regime == "tractive" and model.mode("fwd_b").regime == "inverse-tractive"


def test_spring_load_adds_position_state_and_event():
    model = build_model(load_scene("one-sided"))
    assert model.states == (M.x1, M.v1)
    assert [e.name for e in model.events] == ["load_contact"]


@pytest.mark.parametrize("flank", ["a", "b"])
def test_one_sided_reduces_to_two_sided(flank):
    one, two = variant(flanks=f'["{flank}"]'), variant()
    for word in ("fwd", "bwd"):
        a, b = one.mode(f"{word}_{flank}"), two.mode(f"{word}_{flank}")
        assert sp.simplify(a.accel - b.accel) == 0 and sp.simplify(a.S2 - b.S2) == 0
    assert [m.name for m in one.modes] == [f"fwd_{flank}", f"bwd_{flank}", "stick"]


def test_asymmetric_reduces_to_symmetric_when_frictions_coincide():
    asym, sym = variant(friction=PER_FLANK.format(rho_b="4 deg")), variant()
    rho, rho_a, rho_b = (sp.Symbol(n, real=True) for n in ("rho", "rho_a", "rho_b"))
    same = {rho_a: rho, rho_b: rho}
    for mode in sym.modes:
        other = asym.mode(mode.name)
        for field in ("accel", "S1", "S2"):
            assert sp.simplify(getattr(other, field).subs(same) - getattr(mode, field)) == 0
    assert sp.simplify(asym.stick.cone_forward.subs(same) - sym.stick.cone_forward) == 0
    laws_by_symbol = {q.symbol: q.expr for q in asym.laws}
    assert laws_by_symbol[rho_a] == laws_by_symbol[rho_b].subs(sp.Symbol("friction_b_rho", real=True),
                                                              sp.Symbol("friction_a_rho", real=True))


def test_asymmetric_stick_uses_the_holding_flanks_friction():
    asym = variant(friction=PER_FLANK.format(rho_b="9 deg"))
    rho_a, rho_b = sp.Symbol("rho_a", real=True), sp.Symbol("rho_b", real=True)
    cone = asym.stick.cone_forward
    holds_on_b = {M.F1: 0, M.F2: 100, sp.Symbol("gamma", real=True): 0.1, rho_a: 0.05, rho_b: 0.2}
    assert float(cone.subs(holds_on_b)) == pytest.approx(math.tan(0.2) * 100 * math.cos(0.1) - 100 * math.sin(0.1))


def test_literal_model_is_the_printed_equations():
    model = build_model(load_scene("paper-literal"))
    g, rho, m1, m2 = (sp.Symbol(n, real=True) for n in ("gamma", "rho", "m1", "m2"))
    for name, psi in (("fwd_a", sp.tan(g + rho)), ("fwd_b", sp.tan(g - rho))):
        mode = model.mode(name)
        printed = (M.F1 - M.F2 * psi) / (m1 - m2 * psi * sp.tan(g))
        assert sp.simplify(mode.accel - printed) == 0
        assert sp.simplify(mode.S2 - (M.F1 - m1 * printed) / psi) == 0
    assert sp.simplify(model.switching - (M.F1 / m1 - M.F2 / m2 * sp.tan(g))) == 0
    assert model.stick is None


def test_kloss_safe_form_equals_textbook_and_is_regular_at_synchronous_speed():
    scene = load_scene("paper")
    from derivation.model import param_symbol
    safe, pieces = laws.drive_force(scene.drive, param_symbol, sp.Symbol("x2", real=True))
    assert pieces is None
    Fmax, V0, Vmax = (param_symbol(scene.drive.params[k]) for k in ("Fmax", "V0", "Vmax"))
    textbook = laws.kloss_textbook(Fmax, V0 - M.v1, V0 - Vmax)
    assert sp.simplify(safe - textbook) == 0
    values = {Fmax: 2178.0, V0: 7.85, Vmax: 6.5}
    assert float(safe.subs(values).subs(M.v1, 7.85)) == 0.0
    with pytest.raises(ZeroDivisionError):             # float arithmetic of the printed form
        sp.lambdify(M.v1, textbook.subs(values))(7.85)
    denominator = sp.fraction(sp.together(safe))[1]
    assert all(not root.is_real for root in sp.solve(denominator.subs(values), M.v1))
    assert float(safe.subs(values).subs(M.v1, 6.5)) == pytest.approx(2178.0)   # peak at Vmax


def test_velocity_friction_law_in_degrees():
    scene = load_scene("paper")
    from derivation.model import param_symbol
    rho = laws.friction_angle(scene.friction["a"], param_symbol, param_symbol(scene.gamma["a"]))
    values = {param_symbol(p): p.value for p in scene.params()}
    assert math.degrees(float(rho.subs(values).subs(M.v1, 0))) == pytest.approx(1 / 0.088)
    v = 6.5
    expected = 1 / (0.161 * (v / math.cos(math.radians(4.76))) ** 0.535 + 0.088)
    assert math.degrees(float(rho.subs(values).subs(M.v1, -v))) == pytest.approx(expected)


def test_step_load_is_piecewise_in_its_latched_piece_with_one_event_in_that_piece():
    model = build_model(load_scene("asymmetric"))
    F2 = {q.symbol: q.expr for q in model.laws}[M.F2]
    t_step, piece = sp.Symbol("t_step", real=True), sp.Symbol("load_piece", real=True)
    assert M.t not in F2.free_symbols   # no jump in t inside a segment: the piece is latched
    assert F2.subs(piece, 0) == sp.Symbol("F2_before", real=True)
    assert F2.subs(piece, 1) == sp.Symbol("F2_after", real=True)
    assert [p.symbol for p in model.pieces] == [piece]
    # the event: how far t lies inside the latched piece (t_step - t before the step, t - t_step after)
    (event,) = model.events
    assert event.name == "load_step" and [p.count for p in model.pieces] == [2]
    assert event.expr.subs(piece, 0) == t_step - M.t and event.expr.subs(piece, 1) == M.t - t_step
    assert paper.PSI_TRACTIVE == sp.tan(M.gamma + M.rho)


def _rates(model):
    """d phi/dt along fwd_a and fwd_b, the laws composed in, from switching_rate."""
    composed = compose_laws(model.laws)
    rate = switching_rate(model.switching, composed)
    return [rate.subs(M.a1, model.mode(name).accel).subs(composed) for name in ("fwd_a", "fwd_b")]


def test_consistent_model_never_slides():
    """At phi = 0 both flanks give the same d phi/dt, so no sliding mode is needed (or made)."""
    model = build_model(load_scene("paper"))
    assert all(m.slide is None for m in model.modes)
    m2, F2 = sp.Symbol("m2", real=True), sp.Symbol("F2", real=True)
    fixed = {sp.Symbol(p.name, real=True): p.value for p in model.params if p.name not in ("m2", "F2")}
    on_surface = sp.lambdify((M.v1, m2), sp.solve(model.switching.subs(compose_laws(model.laws)), F2)[0].subs(fixed))
    rate_a, rate_b = _rates(model)
    gap = sp.lambdify((M.v1, m2, F2), (rate_a - rate_b).subs(fixed))
    for v, mass in ((0.3, 100.0), (3.0, 200.0), (6.9, 300.0)):
        assert gap(v, mass, on_surface(v, mass)) == pytest.approx(0.0, abs=1e-9)
        assert abs(gap(v, mass, -15000.0)) > 1.0                # off the surface the rates differ


def test_literal_slide_mode_keeps_phi_and_combines_the_flanks():
    model = build_model(parse_scene(BASE.format(flanks='["a", "b"]', friction=SHARED).replace(
        'law = "constant"\nF1 = "400 N"', 'law = "linear"\nF0 = "400 N"\nV0 = "2 m/s"').replace(
        'law = "constant"\nF2 = "-900 N"', 'law = "spring"\nk = "1e5 N/m"\nx2_contact = "1 mm"\npreload = "10 N"'
    ).replace('["forward", "backward", "stick"]', '["forward", "sliding"]').replace(
        'name = "variant"', 'name = "variant"\nequations = "literal"')))
    slide = model.mode("slide_fwd")
    assert (slide.regime, slide.flank, slide.direction, slide.declared) == ("sliding along phi = 0", "", 1, True)
    composed = compose_laws(model.laws)
    # phi = F1/m1 - F2 tan(gamma)/m2 with F1 = F0 (1 - v1/V0), F2 = -(preload + k (x1 tan(gamma) - x2_contact))
    g, m1, m2, k, F0, V0 = 6 * math.pi / 180, 3.0, 40.0, 1e5, 400.0, 2.0
    point = {M.x1: 0.05, M.v1: 0.7}
    values = {**point, **{sp.Symbol(p.name, real=True): p.value for p in model.params},
              model.pieces[0].symbol: 1.0}   # x2 = 0.05 tan(6 deg) = 5.3 mm: the spring is pressed
    a_a, a_b, a_s = (float(model.mode(n).accel.subs(composed).subs(values)) for n in ("fwd_a", "fwd_b", "slide_fwd"))
    rate_a, rate_b = (-F0 / V0 / m1 * a + k * math.tan(g) ** 2 / m2 * 0.7 for a in (a_a, a_b))
    assert [float(r.subs(values)) for r in _rates(model)] == pytest.approx([rate_a, rate_b], rel=1e-12)
    lam = rate_b / (rate_b - rate_a)
    assert a_s == pytest.approx(lam * a_a + (1 - lam) * a_b, rel=1e-9)
    assert -F0 / V0 / m1 * a_s + k * math.tan(g) ** 2 / m2 * 0.7 == pytest.approx(0.0, abs=1e-9)   # d phi/dt = 0
    for field in ("S1", "S2"):
        a_val, b_val, s_val = (float(getattr(model.mode(n), field).subs(composed).subs(values))
                               for n in ("fwd_a", "fwd_b", "slide_fwd"))
        assert s_val == pytest.approx(lam * a_val + (1 - lam) * b_val, rel=1e-9)


def test_paper_literal_slides_at_constant_speed_undeclared():
    """Its phi depends on v1 alone, so d phi/dt = 0 needs a1 = 0."""
    model = build_model(load_scene("paper-literal"))
    assert [m.name for m in model.modes] == ["fwd_a", "fwd_b", "slide_fwd"]
    assert model.mode("slide_fwd").accel == 0 and not model.mode("slide_fwd").declared


def test_torque_switch_cuts_the_drive_for_good():
    model = build_model(load_scene("seating"))
    assert [latch.symbol for latch in model.latches] == [T_TRIP]
    F1 = compose_laws(model.laws)[M.F1]
    values = {sp.Symbol(p.name, real=True): p.value for p in model.params}
    slip = 7.85 - 2.0
    assert float(F1.subs(values).subs({M.v1: 2.0, M.t: 0.1, T_TRIP: 0.2})) == pytest.approx(
        2 * 2178 * slip * 1.35 / (slip ** 2 + 1.35 ** 2))
    assert F1.subs(values).subs({M.v1: 2.0, M.t: 0.3, T_TRIP: 0.2}) == 0
    assert F1.subs(values).subs({M.v1: 2.0, M.t: 0.3, T_TRIP: sp.oo}) != 0
    trip = model.latches[0]
    assert (trip.name, float(trip.guard.subs(values).subs(M.S1, 1600.0))) == ("torque_switch", -100.0)
    assert build_model(load_scene("paper")).latches == ()
