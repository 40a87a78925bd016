"""Simulated chains of wedge stages against references written by hand: the one-stage model of the same
numbers, and Newton per body with Coulomb per stage (tests/chains.py's HandChain)."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from derivation.chain.scene import parse_chain
from tests.chains import DEG, TIGHT, HandChain, assert_like_hand, wedges
from tswm_runtime.bench.chain import worm_and_nut
from tswm_runtime.simulation.chain import simulate_chain

SWITCHING = dict(gammas=(30.0, 25.0), mus=(0.1, 0.1), masses=(1.0, 1.0, 1.0), forces=(5.0, 0.0, 20.0), spring=1000.0)


@pytest.fixture(scope="module")
def switching(chain_module):
    """The run of the two-stage chain that changes flank (SWITCHING)."""
    return simulate_chain(chain_module(wedges("two-switching", **SWITCHING)), **TIGHT)


def test_two_stages_change_flank_one_after_the_other_as_the_hand_model(switching):
    """The spring's push on the last body first drives the chain (both stages inverse-tractive), then
    resists it: stage 1 changes flank at 35.05 ms, stage 2 at 60.61 ms, and the chain turns back at
    276.7 ms; the switch times and the final state agree with the hand model to 1e-9."""
    result = switching
    log = assert_like_hand(result, HandChain(**SWITCHING), 1.0, 0.5)
    assert len(log) == 4 and [len(s.switches) for s in result.stages] == [2, 2]


def test_the_normal_forces_at_the_turn_are_newtons(switching):
    """The largest normal forces come at the turn (v0 = 0, the spring compressed most), where friction flips:
    each stage's peak is the larger of Newton's N by hand sliding forward and backward there, on flank a."""
    result = switching
    turn = next(e["t"] for e in result.events if e["guard"] == "v0")
    hand = HandChain(**SWITCHING)
    q_turn = hand.run(1.0, turn)[2][0]
    forward, backward = hand.solve(q_turn, 1, (1, 1))[1], hand.solve(q_turn, -1, (1, 1))[1]
    for k in range(2):
        peak = result.stages[k].peaks["normal"]
        assert peak.t == turn
        assert peak.value == pytest.approx(max(forward[k], backward[k]), rel=1e-8)


def test_a_run_samples_its_end_where_no_output_time_lies(chain_module):
    """The run's end (t_end = 0.5 s, sliding back after the turn) is a sample of its last phase even where no output
    time lies (here 0 and 0.1 s only), so the extra travel, the farthest of the samples' travel, sees where the
    run ends: q0 there as the hand model's."""
    from tswm_runtime.chains.run import run_chain

    run = run_chain(chain_module(wedges("two-switching", **SWITCHING)), t_end=0.5, v0=1.0, t_out=np.array([0.0, 0.1]),
                    **TIGHT)
    end = run.phases[-1].table[-1]
    assert run.status == "finished" and run.phases[-1].mode != -1
    assert end[0] == 0.5 and end[1] == pytest.approx(HandChain(**SWITCHING).run(1.0, 0.5)[2][0], rel=1e-9)


THREE = dict(gammas=(30.0, 25.0, 20.0), mus=(0.1, 0.1, 0.1), masses=(1.0, 1.0, 1.0, 1.0),
             forces=(5.0, 0.0, 0.0, 20.0), spring=1000.0)


def test_three_stages_as_the_hand_model(chain_module):
    module = chain_module(wedges("three-switching", **THREE))
    result = simulate_chain(module, **TIGHT)
    log = assert_like_hand(result, HandChain(**THREE), 1.0, 0.5)
    assert len(log) == 3 and [len(s.switches) for s in result.stages] == [0, 1, 1]


HOLD = dict(gammas=(30.0, 5.0), mus=(0.1, 0.15), masses=(1.0, 1.0, 1.0), forces=(0.0, 0.0, -50.0))
BACKDRIVE = dict(HOLD, mus=(0.1, 0.02))


