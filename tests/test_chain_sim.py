"""Simulated chains of wedge stages against references written here by hand: the one-stage model of the
same numbers, and Newton per body with Coulomb per stage integrated by scipy's DOP853 at rtol 1e-12,
its modes found by enumerating every flank combination at each event."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from derivation.chain.codegen import generate_chain_module
from derivation.chain.scene import parse_chain
from tswm_runtime.simulation.chain import simulate_chain

DEG = math.pi / 180
TIGHT = {"rtol": 1e-11, "atol": 1e-13}


@pytest.fixture(scope="session")
def chain_module(module_once):
    """chain_module(toml_text) -> the generated, imported chain module (compiled once per test run)."""
    def write(text, folder):
        chain = parse_chain(text, "test chain")
        path = folder / f"{chain.name.replace('-', '_')}.py"
        path.write_text(generate_chain_module(chain))
        return path
    return lambda text: module_once(text, lambda folder: write(text, folder))


def wedges(name: str, gammas, mus, masses, forces, spring: float = 0.0, v0: float = 1.0, t_end: float = 0.5) -> str:
    """A chain scene of plain wedges (levers 1), a spring on the last body."""
    text = f'name = "{name}"\n'
    for g, mu in zip(gammas, mus):
        text += f'[[stage]]\nkind = "wedge"\ngamma = "{g!r} deg"\nmu = {mu!r}\n'
    for j, (m, f) in enumerate(zip(masses, forces)):
        text += f'[[body]]\nmass = "{m!r} kg"\nforce = "{f!r} N"\n'
        if j == len(masses) - 1 and spring:
            text += f'stiffness = "{spring!r} N/m"\n'
    return text + f"[run]\nt_end = {t_end!r}\nv0 = {v0!r}\n"


class HandChain:
    """Wedges in series: body i-1 moves x1 = r_in q_{i-1}, body i x2 = r_out q_i = tan(gamma_i) x1. Stage i's flank
    has the normal n = (sin g, cos g) and the slip direction t = (-cos g, sin g) in (x1, x2); its force on
    body i is sigma N n - mu N s t (sigma = +1 flank a, -1 flank b, N >= 0, s = sign of the slip = sign
    v0), on body i-1 the opposite; a body feels the force along its motion times its lever. ``mus`` are
    the coefficients in the wedge plane (a helical flank's mu / cos(alpha_n), typed in by the caller)."""

    def __init__(self, gammas, mus, masses, forces, spring=0.0, levers=None, motor=None):
        self.g = np.radians(gammas)
        self.mu, self.m, self.F = np.array(mus), np.array(masses), np.array(forces, dtype=float)
        self.n = len(gammas)
        self.r_in, self.r_out = np.array(levers or [(1.0, 1.0)] * self.n).T   # x1 = r_in q_{i-1}, x2 = r_out q_i
        self.c = np.cumprod([1.0, *(self.r_in * np.tan(self.g) / self.r_out)])   # v_j / v_0
        self.k = np.zeros(self.n + 1)
        self.k[-1] = spring
        self.motor = motor            # (speeds, torques, U / U_n) on body 0: np.interp of the table times (U/U_n)^2

    def forces(self, q0, v0):
        F = self.F - self.k * self.c * q0
        if self.motor:
            speeds, torques, voltage = self.motor
            F[0] += voltage**2 * np.interp(v0, speeds, torques)
        return F

    def solve(self, q0, s, sigma, v0=0.0):
        """(a_0, N_1..N_n): Newton for every body, with a_j = c_j a_0."""
        A = np.zeros((self.n + 1, self.n + 1))
        A[:, 0] = self.m * self.c
        for i in range(self.n):
            g, mu = self.g[i], self.mu[i]
            A[i + 1, 1 + i] = -self.r_out[i] * (sigma[i] * math.cos(g) - mu * s * math.sin(g))   # x2 part, body i
            A[i, 1 + i] = self.r_in[i] * (sigma[i] * math.sin(g) + mu * s * math.cos(g))   # minus the x1 part, i-1
        x = np.linalg.solve(A, self.forces(q0, v0))
        return x[0], x[1:]

    def consistent(self, q0, s, at_rest, noise=1e-9, v0=0.0):
        """Flank combinations with every N >= 0, within ``noise`` [N] of the event's location (from rest:
        leaving it in direction s)."""
        found = []
        for sigma in itertools.product((1, -1), repeat=self.n):
            a, N = self.solve(q0, s, sigma, v0)
            if np.all(N >= -noise) and (not at_rest or s * a > 0):
                found.append(sigma)
        return found

    def run(self, v0, t_end):
        """[(t, s, sigma)] of each sliding phase, or (t, 0, None) for rest; and the final (t, y)."""
        t, y, log = 0.0, np.array([0.0, v0]), []
        while t < t_end:
            if y[1] == 0.0:
                moves = [(s, sg) for s in (1, -1) for sg in self.consistent(y[0], s, True)]
                if not moves:
                    log.append((t, 0, None))
                    return log, t_end, y
                assert len(moves) == 1, moves
                s, sigma = moves[0]
            else:
                s = 1 if y[1] > 0 else -1
                found = self.consistent(y[0], s, False, v0=y[1])
                sigma = found[0] if len(found) == 1 else [f for f in found if f != log[-1][2]][0]
            log.append((t, s, sigma))
            events = [self._normal(i, s, sigma) for i in range(self.n)] + [self._stop(s)]
            sol = solve_ivp(lambda t, y: [y[1], self.solve(y[0], s, sigma, y[1])[0]], (t, t_end), y, method="DOP853",
                            rtol=1e-12, atol=1e-14, events=events)
            t, y = sol.t[-1], sol.y[:, -1].copy()
            if sol.status == 1 and len(sol.t_events[-1]):
                y[1] = 0.0
        return log, t, y

    def _normal(self, i, s, sigma):
        def event(t, y):
            return self.solve(y[0], s, sigma, y[1])[1][i]
        event.terminal, event.direction = True, -1
        return event

    @staticmethod
    def _stop(s):
        def event(t, y):
            return y[1]
        event.terminal, event.direction = True, -s
        return event


def regimes(hand_log, stage):
    """(t, regime, flank) of a stage from the hand log: tractive where sigma s = +1."""
    out = []
    for t, s, sigma in hand_log:
        entry = ("resting", "") if sigma is None else (
            "tractive" if sigma[stage] * s > 0 else "inverse-tractive", "a" if sigma[stage] > 0 else "b")
        if not out or out[-1][1:] != entry:
            out.append((t, *entry))
    return out


def assert_like_hand(result, hand: HandChain, v0: float, t_end: float, tol: float = 1e-9):
    log, t_stop, y = hand.run(v0, t_end)
    for k in range(hand.n):
        expected = regimes(log, k)
        got = [(p.t_start, p.regime, p.flank) for p in result.stages[k].phases]
        assert [g[1:] for g in got] == [e[1:] for e in expected], (k, got, expected)
        assert np.allclose([g[0] for g in got], [e[0] for e in expected], rtol=tol, atol=tol), (got, expected)
    assert result.status == "finished"
    assert result.q0[-1] == pytest.approx(y[0], rel=tol, abs=tol)
    assert result.v0[-1] == pytest.approx(y[1], rel=tol, abs=tol)
    return log


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
    assert result.events[-1]["to"] == "resting" and "statically undetermined" in result.events[-1]["reason"]


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


def one_stage(name: str, rho: float) -> str:
    return (f'name = "{name}"\n[wedge]\nflanks = ["a", "b"]\ngamma = "20 deg"\nm1 = "3 kg"\nm2 = "5 kg"\n'
            f'[friction]\nlaw = "constant"\nrho = {rho!r}\n[drive]\nlaw = "constant"\nF1 = "10 N"\n'
            '[load]\nlaw = "constant"\nF2 = "-40 N"\n[modes]\ninclude = ["forward", "backward", "stick"]\n[run]\nt_end = "1 s"\nv1 = "2 m/s"\n')


@pytest.mark.parametrize("rho, after_rest, single_after", [(0.1, "inverse-tractive", "backward on flank a"),
                                                           (0.4, "resting", "stick")], ids=["back-driven", "self-locking"])
def test_one_stage_chain_runs_as_the_one_stage_model(chain_module, scene_module, rho, after_rest, single_after):
    """The wedge scene of the same numbers, run by the one-stage model: the same phases and switch time, the
    same v1 and x1 at every output point, the same largest S1 and S2 while sliding."""
    import tswm_runtime

    single = tswm_runtime.simulate(scene_module(one_stage(f"one-stage-{after_rest}", rho)), **TIGHT)
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


def test_cli_simulates_a_chain_file(tmp_path, capsys, monkeypatch):
    """tswm simulate CHAIN.toml: per stage regimes, switch times and maxima; exit 0 finished, 1 for a run that
    stops at a Painleve case, 2 for bad input naming the option or key."""
    from tswm_runtime.cli import main

    monkeypatch.setenv("TSWM_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "hold.toml"
    path.write_text(wedges("hold", **HOLD))
    assert main(["simulate", str(path), "--rtol", "1e-10", "--atol", "1e-12", "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "status: finished" in out and "stage 2 (wedge, body 1 -> body 2):" in out
    assert "resting" in out and "statically undetermined" in out and "max |normal force| while sliding" in out
    assert (tmp_path / "hold-summary.json").exists()
    painleve = tmp_path / "painleve.toml"
    painleve.write_text(wedges("painleve", **PAINLEVE))
    assert main(["simulate", str(painleve)]) == 1
    assert "status: indeterminate" in capsys.readouterr().out
    assert main(["simulate", str(path), "--rtol", "5"]) == 2
    assert "--rtol: rtol = 5.0: must be in [1e-13, 0.01]" in capsys.readouterr().err
    assert main(["simulate", str(path), "--set", "F2=1"]) == 2
    assert "--set: a chain scene has no free parameters" in capsys.readouterr().err
    path.write_text(wedges("hold", **HOLD).replace("v0 = 1.0", 'v0 = "fast"'))
    assert main(["simulate", str(path)]) == 2
    assert 'run.v0 = "fast"' in capsys.readouterr().err


def valve(worm_mu: float, screw_mu: float) -> str:
    name = f"valve-{worm_mu}-{screw_mu}".replace(".", "")
    return f"""name = "{name}"
[[stage]]
kind = "worm_gear"
lead_angle = "4.76 deg"
pressure_angle = "20 deg"
worm_radius = "25 mm"
wheel_radius = "80 mm"
mu = {worm_mu!r}
[[stage]]
kind = "power_screw"
lead = "4 mm"
flank_angle = "15 deg"
mean_diameter = "18 mm"
mu = {screw_mu!r}
[[body]]
inertia = "0.0069 kg m^2"
[[body]]
inertia = "0.02 kg m^2"
[[body]]
mass = "20 kg"
force = "-20 kN"
[run]
t_end = 3.0
v0 = 150.0
"""


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


def test_the_mov_example_settles_where_the_motor_meets_the_load_through_both_stages(chain_module):
    """docs/examples/mov.toml: the motor starts the valve from rest against 15 kN and settles where its
    table's torque equals the load's torque at the worm by handbook formulas, the screw's
    F d_m/2 tan(lambda + rho_2') times the worm gear's r1/r2 tan(gamma + rho_1'): 1.2223 N m at
    313.55681 rad/s (falling branch of the table); both stages stay tractive on flank a."""
    from pathlib import Path

    text = (Path(__file__).parent.parent / "docs" / "examples" / "mov.toml").read_text()
    result = simulate_chain(chain_module(text), t_end=1.0)
    lam = math.atan(0.004 / (math.pi * 0.016))
    alpha_n = math.atan(math.tan(15 * DEG) * math.cos(lam))
    at_worm = (15000 * 0.008 * math.tan(lam + math.atan(0.15 / math.cos(alpha_n)))
               * 0.025 / 0.08 * math.tan(4.76 * DEG + math.atan(0.05 / math.cos(20 * DEG))))
    speeds, torques = (260.75, 280.0, 300.0, 310.0, 314.16), (54.45, 49.43, 26.98, 8.43, 0.0)
    steady = np.interp(-at_worm, [-x for x in torques], speeds)
    assert result.status == "finished"
    assert [(p.regime, p.flank) for s in result.stages for p in s.phases] == [("tractive", "a")] * 2
    assert result.v0[-1] == pytest.approx(steady, rel=1e-7)
