"""Drive trains with a torque switch and a valve side against a reference written here by hand: Newton
per body, Coulomb per stage (tests/chains.py's HandChain), the motor cut by the switch, the
valve's friction and seat typed in directly, integrated by scipy's DOP853 at rtol 1e-12 from event to
event, its modes found by enumerating every flank combination."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp, trapezoid

from tests.chains import DEG, TIGHT, HandChain, wedges
from tswm_runtime.simulation.chain import simulate_chain

ARMED, PICKED, TRIPPED = "armed", "picked", "tripped"


class HandValve(HandChain):
    """HandChain with a motor the switch cuts for good, a Coulomb friction ``friction`` against the last
    body's motion and a seat spring k_seat (x_N - seat) on it beyond ``seat``. The switch measures stage
    ``on``'s force on its output body (on = 0: body 0's drive force), picks up at ``setting``, drops out
    below setting - hysteresis and cuts the motor ``delay`` after it picked up."""

    def __init__(self, *, friction=0.0, seat=math.inf, k_seat=0.0, on=None, setting=math.inf, hysteresis=0.0,
                 delay=0.0, **chain):
        super().__init__(**chain)
        self.friction, self.seat, self.k_seat = friction, seat, k_seat
        self.on, self.setting, self.hysteresis, self.delay = on, setting, hysteresis, delay
        self.state, self.t_pick, self.seated, self.s = ARMED, 0.0, False, 0

    def forces(self, q0, v0):
        F = self.F - self.k * self.c * q0
        if self.motor and self.state != TRIPPED:
            speeds, torques, voltage = self.motor
            F[0] += voltage**2 * np.interp(v0, speeds, torques)
        F[-1] -= self.s * self.friction
        if self.seated:
            F[-1] -= self.k_seat * (self.c[-1] * q0 - self.seat)
        return F

    def solve(self, q0, s, sigma, v0=0.0):
        self.s = s
        return super().solve(q0, s, sigma, v0)

    def stage_force(self, i, q0, s, sigma, v0):
        """Stage i's (0-based) force on its output body along that body's motion."""
        N = self.solve(q0, s, sigma, v0)[1][i]
        g = self.g[i]
        return self.r_out[i] * (sigma[i] * math.cos(g) - self.mu[i] * s * math.sin(g)) * N

    def measured(self, q0, s, sigma, v0):
        if self.on == 0:
            speeds, torques, voltage = self.motor
            return self.F[0] + voltage**2 * np.interp(v0, speeds, torques)
        return self.stage_force(self.on - 1, q0, s, sigma, v0)

    def run(self, v0, t_end):
        """[(t, s, sigma)] per phase (s = 0, sigma None: rest), the final (t, y), the samples (t, y, s, sigma,
        state, seated) at each phase's ends, and the trip (t, y, s, sigma, seated) (None: no trip)."""
        t, y, log, samples, trip = 0.0, np.array([0.0, v0]), [], [], None
        self.seated = self.c[-1] * y[0] >= self.seat
        if self.on == 0 and self.measured(y[0], 0, None, y[1]) >= self.setting:   # already above it at the start
            self.state, self.t_pick = PICKED, 0.0
        while t < t_end:
            if y[1] == 0.0:
                moves = [(s, sg) for s in (1, -1) for sg in self.consistent(y[0], s, True)]
                if not moves:
                    log.append((t, 0, None))
                    if self.on is not None and self.on == 0 and self.state == ARMED and \
                            self.measured(y[0], 0, None, 0.0) >= self.setting:
                        self.state, self.t_pick = PICKED, t
                    if self.state == PICKED and self.t_pick + self.delay < t_end:
                        t = self.t_pick + self.delay
                        self.state, trip = TRIPPED, trip or (t, y.copy(), 0, None)
                        continue
                    return log, t_end, y, samples, trip
                assert len(moves) == 1, moves
                s, sigma = moves[0]
            else:
                s = 1 if y[1] > 0 else -1
                found = self.consistent(y[0], s, False, v0=y[1])
                sigma = found[0] if len(found) == 1 else [f for f in found if f != log[-1][2]][0]
            log.append((t, s, sigma))
            samples.append((t, y.copy(), s, sigma, self.state, self.seated))
            events = [self._normal(i, s, sigma) for i in range(self.n)] + [self._stop(s), self._seat(),
                                                                          self._switch(s, sigma), self._delay()]
            sol = solve_ivp(lambda t, y: [y[1], self.solve(y[0], s, sigma, y[1])[0]], (t, t_end), y,
                            method="DOP853", rtol=1e-12, atol=1e-14, events=events)
            t, y = sol.t[-1], sol.y[:, -1].copy()
            samples.append((t, y.copy(), s, sigma, self.state, self.seated))
            fired = [k for k, times in enumerate(sol.t_events) if len(times)]
            if sol.status != 1:
                break
            kind = fired[0] - self.n
            if kind == 0:
                y[1] = 0.0
            elif kind == 1:
                self.seated = not self.seated
            elif kind == 2:
                self.state, self.t_pick = (PICKED, t) if self.state == ARMED else (ARMED, t)
            if (kind == 3 or (kind == 2 and self.delay == 0.0)) and self.state == PICKED:
                trip = (t, y.copy(), s, sigma, self.seated)
                self.state = TRIPPED
        return log, t, y, samples, trip

    def _seat(self):
        def event(t, y):
            x = self.c[-1] * y[0] - self.seat
            return x if self.seated else -x
        event.terminal, event.direction = True, -1
        return event

    def _switch(self, s, sigma):
        def event(t, y):
            if self.on is None or self.state == TRIPPED:
                return 1.0
            m = self.measured(y[0], s, sigma, y[1])
            return self.setting - m if self.state == ARMED else m - (self.setting - self.hysteresis)
        event.terminal, event.direction = True, -1
        return event

    def _delay(self):
        def event(t, y):
            return self.t_pick + self.delay - t if self.state == PICKED else 1.0
        event.terminal, event.direction = True, -1
        return event


