"""Every event exact: law breakpoints, the Painleve point, one-sided maxima, free values.

Expected values come from the independent quadrature reference (``quadrature``: the
force balance written by hand, solved by quadrature in v1 at 34 digits) or from scipy's
DOP853 at rtol 1e-13 on hand formulas (``tswm_runtime.reference.paper_gear``), never from tswm.
"""
import functools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tswm_runtime.reference import quadrature as q
from tswm_runtime.reference import paper_gear as gear
from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN, SimulationInputError, simulate

METHODS = ("dopri5", "rosenbrock23")
# tswm guard -> the reference's event kind
KIND = {"load_step": "load", "load_at1": "load", "load_at2": "load", "v1": "v1", "phi": "phi",
        "D": "D", "cone_forward": "breakaway", "cone_backward": "breakaway"}


def tolerances(rtols):
    """(method, rtol) for each method and rtol, or the method's tightest rtol where it accepts no
    tighter one (rosenbrock23 from 1e-9: simulate.METHOD_RTOL_MIN)."""
    return sorted({(m, max(r, METHOD_RTOL_MIN[m][0])) for m in METHODS for r in rtols})


@functools.lru_cache(maxsize=None)
def reference(m2, schedule, t_end):
    """The quadrature reference from rest, solved once per file for each (m2, schedule, t_end)
    (1 to 2 s each; the tolerance grids below share it)."""
    return q.solve(q.paper_wedge(m2), list(schedule), 0.0, t_end)


@functools.lru_cache(maxsize=None)
def extrema(m2, schedule, t_end):
    """``reference(...).S_extrema()``, computed once."""
    return reference(m2, schedule, t_end).S_extrema()


# --- the Painleve point: D -> 0+ on flank b, found in finite time ---------------------------

PAINLEVE = {"m2": 5000.0, "F2_after": 60000.0, "t_step": 0.04}


@pytest.fixture(scope="module")
def painleve_reference():
    tr = reference(5000.0, ((0.0, 0.0), (0.04, 60000.0)), 1.0)
    assert tr.status == "inconsistent" and tr.events[-1].kind == "D"
    return tr


@pytest.mark.parametrize("method, rtol", tolerances([1e-3, 1e-6, 1e-10]))
def test_painleve_point_is_a_located_event(method, rtol, painleve_reference):
    """After the load step the gear brakes on flank b with a self-locking FTF: D falls to 0
    at t* and a1 -> -inf (v1 - v* ~ sqrt(t* - t)). Integrating in t either stalls or steps
    across; tswm must stop there, at t*, as inconsistent, with unbounded reactions."""
    ref = painleve_reference
    t_star, v_star = float(ref.t_stop), float(ref.events[-1].v)
    r = simulate("paper-runup", PAINLEVE, method=method, rtol=rtol, atol=rtol * 1e-3)
    assert r.status == "inconsistent", r.message
    assert [(e.guard, e.from_mode, e.to_mode) for e in r.events] == [("load_step", "fwd_a", "fwd_b"),
                                                                    ("D", "fwd_b", None)]
    # rosenbrock23 carries its run-up error from rest (see the known-limit test below) here.
    assert abs(r.t_stop - t_star) <= (5 if method == "dopri5" else 250) * rtol * t_star
    assert r.events[-1].v1 == pytest.approx(v_star, rel=1e-6)
    # S1 = F1 - m1 a1 and S2 = F2 - m2 tan(gamma) a1 with a1 -> -inf: both +inf.
    assert r.S1_max == math.inf and r.S2_max == math.inf and r.KD1 == math.inf
    assert float(ref.S_extrema()["S1"][0]) == math.inf
    assert "fwd_b" in r.message and "m1 + m2*tan(gamma)*tan(gamma - rho)" in r.message
    assert "unbounded" in r.message


def test_painleve_output_rows_follow_the_reference(painleve_reference):
    """Output points inside the approach (solved in Sundman time) are on the trajectory."""
    t_star = float(painleve_reference.t_stop)
    r = simulate("paper-runup", PAINLEVE, rtol=1e-10, atol=1e-13, t_end=0.0405, points=8101)
    near = (r.t > 0.0402) & (r.t < t_star - 1e-7)
    assert near.sum() > 20
    v_ref = np.array([float(painleve_reference.v_at(t)) for t in r.t[near]])
    np.testing.assert_allclose(r.v1[near], v_ref, rtol=1e-7)


# --- each side of an event in its own mode and laws --------------------------------------