def test_a_self_locking_stage_holds_the_load(chain_module):
    """Stage 2 self-locks (tan rho = 0.15 > tan 5 deg): the chain coasts to rest against the load and stays."""
    module = chain_module(wedges("hold", **HOLD))
    result = simulate_chain(module, **TIGHT)
    assert_like_hand(result, HandChain(**HOLD), 1.0, 0.5)
    assert [p.regime for p in result.stages[1].phases] == ["tractive", "resting"]
    # no force on body 0 and stage 1 not self-locking (tan 30 deg > 0.1): it holds no force, X_1 = 0 exactly
    assert result.events[-1]["to"] == "resting" and "determine the internal forces: X_1 = 0;" in result.events[-1]["reason"]


def test_the_load_back_drives_the_chain_when_no_stage_self_locks(chain_module):
    module = chain_module(wedges("backdrive", **BACKDRIVE))
    result = simulate_chain(module, **TIGHT)
    assert_like_hand(result, HandChain(**BACKDRIVE), 1.0, 0.5)
    assert [p.regime for p in result.stages[1].phases] == ["tractive", "inverse-tractive"]


PAINLEVE = dict(gammas=(5.0,), mus=(math.tan(8 * DEG),), masses=(1.0, 1000.0), forces=(100.0, 0.0))


def test_a_painleve_case_is_reported_not_integrated(chain_module):
    """A light input drives a heavy output through a self-locking wedge: both flanks are consistent by hand
    (a Painleve ambiguity); the run stops at once and says so."""
    assert len(HandChain(**PAINLEVE).consistent(0.0, 1, False, noise=0.0)) == 2
    module = chain_module(wedges("painleve", **PAINLEVE))
    result = simulate_chain(module, **TIGHT)
    assert result.status == "indeterminate" and result.t_stop == 0.0
    assert "Painleve" in result.message and "D < 0" in result.message
    assert result.events[0]["to"] is None


# One stage as the one-stage model's scene: rho free, so that both cases run one compiled module.
ONE_STAGE = ('name = "one-stage"\n[wedge]\nflanks = ["a", "b"]\ngamma = "20 deg"\nm1 = "3 kg"\nm2 = "5 kg"\n'
             '[friction]\nlaw = "constant"\nrho = { value = 0.1, free = true }\n[drive]\nlaw = "constant"\nF1 = "10 N"\n'
             '[load]\nlaw = "constant"\nF2 = "-40 N"\n[modes]\ninclude = ["forward", "backward", "stick"]\n[run]\nt_end = "1 s"\nv1 = "2 m/s"\n')


@pytest.mark.parametrize("rho, after_rest, single_after", [(0.1, "inverse-tractive", "backward on flank a"),
                                                           (0.4, "resting", "stick")], ids=["back-driven", "self-locking"])
def test_one_stage_chain_runs_as_the_one_stage_model(chain_module, scene_module, rho, after_rest, single_after):
    """The wedge scene of the same numbers, run by the one-stage model: the same phases and switch time, the
    same v1 and x1 at every output point, the same largest S1 and S2 while sliding."""
    import tswm_runtime

    single = tswm_runtime.simulate(scene_module(ONE_STAGE), {"friction_rho": rho}, **TIGHT)
    chain = simulate_chain(chain_module(wedges(f"one-chain-{after_rest}", (20.0,), (math.tan(rho),), (3.0, 5.0),
                                               (10.0, -40.0), v0=2.0, t_end=1.0)), **TIGHT)
    assert single.status == chain.status == "finished"
    stage = chain.stages[0]
    assert [p.regime for p in stage.phases] == ["tractive", after_rest]
    assert [p.regime for p in single.phases] == ["tractive", single_after]
    assert stage.switches[0] == pytest.approx(single.phases[1].t_start, rel=1e-12)
    assert np.allclose(chain.v0, single.v1, rtol=1e-9, atol=1e-11)
    assert np.allclose(chain.q0, single.x1, rtol=1e-9, atol=1e-11)
    sliding = np.array([single.mode_names[m] != "stick" for m in single.mode])
    for name, series in (("input", single.S1), ("output", single.S2)):   # S = F - m a: what a body exerts on
        k = np.argmax(np.abs(series[sliding]))                           # the wedge, the stage's force on it negated
        assert stage.peaks[name].value == pytest.approx(-series[sliding][k], rel=1e-9), name