MOTOR = ((0.0, 2.0), (100.0, 0.0), 1.0)     # force [N] over speed [m/s] of body 0, U / U_n
SPRING_TRIP = dict(gammas=(30.0, 20.0), mus=(0.1, 0.1), masses=(1.0, 1.0, 1.0), forces=(5.0, 0.0, -10.0),
                   spring=2000.0, motor=MOTOR)
SWITCH = dict(on=2, setting=60.0, hysteresis=5.0, delay=0.01)


def scene(name: str, chain: dict, switch: dict | None = None, valve: str = "", t_end: float = 0.5) -> str:
    """A wedge chain's scene with the motor on body 0, a [switch] table and valve keys on the last body."""
    text = wedges(name, chain["gammas"], chain["mus"], chain["masses"], chain["forces"], chain.get("spring", 0.0),
                  v0=0.0, t_end=t_end)
    speeds, forces, voltage = chain["motor"]
    text = text.replace("[[body]]\n", f"[[body]]\nmotor = {{ speed = {list(speeds)}, torque = {list(forces)}, "
                        f"voltage = {voltage} }}\n", 1)
    last = text.rindex("[[body]]\n") + len("[[body]]\n")
    text = text[:last] + valve + text[last:]
    if switch:
        on = "motor" if switch["on"] == 0 else f"stage {switch['on']}"
        text += (f'[switch]\non = "{on}"\nsetting = {switch["setting"]!r}\nhysteresis = {switch["hysteresis"]!r}\n'
                 f'delay = {switch["delay"]!r}\n')
    return text