def test_reaction_maxima_are_attained_one_sided_limits():
    """m2 = 100 kg, F2 = +30 kN stepped on at 2 ms: the contact moves to flank b at the step
    and the gear brakes to rest. The largest |S1| is positive, at the stop; evaluating flank
    a's reaction with the new load at the step (-5480 N) mixes the two sides."""
    ref = reference(100.0, ((0.0, 0.0), (0.002, 30000.0)), 1.0)
    S = ref.S_extrema()
    r = simulate("paper-runup", {"m2": 100.0, "F2_after": 30000.0, "t_step": 0.002}, rtol=1e-8, atol=1e-11)
    assert [(e.guard, e.to_mode) for e in r.events] == [("load_step", "fwd_b"), ("v1", "stick")]
    for name, value, t in (("S1", r.S1_max, r.t_S1_max), ("S2", r.S2_max, r.t_S2_max)):
        # Both peak at the stop, where the state is v1 = 0 exactly (the located state lies
        # 1e-14 past it, and |S| ~ |v1|^0.535 there would cost 1e-7): exact to rounding.
        assert value == pytest.approx(float(S[name][0]), rel=1e-12), name
        assert t == pytest.approx(float(S[name][1]), abs=1e-9), name
    assert r.S1_max > 0


@pytest.mark.parametrize("method, rtol", tolerances([1e-4, 1e-6, 1e-8, 1e-10]))
def test_interior_reaction_maxima_are_located_between_steps(method, rtol):
    """A free run-up: |S1| and |S2| peak inside a step (at 0.0796 s and 0.0798 s), located on
    the dense output. S depends on v1 alone there, so the peak value is exact to rounding
    once the search finds the peak's v1; its time carries the run's own time error (< rtol s
    here, and sqrt(eps) relative is the floor for locating a flat maximum). At rtol 1e-4 the
    step ends lie 1e-3 relative below the peak: a search that stops at them fails."""
    S = extrema(200.0, ((0.0, 0.0),), 0.3)
    r = simulate("paper-runup", {"F2_after": 0.0}, method=method, rtol=rtol, atol=rtol * 1e-3, t_end=0.3)
    for name, value, t in (("S1", r.S1_max, r.t_S1_max), ("S2", r.S2_max, r.t_S2_max)):
        assert 0.07 < float(S[name][1]) < 0.09, name  # inside the run-up, not at an event
        assert value == pytest.approx(float(S[name][0]), rel=1e-12), name
        assert t == pytest.approx(float(S[name][1]), abs=max(rtol, 2e-9)), name


@pytest.mark.parametrize("method, rtol", tolerances([1e-3, 1e-6, 1e-8, 1e-10]))
def test_state_at_and_after_a_load_step_is_within_tolerance(method, rtol):
    """Run up free, -15 kN from 0.3 s: the load is latched per segment, so no step sees the
    jump; the state at the step and at t_end agree with the reference to the tolerance."""
    ref = reference(200.0, ((0.0, 0.0), (0.3, -15000.0)), 1.0)
    r = simulate("paper-runup", {"F2_after": -15000.0}, method=method, rtol=rtol, atol=rtol * 1e-3)
    assert [e.guard for e in r.events] == ["load_step"] and r.events[0].t == pytest.approx(0.3, abs=1e-15)
    assert r.events[0].v1 == pytest.approx(float(ref.v_at(0.3)), rel=2 * rtol)
    assert r.v1[-1] == pytest.approx(float(ref.v_at(1.0)), rel=2 * rtol)
    S = extrema(200.0, ((0.0, 0.0), (0.3, -15000.0)), 1.0)
    assert r.S2_max == pytest.approx(float(S["S2"][0]), rel=2 * rtol)


@pytest.mark.parametrize("rtol", [1e-3, 1e-6, 1e-8, 1e-10])
def test_early_load_step_state_with_dopri5(rtol):
    """A load step 50 ms into the run-up, while v1 still climbs fast: dopri5 within 2 rtol."""
    ref = reference(200.0, ((0.0, 0.0), (0.05, -5000.0)), 1.0)
    r = simulate("paper-runup", {"F2_after": -5000.0, "t_step": 0.05}, rtol=rtol, atol=rtol * 1e-3)
    assert r.events[0].v1 == pytest.approx(float(ref.v_at(0.05)), rel=2 * rtol)
    assert r.v1[-1] == pytest.approx(float(ref.v_at(1.0)), rel=2 * rtol)