@pytest.mark.heavy
def test_cli_simulates_a_chain_file(tmp_path, capsys, caplog, monkeypatch):
    """tswm simulate CHAIN.toml: says that it derives and compiles the new file's model before it does, then
    per stage regimes, switch times and maxima; exit 0 finished, 1 for a run that stops at a Painleve case,
    2 for bad input naming the option or key."""
    from tswm_runtime.cli import main

    monkeypatch.setenv("TSWM_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "hold.toml"
    path.write_text(wedges("hold", **HOLD))
    with caplog.at_level(logging.WARNING):
        assert main(["simulate", str(path), "--rtol", "1e-10", "--atol", "1e-12", "-o", str(tmp_path)]) == 0
    said = [record.getMessage() for record in caplog.records]
    assert said[0].startswith("tswm: deriving the model of chain scene 'hold' with SymPy"), said
    assert said[1].startswith("tswm: compiling the model `hold` into numba's cache: about "), said
    out = capsys.readouterr().out
    assert "status: finished" in out and "stage 2 (wedge, body 1 -> body 2):" in out
    assert "resting" in out and "all stuck: the statics determine the internal forces: X_1 = 0;" in out
    hand = HandChain(**HOLD)                    # coasting forward, both stages on flank a: constant forces
    normal = hand.solve(0.0, 1, (1, 1))[1]
    on_input = [-(math.sin(g) + mu * math.cos(g)) * n for g, mu, n in zip(hand.g, hand.mu, normal)]
    assert all(f < 0 for f in on_input)         # the stage holds its input body back: printed as |.| and signed
    for f, n in zip(on_input, normal):
        assert f"max |input force| while sliding: {-f:.6g} N at t = " in out and f"(the force is {f:.6g} N)" in out
        assert f"max |normal force| while sliding: {n:.6g} N at t = " in out
    assert (tmp_path / "hold-summary.json").exists()
    painleve = tmp_path / "painleve.toml"
    painleve.write_text(wedges("painleve", **PAINLEVE))
    assert main(["simulate", str(painleve)]) == 1
    assert "status: indeterminate" in capsys.readouterr().out
    assert main(["simulate", str(path), "--rtol", "5"]) == 2
    assert "--rtol: rtol = 5.0: must be in [1e-13, 0.01]" in capsys.readouterr().err
    assert main(["simulate", str(path), "--set", "F2=1"]) == 2
    assert "parameter 'F2': chain scene 'hold' has no such value (values: gamma_1, mu_1, " in capsys.readouterr().err
    path.write_text(wedges("hold", **HOLD).replace("v0 = 1.0", 'v0 = "fast"'))
    assert main(["simulate", str(path)]) == 2
    assert 'run.v0 = "fast"' in capsys.readouterr().err


def valve(worm_mu: float, screw_mu: float) -> str:
    return worm_and_nut(f"valve-{worm_mu}-{screw_mu}".replace(".", ""), worm_mu=worm_mu, screw_mu=screw_mu,
                        run="t_end = 3.0\nv0 = 150.0")


def hand_valve(worm_mu: float, screw_mu: float) -> HandChain:
    """The same chain from handbook formulas: the screw's lead angle tan(lambda) = L / (pi d_m), its flank's
    normal angle tan(alpha_n) = tan(alpha) cos(lambda) (Shigley), mu' = mu / cos(alpha_n) on both stages."""
    lam = math.atan(0.004 / (math.pi * 0.018))
    alpha_n = math.atan(math.tan(15 * DEG) * math.cos(lam))
    return HandChain((4.76, math.degrees(lam)), (worm_mu / math.cos(20 * DEG), screw_mu / math.cos(alpha_n)),
                     (0.0069, 0.02, 20.0), (0.0, 0.0, -20000.0), levers=[(0.025, 0.08), (0.009, 1.0)])


@pytest.mark.parametrize("worm_mu, screw_mu, after", [(0.05, 0.15, "resting"), (0.02, 0.02, "inverse-tractive")],
                         ids=["screw-self-locks", "back-driven"])
def test_worm_and_stem_nut_as_the_hand_model(chain_module, worm_mu, screw_mu, after):
    """Motor -> worm gear -> stem nut -> stem coasting at 150 rad/s against 20 kN: the self-locking nut
    (rho' 8.8 deg > lambda 4.05 deg) holds the stem when the chain stops; with mu 0.02 on both stages
    none self-locks and the load drives the chain back. Stop time and final state as the hand model's."""
    result = simulate_chain(chain_module(valve(worm_mu, screw_mu)), **TIGHT)
    assert_like_hand(result, hand_valve(worm_mu, screw_mu), 150.0, 3.0)
    assert [p.regime for p in result.stages[1].phases] == ["tractive", after]


MOTOR = ((0.0, 1.0, 2.0, 3.0), (30.0, 32.0, 20.0, 0.0), 0.9)


def test_a_motor_table_drives_the_chain_as_the_hand_model(chain_module):
    """A motor on body 0 (its table at 0.9 U_n: torque x 0.81) starts the chain from rest against a spring,
    which stops it at 0.7378 s, where the stall torque no longer breaks it away: it rests. The table's
    kinks lie inside steps of both integrators, so the agreement is 1e-7, not 1e-9."""
    motor = "motor = { speed = [0.0, 1.0, 2.0, 3.0], torque = [30.0, 32.0, 20.0, 0.0], voltage = 0.9 }\n"
    text = wedges("motor", (30.0, 25.0), (0.1, 0.1), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), spring=300.0, v0=0.0, t_end=1.0)
    text = text.replace('force = "0.0 N"\n', 'force = "0.0 N"\n' + motor, 1)
    result = simulate_chain(chain_module(text), **TIGHT)
    hand = HandChain((30.0, 25.0), (0.1, 0.1), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), spring=300.0, motor=MOTOR)
    assert_like_hand(result, hand, 0.0, 1.0, tol=1e-7)
    assert [p.regime for p in result.stages[0].phases] == ["tractive", "resting"]
    assert result.t[500] == 0.5
    assert result.v0[500] == pytest.approx(hand.run(0.0, 0.5)[2][1], rel=1e-7)   # mid-run, while it drives