def test_the_switch_trips_on_the_stage_force_as_the_hand_model(chain_module):
    """The motor drives the chain against a spring; stage 2's force picks the switch up, the motor is cut
    10 ms later, and the chain coasts to rest: pick-up, trip and rest times, the force at the trip and the
    final state agree with the hand model to 1e-9."""
    module = chain_module(scene("spring-trip", SPRING_TRIP, SWITCH))
    result = simulate_chain(module, **TIGHT)
    hand = HandValve(**SPRING_TRIP, **SWITCH)
    log, t_stop, y, samples, trip = hand.run(0.0, 0.5)
    assert trip is not None and result.trip is not None
    assert result.trip["t"] == pytest.approx(trip[0], rel=1e-9)
    hand.state = PICKED                   # just before the cut
    assert result.trip["thrust"] == pytest.approx(hand.stage_force(1, trip[1][0], trip[2], trip[3], trip[1][1]),
                                                  rel=1e-8)
    picks = [e["t"] for e in result.events if e["guard"] == "switch"]
    assert picks and picks[0] == pytest.approx(trip[0] - SWITCH["delay"], rel=1e-9)
    assert result.status == "finished"
    assert result.q0[-1] == pytest.approx(y[0], rel=1e-9)
    assert result.v0[-1] == pytest.approx(y[1], abs=1e-9)


MOTOR_SWITCH = dict(on=0, setting=70.0, hysteresis=5.0, delay=0.005)
RISING = dict(SPRING_TRIP, motor=((0.0, 2.0), (60.0, 100.0), 1.0))    # the drive force rises with speed


@pytest.mark.parametrize("chain", [SPRING_TRIP, RISING], ids=["above-at-start", "crossing"])
def test_the_switch_trips_on_the_motor_torque_as_the_hand_model(chain_module, chain):
    """on = "motor": body 0's drive force (5 N and the table's) is above the 70 N setting at the start with
    a falling table (picked up at t = 0, cut 5 ms later) and crosses it during the run-up with a rising
    one; the cut, the drive force there and the final state agree with the hand model."""
    module = chain_module(scene("motor-trip" if chain is SPRING_TRIP else "motor-rising", chain, MOTOR_SWITCH))
    result = simulate_chain(module, **TIGHT)
    hand = HandValve(**chain, **MOTOR_SWITCH)
    log, t_stop, y, samples, trip = hand.run(0.0, 0.5)
    assert result.status == "finished"
    assert result.trip["t"] == pytest.approx(trip[0], rel=1e-9)
    hand.state = PICKED
    assert result.trip["drive"] == pytest.approx(hand.measured(trip[1][0], trip[2], trip[3], trip[1][1]), rel=1e-8)
    assert result.q0[-1] == pytest.approx(y[0], rel=1e-9)
    assert result.v0[-1] == pytest.approx(y[1], rel=1e-9)


VALVE = dict(gammas=(30.0, 5.0), mus=(0.1, 0.15), masses=(1.0, 1.0, 1.0), forces=(0.0, 0.0, -5.0), motor=MOTOR)
VALVE_KEYS = ('packing = "2 N"\ndp = "1 kPa"\narea = "10 cm^2"\nvalve_factor = 0.5\nseat = "5 mm"\n'
              'seat_stiffness = "100 N/mm"\n')
SEAT = dict(friction=2.0 + 0.5 * 1e3 * 10e-4, seat=0.005, k_seat=1e5)
THRUST_SWITCH = dict(on=2, setting=300.0, hysteresis=20.0, delay=0.002)
LOOSE = dict(VALVE, mus=(0.1, 0.02))         # tan 5 deg = 0.0875 > 0.02: stage 2 does not self-lock


def hand_answers(chain: dict) -> dict:
    """The hand model's seat contact, trip, peak thrust after it, extra travel and final state."""
    hand = HandValve(**chain, **SEAT, **THRUST_SWITCH)
    log, t_stop, y, samples, trip = hand.run(0.0, 0.5)
    hand.state, hand.seated = PICKED, trip[4]
    thrust = hand.stage_force(1, trip[1][0], trip[2], trip[3], trip[1][1])
    hand.state = TRIPPED
    after = [(t, yy, s, sg, seated) for t, yy, s, sg, state, seated in samples if state == TRIPPED]
    peaks = []
    for t, yy, s, sg, seated in after:
        hand.seated = seated
        peaks.append((hand.stage_force(1, yy[0], s, sg, yy[1]), t))
    x = [hand.c[-1] * yy[0] for _, yy, *_ in after]
    return {"trip": trip[0], "thrust": thrust, "peak": max(peaks, key=lambda p: abs(p[0])),
            "extra": max(x) - hand.c[-1] * trip[1][0], "y": y, "log": log}