@pytest.mark.parametrize("rtol", [1e-6, 1e-8, 1e-9])
def test_rosenbrock_run_up_from_rest_known_limit(rtol):
    """Known limit (docs/runtime.md): from rest the friction law is not Lipschitz (rho ~
    |v1|^0.535), the Jacobian is infinite at v1 = 0 and ode23s's error estimate misses the
    first steps' error; its global error in the run-up stays below 250 rtol (measured: 4x
    at 1e-6, 104x at 1e-10, a tolerance rosenbrock23 no longer accepts). This pins it, so a
    regression shows."""
    ref = reference(200.0, ((0.0, 0.0), (0.05, -5000.0)), 1.0)
    r = simulate("paper-runup", {"F2_after": -5000.0, "t_step": 0.05}, method="rosenbrock23", rtol=rtol,
                 atol=rtol * 1e-3)
    assert r.events[0].v1 == pytest.approx(float(ref.v_at(0.05)), rel=250 * rtol)


# --- schedules -------------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_load_schedule_in_time_stall_and_restart(method):
    """0 -> -30 kN at 0.3 s -> -2 kN at 0.6 s (scene load-schedule): the reference gives the
    events (load, stop and stick, load, breakaway) and the speed at t_end."""
    ref = reference(200.0, ((0.0, 0.0), (0.3, -30000.0), (0.6, -2000.0)), 1.0)
    r = simulate("load-schedule", method=method, rtol=1e-9, atol=1e-12)
    assert r.status == "finished", r.message
    # A load event that leaves stick is what the reference calls a breakaway.
    got = [("breakaway" if e.from_mode == "stick" != e.to_mode else KIND[e.guard], e.to_mode) for e in r.events]
    want = [(e.kind, e.mode_after) for e in ref.events]
    assert got == want
    for e, re in zip(r.events, ref.events):
        assert e.t == pytest.approx(float(re.t), rel=1e-7, abs=1e-12), e
        assert e.v1 == pytest.approx(float(re.v), rel=1e-6, abs=1e-9), e
    assert r.v1[-1] == pytest.approx(float(ref.v_at(1.0)), rel=1e-7)


def _valve_reference(t_end=0.5):
    """valve-travel by hand: F2(x2) piecewise linear (-1 kN to 20 mm, ramp to -20 kN at 50 mm),
    DOP853 on (x1, v1) restarted at each breakpoint and stopped at v1 = 0 (the gear then
    self-locks: rho(0) > gamma and the drive's F1(0) is far below the breakaway force)."""
    tg = math.tan(gear.GAMMA)

    def load(x2):
        return -1000.0 if x2 < 0.02 else (-1000.0 - 19000.0 * (x2 - 0.02) / 0.03 if x2 < 0.05 else -20000.0)

    def f(t, y):
        return [y[1], gear.accel(y[1], 1, load(y[0] * tg), 200.0)]

    events, t, y = [], 0.0, [0.0, 1e-12]
    for x2_break in (0.02, 0.05, None):
        hit = (lambda t, y, xb=x2_break: y[0] * tg - xb) if x2_break else (lambda t, y: 1.0)
        stop = lambda t, y: y[1]  # noqa: E731
        hit.terminal, stop.terminal, stop.direction = True, True, -1
        sol = solve_ivp(f, (t, t_end), y, events=[hit, stop], method="DOP853", rtol=1e-13, atol=1e-15)
        if sol.status != 1:
            return events, sol.y[:, -1]
        which = 0 if sol.t_events[0].size else 1
        t, y = sol.t_events[which][0], sol.y_events[which][0]
        events.append(("load_at" if which == 0 else "v1", t, y[1]))
        if which == 1:
            return events, y
    return events, y


@pytest.mark.parametrize("method", METHODS)
def test_load_schedule_in_x2_against_dop853(method):
    ref_events, _ = _valve_reference()
    assert [k for k, _, _ in ref_events] == ["load_at", "load_at", "v1"]
    r = simulate("valve-travel", method=method, rtol=1e-9, atol=1e-12)
    assert r.status == "finished", r.message
    assert [e.guard for e in r.events] == ["load_at1", "load_at2", "v1"]
    assert r.events[-1].to_mode == "stick"
    # rosenbrock23 carries its run-up error from rest (known limit, below): 2.5e-7 measured.
    for e, (_, t, v) in zip(r.events, ref_events):
        assert e.t == pytest.approx(t, rel=1e-7 if method == "dopri5" else 5e-7), e
        assert e.v1 == pytest.approx(v, rel=1e-6, abs=1e-9), e
    # The law's slope changes at the breakpoints, not its value: F2 is continuous in x2.
    x2 = r.x2
    assert np.all(np.diff(r.F2[(x2 > 0.021) & (x2 < 0.049)]) <= 0)