def test_a_powered_phase_peaks_between_its_samples_as_the_hand_model(chain_module):
    """The motor scene above with 3 output points (0, 0.5, 1 s): while the spring stops the chain (v0 falls to
    0 at 0.7378 s) the motor's torque falls back along its table and each stage's normal force peaks inside the
    sliding phase (stage 1 at t = 0.7133 s, v0 = 0.18 rad/s), not at an output point or the phase's ends. Each
    peak is the largest N_i(t) of the hand model (Newton per body, DOP853 at rtol 1e-11 with dense output, the
    best of 20001 points refined by scipy's bounded Brent) to 1e-9 relative, its time to 1e-8 s; the samples'
    largest, what the peak was before, is visibly below it (stage 1 by 1.6e-3, stage 2 by 5e-5, relative)."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import minimize_scalar

    motor = "motor = { speed = [0.0, 1.0, 2.0, 3.0], torque = [30.0, 32.0, 20.0, 0.0], voltage = 0.9 }\n"
    text = wedges("motor", (30.0, 25.0), (0.1, 0.1), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), spring=300.0, v0=0.0, t_end=1.0)
    result = simulate_chain(chain_module(text.replace('force = "0.0 N"\n', 'force = "0.0 N"\n' + motor, 1)),
                            points=3, **TIGHT)
    hand = HandChain((30.0, 25.0), (0.1, 0.1), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), spring=300.0, motor=MOTOR)

    def stop(t, y):
        return y[1] if t > 0.0 else 1.0
    stop.terminal, stop.direction = True, -1
    sol = solve_ivp(lambda t, y: [y[1], hand.solve(y[0], 1, (1, 1), y[1])[0]], (0.0, 1.0), [0.0, 0.0],
                    method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True, events=stop)
    t_stop = sol.t_events[0][0]
    assert [p.t_end for p in result.stages[0].phases][0] == pytest.approx(t_stop, rel=1e-9)
    grid = np.linspace(0.0, t_stop, 20001)
    for k in range(2):
        def normal(t):
            q0, v0 = sol.sol(t)
            return hand.solve(q0, 1, (1, 1), v0)[1][k]
        j = int(np.argmax([normal(t) for t in grid]))
        best = minimize_scalar(lambda t: -normal(t), bounds=(grid[j - 1], grid[j + 1]), method="bounded",
                               options={"xatol": 1e-12})
        peak = result.stages[k].peaks["normal"]
        assert peak.value == pytest.approx(-best.fun, rel=1e-9), k
        assert peak.t == pytest.approx(best.x, abs=1e-8), k
        assert 0.1 < best.x < t_stop - 1e-3 and abs(best.x - 0.5) > 0.1   # inside the phase, away from a sample
        sampled = np.nanmax(np.abs(result.samples[3][:, 3 * k + 2]))
        assert -best.fun - sampled > 1e3 * 1e-9 * -best.fun, (k, sampled, -best.fun)


@pytest.mark.parametrize("motor, parts", [
    ("{ speed = [0.0, 2.0, 1.0], torque = [1.0, 2.0, 3.0] }", ["body[0].motor.speed", "increase strictly"]),
    ("{ speed = [0.0, 1.0], torque = [1.0] }", ["body[0].motor.torque", "2 to 100 values"]),
    ("{ speed = [0.0, 1.0, 2.0], torque = [1.0, 2.0] }", ["body[0].motor.torque", "one value per speed (3)"]),
    ('{ speed = [0.0, "1 rpm"], torque = [1.0, 2.0] }', ['body[0].motor.speed[1] = "1 rpm"', "plain number in SI"]),
    ("{ speed = [0.0, 1.0], torque = [1.0, 2.0], voltage = 3.0 }", ["body[0].motor.voltage = 3", "(0, 2]"]),
    ("{ speed = [0.0, 1.0], torque = [1.0, 2.0], volts = 1.0 }", ["body[0].motor.volts", "unknown key"]),
    ("3.0", ["body[0].motor = 3", "expected a table"]),
])
def test_a_bad_motor_table_is_named(motor, parts):
    from derivation.scene import SceneError

    text = wedges("bad-motor", (30.0,), (0.1,), (1.0, 1.0), (0.0, 0.0)).replace(
        'force = "0.0 N"\n', f'force = "0.0 N"\nmotor = {motor}\n', 1)
    with pytest.raises(SceneError) as err:
        parse_chain(text, "m.toml")
    for part in parts:
        assert part in str(err.value), str(err.value)


def test_the_shipped_motor_settles_where_it_meets_the_load_through_both_stages(chain_module):
    """The shipped mov's motor (its table, derivation/chain/scenes/mov.toml) starts the worm and nut from rest
    against 15 kN and settles where its table's torque equals the load's torque at the worm by handbook
    formulas, the screw's F d_m/2 tan(lambda + rho_2') times the worm gear's r1/r2 tan(gamma + rho_1');
    both stages stay tractive on flank a."""
    from derivation.chain.scene import load_chain

    motor = load_chain("mov").bodies[0].motor
    table = f"motor = {{ speed = {list(motor.speed)!r}, torque = {list(motor.torque)!r}, voltage = 1.0 }}"
    result = simulate_chain(chain_module(worm_and_nut("motor-nut", drive=table, load='force = "-15 kN"',
                                                      run="t_end = 1.0\nv0 = 0.0")), **TIGHT)
    lam = math.atan(0.004 / (math.pi * 0.018))
    alpha_n = math.atan(math.tan(15 * DEG) * math.cos(lam))
    at_worm = (15000 * 0.009 * math.tan(lam + math.atan(0.15 / math.cos(alpha_n)))
               * 0.025 / 0.08 * math.tan(4.76 * DEG + math.atan(0.05 / math.cos(20 * DEG))))
    falling = np.argmax(motor.torque)                       # the table's falling branch, past its pull-out
    steady = np.interp(-at_worm, -np.array(motor.torque[falling:]), motor.speed[falling:])
    assert result.status == "finished"
    assert [(p.regime, p.flank) for s in result.stages for p in s.phases] == [("tractive", "a")] * 2
    assert result.v0[-1] == pytest.approx(steady, rel=1e-7)


def test_a_force_peak_is_the_first_phase_maximum_of_largest_magnitude_over_the_sliding_phases():
    """By hand over two sliding phases' maxima (one stage's three forces, then their times): input -3 at t = 2
    (the later -3 at t = 4 is as large, not larger), output 5 at t = 3 (the NaN of the second phase is never a
    peak), normal -9.5 at t = 4 (a NaN, a force undetermined in a whole phase, is never a peak, not even the
    first phase's); a force NaN in every phase peaks as NaN."""
    from types import SimpleNamespace

    from tswm_runtime.simulation.chain import _peaks

    first = np.array([-3.0, 5.0, np.nan, 2.0, 3.0, np.nan])
    second = np.array([3.0, np.nan, -9.5, 4.0, np.nan, 4.0])
    [peaks] = _peaks([SimpleNamespace(peaks=first), SimpleNamespace(peaks=second)], 1)
    assert (peaks["input"].value, peaks["input"].t) == (-3.0, 2.0)
    assert (peaks["output"].value, peaks["output"].t) == (5.0, 3.0)
    assert (peaks["normal"].value, peaks["normal"].t) == (-9.5, 4.0)
    [undetermined] = _peaks([SimpleNamespace(peaks=np.full(6, np.nan))] * 2, 1)
    assert math.isnan(undetermined["normal"].value) and math.isnan(undetermined["normal"].t)
    assert _peaks([], 2) == [dict.fromkeys(("input", "output", "normal"))] * 2


def test_a_result_read_for_its_outcome_builds_no_summaries(chain_module, monkeypatch):
    """The stages' summaries, the drive train's answers, the samples' table and the run's events (with their
    decisions) are built on first access: a caller reading the outcome and the events' times and modes (a sweep's
    case, the bench) never pays for them."""
    from tswm_runtime.simulation import chain as simulation

    def unread(*_):
        raise AssertionError("built though not read")
    for name in ("_peaks", "_stage", "_samples", "drive_train_answers"):
        monkeypatch.setattr(simulation, name, unread)
    result = simulate_chain(chain_module(wedges("two-switching", **SWITCHING)), **TIGHT)
    assert result.status == "finished" and result.events[0]["guard"] == "start"
    assert [e["to"] for e in result.events][-1] and "events" not in vars(result.run)
    assert result.events[-1]["reason"] and "events" in vars(result.run)
    with pytest.raises(AssertionError, match="not read"):
        result.stages


def test_the_output_times_are_linspaces():
    """simulate_chain's output times (the runtime's remembered ones) are np.linspace(0, t_end, points),
    bit for bit."""
    from tswm_runtime.results.rows import output_times

    for t_end in (5.0, 0.1, 1e-9, 3.3, 77.7):
        for points in (1, 2, 3, 7, 1000, 200001):
            assert np.array_equal(output_times(t_end, points), np.linspace(0.0, t_end, points)), (t_end, points)


def test_remembered_settings_are_checked_as_given(chain_module):
    """The validated settings are remembered per module and overrides, their types included: points=True
    (a bool, refused) does not pass as the points=1 checked before, nor a bad value after a good one."""
    from tswm_runtime.simulation.chain import settings
    from tswm_runtime.simulation.simulate import SimulationInputError

    module = chain_module(wedges("two-switching", **SWITCHING))
    assert settings(module, {"points": 1})["points"] == 1
    assert settings(module, {"points": 1}) == settings(module, {"points": 1})
    with pytest.raises(SimulationInputError, match="points"):
        settings(module, {"points": True})
    with pytest.raises(SimulationInputError, match="rtol"):
        settings(module, {"rtol": float("nan")})
    with pytest.raises(SimulationInputError, match="rtol"):
        settings(module, {"rtol": [1e-6]})


def test_a_run_reads_its_phases_from_its_record_on_first_access(chain_module):
    """A run's phases and events are views into its own record, built when read; the events' states are the
    ones the decisions saw (the Python decision there agrees with the compiled one)."""
    result = simulate_chain(chain_module(wedges("two-switching", **SWITCHING)), **TIGHT)
    run = result.run
    assert "phases" not in vars(run)
    assert [phase.mode for phase in run.phases][0] == run.events[0].to_mode
    assert all(np.shares_memory(event.seen[1], run.record.event_f) for event in run.events)
    assert [e["outcome"] for e in result.events] == [e.decision.outcome for e in run.events]
    assert [(e["t"], e["guard"], e["outcome"]) for e in result.events] == [(e.t, e.guard, e.outcome)
                                                                         for e in run.events]


def test_a_runs_start_is_its_own(chain_module):
    """The p a run starts from (the scene's values prepared once per module and voltage) is a copy: writing
    a run's p changes no later start, and each voltage has its own."""
    from tswm_runtime.chains.run import latches

    module = chain_module(wedges("two-switching", **SWITCHING))
    first = latches(module, np.zeros(2))
    expected = first.copy()
    first[:] = np.nan
    assert np.array_equal(latches(module, np.zeros(2)), expected)
    assert latches(module, np.zeros(2), voltage=0.5)[module.P_VOLTAGE] == 0.5
    assert np.array_equal(latches(module, np.zeros(2)), expected)



def test_a_repeated_call_runs_as_the_first():
    """simulate_chain remembers a call's settings and the kernel's arguments per module, method and overrides: a
    repeated call gives the first one's numbers bit for bit, with its own p and output times (writing a result's
    changes no later run); other overrides (their types included) and other values are not taken for them."""
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.simulation.simulate import SimulationInputError

    mov = load_module("mov")
    first = simulate_chain(mov, **TIGHT)
    first.p[:] = np.nan
    first.t[:] = np.nan
    again = simulate_chain(mov, **TIGHT)
    assert np.isfinite(again.p).all() and np.array_equal(again.t, np.linspace(0.0, mov.RUN["t_end"], again.t.size))
    assert np.array_equal(again.q0, simulate_chain(mov, **TIGHT).q0)
    assert [e["t"] for e in again.events] == [e["t"] for e in simulate_chain(mov, **TIGHT).events]
    assert simulate_chain(mov, **{**TIGHT, "rtol": 1e-4}).n_steps < again.n_steps
    other = simulate_chain(mov, {"mu_1": 0.08}, **TIGHT)
    assert other.p[mov.P_VALUES + mov.PARAM_NAMES.index("mu_1")] == 0.08 and other.q0[-1] != again.q0[-1]
    assert simulate_chain(mov, **TIGHT).q0[-1] == again.q0[-1]
    simulate_chain(mov, points=1)
    with pytest.raises(SimulationInputError, match="points"):
        simulate_chain(mov, points=True)