@pytest.mark.parametrize("chain, verdict", [(VALVE, "holds"), (LOOSE, "seat lost: no stage self-locks")],
                         ids=["self-locking", "back-driven"])
def test_trip_peak_and_hold_at_the_seat_as_the_hand_model(chain_module, chain, verdict):
    """The motor closes the valve against its packing, differential pressure and load onto the seat; stage
    2's force trips the switch. Trip time and thrust, the peak thrust after the trip (the rotor's
    overrun into the seat), the extra travel and the final state agree with the hand model; with stage 2
    self-locking (tan 5 deg < 0.15) the chain rests on the seat after power off, without (0.02) the seat
    and the load back-drive it off the seat."""
    name = "valve-hold" if chain is VALVE else "valve-loose"
    module = chain_module(scene(name, chain, THRUST_SWITCH, VALVE_KEYS))
    result = simulate_chain(module, **TIGHT)
    hand = hand_answers(chain)
    answers = result.answers
    assert result.status == "finished"
    assert answers["trip"]["t"] == pytest.approx(hand["trip"], rel=1e-9)
    assert answers["trip"]["thrust"] == pytest.approx(hand["thrust"], rel=1e-8)
    assert answers["peak_after_trip"]["thrust"] == pytest.approx(hand["peak"][0], rel=1e-8)
    assert answers["peak_after_trip"]["t"] == pytest.approx(hand["peak"][1], rel=1e-9)
    assert answers["extra_travel"] == pytest.approx(hand["extra"], rel=1e-7)
    assert answers["holds"]["verdict"] == verdict
    assert (answers["holds"]["self_locking"] == [2]) == (math.tan(5 * DEG) <= chain["mus"][1])
    assert result.q0[-1] == pytest.approx(hand["y"][0], rel=1e-9)
    assert result.v0[-1] == pytest.approx(hand["y"][1], abs=1e-9)



def test_energy_over_a_trip_and_coast_run(chain_module):
    """Kinetic energy change = motor work + the load's work - the stages' Coulomb losses - the valve's work
    (its friction and its seat's spring), each written here from the run's states and normal forces:
    motor and friction by the trapezoid rule over 200001 output points, the load and the seat in closed
    form between each phase's ends; they balance to 1e-6 of the motor's work."""
    from tswm_runtime.chains.run import RESTING, run_chain

    module = chain_module(scene("valve-hold", VALVE, THRUST_SWITCH, VALVE_KEYS))
    run = run_chain(module, t_end=0.5, v0=0.0, t_out=np.linspace(0.0, 0.5, 200001), **TIGHT)
    assert run.status == "finished" and run.trip is not None
    speeds, forces, voltage = MOTOR
    c = run.p[module.P_SPEED:module.P_SPEED + module.STAGES + 1]
    mass, gammas, mus = np.array(VALVE["masses"]), np.radians(VALVE["gammas"]), np.array(VALVE["mus"])
    motor = load = losses = valve = 0.0
    for phase in (p for p in run.phases if p.mode != RESTING):
        t = np.array([s[0] for s in phase.samples])
        q, v = np.array([s[1] for s in phase.samples]).T
        normal = np.array([s[2][2::3] for s in phase.samples])
        powered = phase.latches[module.P_SWITCH] != module.TRIPPED
        motor += powered * trapezoid(voltage**2 * np.interp(v, speeds, forces) * v, t)
        load += sum(F * c_j * (q[-1] - q[0]) for F, c_j in zip(VALVE["forces"], c))
        slip = np.abs(np.outer(v, c[:-1])) / np.cos(gammas)          # each stage's input speed along its flank
        losses += trapezoid((mus * normal * slip).sum(axis=1), t)
        valve += SEAT["friction"] * trapezoid(np.abs(c[-1] * v), t)
        if phase.latches[module.P_SEATED]:
            x = c[-1] * q - SEAT["seat"]
            valve += 0.5 * SEAT["k_seat"] * (x[-1]**2 - x[0]**2)
    kinetic = 0.5 * (mass * c**2).sum() * (run.y[-1, 1]**2 - 0.0)
    assert motor > 1.0 and valve > 0.1 * motor
    assert kinetic == pytest.approx(motor + load - losses - valve, abs=1e-6 * motor)