# --- free values held to the scene file's rules ---------------------------------------------

@pytest.mark.parametrize("value", [-200.0, 0.0])
def test_free_mass_out_of_range_is_refused_naming_it(value):
    with pytest.raises(SimulationInputError, match=r"m2 = .*must be > 0 kg.*wedge\.m2"):
        simulate("paper", {"m2": value})


def test_free_breakpoints_must_stay_increasing():
    with pytest.raises(SimulationInputError, match=r"load_at1 = 0\.7 s: must be below load\.at\[1\]"):
        simulate("load-schedule", {"load_at1": 0.7})
    with pytest.raises(SimulationInputError, match=r"load_at1 = -0\.1 s: must be >= 0 s"):
        simulate("load-schedule", {"load_at1": -0.1})


def test_cli_refuses_a_free_value_out_of_range_with_exit_2(capsys):
    from tswm_runtime.cli import main

    assert main(["simulate", "paper", "--set", "m2=0", "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "m2 = 0 kg: must be > 0 kg" in err and "Traceback" not in err


def test_sweep_records_invalid_cases_and_goes_on():
    from tswm_runtime.sweeps.sweep import sweep

    P = np.array([[-100.0, -5000.0], [0.0, -5000.0], [100.0, -5000.0]])  # (m2, F2)
    table = sweep("paper", P, {"t_end": 0.05}).table
    assert table["status"].tolist() == ["invalid-parameter", "invalid-parameter", "finished"]
    assert all("m2" in reason and "> 0 kg" in reason for reason in table["problem"][:2])
    assert table["problem"][2] == "" and np.isnan(table["S1m"][0])
    direct = simulate("paper", {"m2": 100.0, "F2": -5000.0}, t_end=0.05)
    assert table["S1m"][2] == pytest.approx(direct.S1_max, rel=1e-12)


# --- every status message can be built -------------------------------------------------------

def test_every_status_message_builds_for_every_mode():
    """No status message may raise: each status, with each mode as the last one (the
    inconsistent-in-stick case used to raise AttributeError)."""
    from tswm_runtime.hybrid import machine as hybrid
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.results.result import STATUS_NAMES, Event, status_message
    from tswm_runtime.simulation.simulate import parameter_vector

    for scene in ("paper-runup", "seating", "paper-literal", "one-sided", "backlash", "mesh", "lost-motion"):
        m = load_module(scene)
        p = parameter_vector(m, {})
        y = np.array([{"x1": 0.1, "v1": 0.5, "gap": 1e-4}.get(s, 0.0) for s in m.STATES])
        events = [Event(0.1, "D" if "D" in m.GUARDS else m.GUARDS[0], m.MODES[0], None, 0.0, 0.5)]
        for status in STATUS_NAMES:
            for last in range(len(m.MODES)):
                for need in (hybrid.NEED_NOTHING, hybrid.NEED_STICK, hybrid.NEED_FORWARD,
                             hybrid.NEED_BACKWARD, hybrid.NEED_FLANK):
                    if status == hybrid.UNDECLARED and need == hybrid.NEED_NOTHING:
                        continue  # UNDECLARED always says what it needs
                    text = status_message(m, status, 0.1, y, last, need, events, p)
                    assert isinstance(text, str) and text, (scene, status, last, need)


# --- the Result's dense solution and tables --------------------------------------------------

@pytest.mark.heavy
def test_result_sol_follows_the_reference_across_a_load_step():
    """result.sol(t): cubic Hermite between output points, split at events, against the
    quadrature reference at off-grid times, including just before and after the step."""
    ref = reference(200.0, ((0.0, 0.0), (0.3, -15000.0)), 1.0)
    r = simulate("paper-runup", {"F2_after": -15000.0}, rtol=1e-10, atol=1e-13, points=2001)
    t = np.array([0.0123456, 0.1, 0.29977, 0.3 - 1e-6, 0.3 + 1e-6, 0.30041, 0.777, 0.99999])
    v = r.sol(t)[1]
    v_ref = np.array([float(ref.v_at(x)) for x in t])
    np.testing.assert_allclose(v, v_ref, rtol=2e-7)
    x_ref = np.array([float(ref.x_at(x)) for x in t])
    np.testing.assert_allclose(r.sol(t)[0], x_ref, rtol=1e-8)
    assert np.isnan(r.sol([1.5])).all()


def test_result_dataframe_and_dict():
    r = simulate("paper-runup", {"F2_after": -15000.0})
    df = r.to_dataframe()
    assert list(df.columns[:3]) == ["t", "x1", "v1"] and df.attrs["units"]["S1"] == "N"
    # the load law by hand: 0 N before the step at 0.3 s, -15 kN from the first row after it
    assert (df.loc[df.t <= 0.3, "F2"] == 0.0).all() and (df.loc[df.t > 0.3, "F2"] == -15000.0).all()
    assert set(df.regime) == {"tractive"}
    # every row's a1, S1, S2 (evaluated in one numba pass) against the hand formulas, with
    # the load in force at that row
    for v, F2, a1, S1, S2 in zip(df.v1[::50], df.F2[::50], df.a1[::50], df.S1[::50], df.S2[::50]):
        assert a1 == pytest.approx(gear.accel(v, 1, F2, 200.0), rel=1e-9, abs=1e-9)
        assert (S1, S2) == pytest.approx(gear.reactions(v, 1, F2, 200.0), rel=1e-9, abs=1e-6)
    d = r.to_dict()
    assert d["events"][0] == {"t": r.events[0].t, "guard": "load_step", "kind": "load step", "from_mode": "fwd_a",
                              "to_mode": "fwd_a", "x1": r.events[0].x1, "v1": r.events[0].v1}
    assert d["param_units"] == {"m2": "kg", "F2_after": "N", "t_step": "s"}


# --- equilibrium tails ---------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_equilibrium_tail_is_held_exactly_and_its_cost_is_flat(method):
    """Run up, -15 kN from 0.3 s, then 100 s at the new equilibrium: the tail is held at
    the equilibrium (one Newton step from the integrated state), so v1 and x1 at 100 s
    agree with the reference to the tolerance and the step count does not grow with T."""
    ref = reference(200.0, ((0.0, 0.0), (0.3, -15000.0)), 100.0)
    runs = {T: simulate("paper-runup", {"F2_after": -15000.0}, method=method, t_end=T) for T in (1.0, 100.0)}
    r = runs[100.0]
    assert r.status == "finished" and r.njev > 0
    assert r.v1[-1] == pytest.approx(float(ref.v_at(100.0)), rel=1e-6)
    assert r.x1[-1] == pytest.approx(float(ref.x_at(100.0)), rel=1e-6)
    assert r.n_steps == runs[1.0].n_steps


def test_a_held_state_still_meets_its_scheduled_load_times():
    """load-schedule: the run-up settles before the 30 kN step at 0.3 s; the held state
    ends exactly at the breakpoint, which the reference places at 0.3 s as well."""
    r = simulate("load-schedule", rtol=1e-9, atol=1e-12)
    assert r.njev > 0  # dopri5 looked up J only to confirm the equilibrium it held
    assert [e.guard for e in r.events][0] == "load_at1" and r.events[0].t == pytest.approx(0.3, abs=1e-15)


X2_STEPS = """
name = "x2-steps"
[wedge]
flanks = ["a", "b"]
gamma = "10 deg"
m1 = "10 kg"
m2 = "100 kg"
[friction]
law = "constant"
rho = "5 deg"
[drive]
law = "constant"
F1 = "300 N"
[load]
law = "schedule"
variable = "x2"
shape = "steps"
at = [{ value = "1 mm", free = true }]
values = ["0 N", "-100 N"]
[modes]
include = ["forward", "stick"]
[run]
t_end = "0.2 s"
v1 = "0.1 m/s"
rtol = 1e-10
atol = 1e-13
"""


@pytest.mark.heavy
def test_steps_in_x2_are_located_where_body_2_reaches_them(scene_module):
    """A load stepped on at x2 = 1 mm (the law reads only its latched piece, the breakpoint's
    guard reads x2): reached at the closed-form time of uniform acceleration on flank a."""
    from hard_cases.test_impacts import sliding_a_accel
    module = scene_module(X2_STEPS)
    a1 = sliding_a_accel(300.0, 0.0, 10.0, 100.0, math.tan(math.radians(5.0)))
    # x2 = x1 tan(gamma) = (0.1 t + a1 t^2 / 2) tan(gamma) = 1 mm
    x1_step = 1e-3 / math.tan(math.radians(10.0))
    t_step = (-0.1 + math.sqrt(0.01 + 2.0 * a1 * x1_step)) / a1
    r = simulate(module, t_end=0.2, rtol=1e-10, atol=1e-13)
    assert r.status == "finished", r.message
    step = next(e for e in r.events if e.guard == "load_at1")
    assert step.t == pytest.approx(t_step, rel=1e-9)
    assert step.x1 == pytest.approx(x1_step, rel=1e-9)