PACKING = dict(gammas=(30.0,), mus=(0.1,), masses=(1.0, 1.0), forces=(0.0, 0.0))
PACKING_KEYS = 'packing = "2 N"\ndp = "1 bar"\npacking_dp = "20 mm^2"\narea = "10 cm^2"\nvalve_factor = 0.01\n'


def test_the_packing_friction_grows_with_the_pressure_as_the_hand_model(chain_module):
    """packing 2 N + packing_dp dp = 20 mm^2 x 1 bar = 2 N, and the disc's 0.01 x 1 bar x 10 cm^2 = 1 N: 5 N
    against the stem's motion (by hand). The module's friction at that dp is 5 N; a wedge coasting from 1 m/s
    against it stops and rests when and where the hand model (Newton per body, Coulomb per stage, the
    5 N typed in) does, to 1e-9."""
    friction = 2.0 + 20e-6 * 1e5 + 0.01 * 1e5 * 10e-4
    assert friction == pytest.approx(5.0, rel=1e-14)
    text = wedges("packing-dp", **PACKING, v0=1.0, t_end=0.5)
    last = text.rindex("[[body]]\n") + len("[[body]]\n")
    module = chain_module(text[:last] + PACKING_KEYS + text[last:])
    from tswm_runtime.chains.run import latches

    assert latches(module, np.zeros(2))[module.P_SLACK] == pytest.approx(friction, rel=1e-14)
    result = simulate_chain(module, **TIGHT)
    log, _, y, _, _ = HandValve(**PACKING, friction=friction).run(1.0, 0.5)
    assert [(p.regime, p.flank) for p in result.stages[0].phases] == [("tractive", "a"), ("resting", "")]
    assert [s for _, s, _ in log] == [1, 0]
    assert result.stages[0].switches[0] == pytest.approx(log[1][0], rel=1e-9)
    assert result.q0[-1] == pytest.approx(y[0], rel=1e-9) and result.v0[-1] == 0.0


def test_the_shipped_mov_module_is_fresh():
    """generated/mov.py is what the generator makes of derivation/chain/scenes/mov.toml today."""
    from pathlib import Path

    from derivation.chain.codegen import generate_chain_module
    from derivation.chain.scene import load_chain, shipped_chains

    assert "mov" in shipped_chains()
    shipped = Path(__file__).resolve().parents[1] / "generated" / "mov.py"
    assert shipped.read_text() == generate_chain_module(load_chain("mov"))


def test_switch_and_valve_keys_are_refused_with_their_names():
    from derivation.chain.scene import parse_chain
    from derivation.scene import SceneError

    good = scene("keys", VALVE, THRUST_SWITCH, VALVE_KEYS)
    parse_chain(good, "k.toml")
    for old, new, parts in (
            ('on = "stage 2"', 'on = "stage 3"', ('switch.on = "stage 3"', '"motor", "stage 1", "stage 2"')),
            ("hysteresis = 20.0", "hysteresis = 300.0", ("switch.hysteresis", "below switch.setting")),
            ("delay = 0.002", "delay = -1.0", ("switch.delay",)),
            ('seat_stiffness = "100 N/mm"\n', "", ("seat_stiffness", "missing required key")),
            ('dp = "1 kPa"', 'dp = "1 kg"', ("dp",)),
            ('dp = "1 kPa"', 'dp = "1 kPa"\npacking_dp = "-1 mm^2"', ("body[2].packing_dp = -1 mm^2", ">= 0")),
            ('dp = "1 kPa"', 'dp = "1 kPa"\npacking_dp = "1 N"', ("body[2].packing_dp", "force unit")),
            ("[switch]", "[switch]\ncolour = 1", ("switch.colour: unknown key",))):
        assert old in good, old
        with pytest.raises(SceneError) as err:
            parse_chain(good.replace(old, new, 1), "k.toml")
        for part in parts:
            assert part in str(err.value), str(err.value)
    with pytest.raises(SceneError, match=r"body\[1\].packing: unknown key"):
        parse_chain(good.replace("[[body]]\n", '[[body]]\npacking = "1 N"\n', 2).replace(
            'packing = "1 N"\n', "", 1), "k.toml")


def test_tswm_simulate_mov_prints_the_answers(tmp_path, capsys):
    """`tswm simulate mov` by name: the trip, the peak after it above the thrust at the trip (the rotor's
    overrun), the hold by the stem nut alone: by the closed form the Tr 18x4 thread self-locks
    (tan(lambda) = 4 / (16 pi) = 0.0796 < 0.15 / cos(alpha_n)) and the worm gear does not
    (tan 4.76 deg = 0.0833 > 0.05 / cos 20 deg = 0.0532); -o writes the summary and the figure."""
    import json

    from tswm_runtime.cli import main

    lam = math.atan(0.004 / (math.pi * 0.016))
    alpha_n = math.atan(math.tan(15 * DEG) * math.cos(lam))
    assert math.tan(lam) < 0.15 / math.cos(alpha_n) and math.tan(4.76 * DEG) > 0.05 / math.cos(20 * DEG)
    assert main(["simulate", "mov", "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "chain mov (2 stages, generated/mov.py)" in out and "status: finished" in out
    assert "after power off: holds; self-locking: stage 2 (power_screw" in out and "stage 1 (worm_gear, Psi" not in out
    answers = json.loads((tmp_path / "mov-summary.json").read_text())["answers"]
    assert answers["peak_after_trip"]["thrust"] > answers["trip"]["thrust"] >= 20e3 > 0 < answers["extra_travel"]
    assert answers["trip"]["travel"] >= 0.010 and answers["stall_margin"] > 1
    assert (tmp_path / "mov-stages.png").stat().st_size > 10_000


def test_tswm_sweep_mov_gives_a_sizing_table_and_keeps_failed_cases(tmp_path, capsys, monkeypatch):
    """`tswm sweep mov` over voltage and mu_2: one row per case, all on the shipped module (nothing is generated
    into the user cache); the scene's own case equals `tswm simulate mov`'s answers; the stall margin times
    the trip thrust scales as (U/U_n)^2 (its definition: pull-out torque over the torque the trip thrust
    needs); a case whose mu_2 is refused keeps its status and the sweep goes on; a bad --grid exits 2 naming
    it."""
    import pandas as pd

    from tswm_runtime.cli import main
    from tswm_runtime.model.contract import load_module

    monkeypatch.setenv("TSWM_CACHE", str(tmp_path / "cache"))
    assert main(["sweep", "mov", "--grid", "voltage=0.8,1.0", "--grid", "mu_2=0.15,11", "-o", str(tmp_path),
                 "--no-progress"]) == 0
    assert "chain mov: sizing table, 4 cases" in capsys.readouterr().out
    table = pd.read_csv(tmp_path / "mov-sizing.csv")
    refused = "error: parameter mu_2 = 11: must be >= 0 and < 10 (stage[2].mu in the scene file)"
    assert list(table["status"]) == ["finished", refused] * 2           # the first --grid item varies slowest
    assert not (tmp_path / "cache").exists()
    low, nominal = table.iloc[0], table.iloc[2]
    answers = simulate_chain(load_module("mov")).answers
    assert nominal["thrust at trip [N]"] == pytest.approx(answers["trip"]["thrust"], rel=1e-12)
    assert nominal["peak after trip [N]"] == pytest.approx(answers["peak_after_trip"]["thrust"], rel=1e-12)
    assert nominal["stall margin"] == pytest.approx(answers["stall_margin"], rel=1e-12)
    assert (low["stall margin"] * low["thrust at trip [N]"]) / (nominal["stall margin"] * nominal["thrust at trip [N]"]) \
        == pytest.approx(0.64, rel=1e-12)
    assert list(table["holds"][::2]) == ["holds", "holds"]
    assert main(["sweep", "mov", "--grid", "mu_3=0.1"]) == 2
    assert "--grid 'mu_3': chain scene 'mov' has no such value (values: lead_angle_1," in capsys.readouterr().err
