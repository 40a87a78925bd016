"""Laws of a drive train checked on simulated chains against closed forms written here by hand.

The hand formulas, for a stage of slope gamma (a worm's lead angle, a thread's lead angle lambda with
tan(lambda) = L / (pi d_m), a wedge's angle) and a flank that is tilted out of the plane of motion by
its normal angle alpha_n: the flank's normal force N has the in-plane part N cos(alpha_n), the
friction mu N lies in the plane (along the slip), so in the plane the stage is a plain wedge with
tan(rho') = mu / cos(alpha_n). A worm's alpha_n is its normal pressure angle; a thread's flank angle
alpha lies in the axial section, and its normal-section angle is tan(alpha_n) = tan(alpha) cos(lambda).
A wedge driven at its input (power input -> output) has the efficiency tan(gamma) / tan(gamma + rho'),
driven back from its output tan(gamma - rho') / tan(gamma); it self-locks (cannot be back-driven)
when rho' >= gamma. Transmission: a worm turns its wheel at omega_2 = omega_1 r_1 tan(gamma) / r_2, a
nut moves its stem by L per turn, a wedge its output at tan(gamma) times its input's speed.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from derivation.chain.scene import parse_chain
from derivation.chain.selector import decide
from tests.chains import DEG, EXAMPLES, TIGHT, HandChain, wedges
from tswm_runtime.simulation.chain import simulate_chain

# ---- a worm gear, a stem nut and a wedge in series, by hand -----------------------------------------

class Train:
    """Worm (gamma_1, alpha_n, r_1 -> r_2, mu_1) -> nut (lead L, mean diameter d_m, flank angle alpha, mu_2)
    -> wedge (gamma_3, mu_3): bodies worm, wheel and nut, stem, wedge output. Closed forms by hand."""

    def __init__(self, worm_gamma=12.0, worm_mu=0.05, lead=12e-3, screw_mu=0.1, wedge_gamma=30.0, wedge_mu=0.1):
        self.worm_gamma, self.worm_mu, self.lead, self.screw_mu = worm_gamma, worm_mu, lead, screw_mu
        self.wedge_gamma, self.wedge_mu = wedge_gamma, wedge_mu
        lam = math.atan(lead / (math.pi * 0.016))
        thread_normal = math.atan(math.tan(15 * DEG) * math.cos(lam))
        self.gamma = (worm_gamma * DEG, lam, wedge_gamma * DEG)
        self.rho = (math.atan(worm_mu / math.cos(20 * DEG)), math.atan(screw_mu / math.cos(thread_normal)),
                    math.atan(wedge_mu))
        self.ratio = (0.02 * math.tan(worm_gamma * DEG) / 0.08, lead / (2 * math.pi), math.tan(wedge_gamma * DEG))
        self.lever_in = (0.02, 0.008, 1.0)       # the worm's and the nut's pitch radius: slip speeds from them

    def forward(self, k: int) -> float:
        return math.tan(self.gamma[k]) / math.tan(self.gamma[k] + self.rho[k])

    def backward(self, k: int) -> float:
        return math.tan(self.gamma[k] - self.rho[k]) / math.tan(self.gamma[k])

    def self_locks(self, k: int) -> bool:
        return self.rho[k] >= self.gamma[k]

    def speed(self, j: int) -> float:
        """v_j / v_0 of body j."""
        return math.prod(self.ratio[:j])

    def scene(self, name: str, torque: float, load: float, v0: float, t_end: float = 0.1) -> str:
        return f"""name = "{name}"
[[stage]]
kind = "worm_gear"
lead_angle = "{self.worm_gamma!r} deg"
pressure_angle = "20 deg"
worm_radius = "20 mm"
wheel_radius = "80 mm"
mu = {self.worm_mu!r}
[[stage]]
kind = "power_screw"
lead = "{self.lead * 1e3!r} mm"
flank_angle = "15 deg"
mean_diameter = "16 mm"
mu = {self.screw_mu!r}
[[stage]]
kind = "wedge"
gamma = "{self.wedge_gamma!r} deg"
mu = {self.wedge_mu!r}
[[body]]
inertia = "0.001 kg m^2"
torque = "{torque!r} N m"
[[body]]
inertia = "0.005 kg m^2"
[[body]]
mass = "2 kg"
[[body]]
mass = "5 kg"
force = "{load!r} N"
[run]
t_end = {t_end!r}
v0 = {v0!r}
"""


LOAD = -1000.0          # N on the wedge's output: it pushes the train back
SPEED = 100.0           # rad/s of the worm


def _mode(module, direction: int, regime: str) -> int:
    return next(m for m, (d, r) in enumerate(zip(module.MODE_DIRECTION, module.MODE_REGIMES))
                if d == direction and set(r) == {regime})


def _stage_forces(module, mode: int, t: float, y, p: np.ndarray) -> np.ndarray:
    """The module's stage forces in ``mode`` at (t, y) under the run's p (its values and derived slots)."""
    out = np.empty(3 * module.STAGES)
    module.stage_forces(mode, t, np.asarray(y, float), p, out)
    return out


@pytest.mark.parametrize("flow", ["forward", "backward"])
def test_steady_efficiency_of_each_stage_and_of_the_chain(chain_module, flow):
    """Forward: the worm's torque the product of the hand efficiencies asks for, -LOAD v_3 / (eta v_0), lifts
    the load at exactly steady speed; backward: the load drives the train back against the brake torque
    eta_back (-LOAD) v_3 / v_0 at steady speed. From the simulated contact forces each stage's efficiency
    (power out over power in) is its closed form, and the chain's is their product."""
    hand = Train()
    etas = [hand.forward(k) if flow == "forward" else hand.backward(k) for k in range(3)]
    eta = math.prod(etas)
    at_input = -LOAD * hand.speed(3)          # the load's torque at the worm, N m
    torque, direction, regime = ((at_input / eta, 1, "tractive") if flow == "forward"
                                 else (eta * at_input, -1, "inverse-tractive"))
    module = chain_module(hand.scene(f"steady-{flow}", torque, LOAD, direction * SPEED))
    result = simulate_chain(module, points=101, **TIGHT)
    assert result.status == "finished"
    assert [(p.regime, p.flank) for s in result.stages for p in s.phases] == [(regime, "a")] * 3
    # steady: a 1e-3 error in eta would change v_0 by 0.3 rad/s over the run
    assert np.max(np.abs(result.v0 - direction * SPEED)) <= 1e-8 * SPEED
    mode = _mode(module, direction, regime)
    for t, q0, v0 in zip(result.t, result.q0, result.v0):
        forces = _stage_forces(module, mode, t, (q0, v0), result.p)
        measured = []
        for k in range(3):
            on_input, on_output = forces[3 * k] * hand.speed(k), forces[3 * k + 1] * hand.speed(k + 1)
            # power the stage takes from its input body and gives to its output body, per unit v_0
            measured.append(on_output / -on_input if flow == "forward" else -on_input / on_output)
        assert measured == pytest.approx(etas, rel=1e-9)
        chain = (-LOAD * hand.speed(3) / torque) if flow == "forward" else (torque / (-LOAD * hand.speed(3)))
        assert math.prod(measured) == pytest.approx(chain, rel=1e-9)


# ---- back-drivable iff no stage self-locks: a grid around each stage's boundary ------------------------

def _limit(hand: Train, k: int) -> float:
    """The mu at which stage k starts to self-lock (rho' = gamma), by hand."""
    if k == 0:
        return math.tan(hand.gamma[0]) * math.cos(20 * DEG)
    if k == 1:
        return math.tan(hand.gamma[1]) * math.cos(math.atan(math.tan(15 * DEG) * math.cos(hand.gamma[1])))
    return math.tan(hand.gamma[2])


MU_KEYS = ("worm_mu", "screw_mu", "wedge_mu")


@pytest.mark.heavy
@pytest.mark.parametrize("stage", (0, 1, 2), ids=("worm", "screw", "wedge"))
def test_back_drivable_iff_no_stage_self_locks(stage):
    """The load alone (no torque on the worm) starts the resting train backward exactly when no stage
    self-locks. Grid: stage ``stage``'s lead angle over three values and its mu from 0.8 to 1.2 times its
    self-locking limit; every other stage either well below its limit or just above it."""
    geometry = {0: [("worm_gamma", g) for g in (3.0, 8.0, 20.0)], 1: [("lead", lead) for lead in (3e-3, 6e-3, 12e-3)],
                2: [("wedge_gamma", g) for g in (4.0, 10.0, 25.0)]}[stage]
    checked = {True: 0, False: 0}
    for key, value in geometry:
        for others_lock in (False, True):
            for factor in (0.8, 0.9, 0.97, 0.995, 1.005, 1.03, 1.1, 1.2):
                base = Train(**{key: value})
                mus = {MU_KEYS[k]: (1.02 if others_lock and k == (stage + 1) % 3 else 0.5) * _limit(base, k)
                       for k in range(3)}
                mus[MU_KEYS[stage]] = factor * _limit(base, stage)
                hand = Train(**{key: value}, **mus)
                locks = [hand.self_locks(k) for k in range(3)]
                assert locks[stage] == (factor > 1)
                decision = decide(parse_chain(hand.scene("grid", 0.0, LOAD, 0.0), "grid").values(), 0.0)
                assert decision.outcome == "unique", decision.reason
                back_drivable = not any(locks)
                assert (decision.modes[0] != "stuck") == back_drivable, (key, value, mus, decision)
                if back_drivable:
                    assert decision.modes[0].startswith("backward") and decision.accel < 0
                checked[back_drivable] += 1
    assert checked[True] >= 12 and checked[False] >= 24


# ---- energy balance per stage over a run with mode changes ---------------------------------------------

SWITCHING = wedges("energy-switching", (30.0, 25.0), (0.1, 0.12), (1.0, 1.5, 1.0), (5.0, 0.0, 20.0), spring=1000.0)
GAMMA, MU, MASS, FORCE, STIFFNESS = (30 * DEG, 25 * DEG), (0.1, 0.12), (1.0, 1.5, 1.0), (5.0, 0.0, 20.0), 1000.0


def _modes_at(module, result) -> list[int]:
    """The module's mode at each output point, from each stage's phases and the sign of v_0."""
    modes = []
    for t, v in zip(result.t, result.v0):
        phases = [next(p for p in s.phases if p.t_start <= t <= p.t_end) for s in result.stages]
        regimes, flanks = tuple(p.regime for p in phases), tuple(p.flank for p in phases)
        modes.append(next(m for m in range(len(module.MODES)) if module.MODE_REGIMES[m] == regimes
                          and module.MODE_FLANKS[m] == flanks and module.MODE_DIRECTION[m] == (1 if v > 0 else -1)))
    return modes


def test_kinetic_energy_change_is_input_work_less_each_stages_friction_work(chain_module):
    """A spring on the last body first drives the chain, then turns it back: both stages change flank and
    the chain changes direction. At every output point each stage's power balance holds (power in from
    one body less power out to the other = Coulomb's tan(rho) N times the slip speed |v_in| / cos(gamma),
    from the simulated normal force); over the run each body's kinetic energy changes by the work of its
    forces and stage forces, and the chain's by the input work less every stage's friction work."""
    module = chain_module(SWITCHING)
    result = simulate_chain(module, points=40001, **TIGHT)
    assert result.status == "finished"
    assert [len(s.switches) for s in result.stages] == [2, 2] and any(e["guard"] == "v0" for e in result.events)
    speed = np.cumprod([1.0, math.tan(GAMMA[0]), math.tan(GAMMA[1])])
    forces = np.array([_stage_forces(module, m, t, (q, v), result.p)
                       for m, t, q, v in zip(_modes_at(module, result), result.t, result.q0, result.v0)])
    dq0 = np.diff(result.q0)
    mid = lambda x: (x[1:] + x[:-1]) / 2           # noqa: E731  trapezoid in q_0 between output points
    scale = FORCE[0] * np.max(np.abs(result.q0))   # the work the drive does, J
    friction = []
    for k in range(2):
        on_input, on_output, normal = forces[:, 3 * k], forces[:, 3 * k + 1], forces[:, 3 * k + 2]
        slip = np.abs(result.v0 * speed[k]) / math.cos(GAMMA[k])
        loss = -(on_input * speed[k] + on_output * speed[k + 1]) * result.v0
        assert loss == pytest.approx(MU[k] * normal * slip, rel=1e-9, abs=1e-9 * scale)
        friction.append(np.sum(mid(MU[k] * normal / math.cos(GAMMA[k]) * speed[k]) * np.abs(dq0)))
    assert min(friction) > 0.01 * scale
    q_end, kinetic = result.q0[-1], 0.5 * np.array(MASS) * speed**2 * (result.v0[-1]**2 - result.v0[0]**2)
    external = np.array(FORCE) * speed * q_end - np.array([0, 0, 0.5 * STIFFNESS * (speed[2] * q_end)**2])
    stage_on_body = np.zeros((len(dq0), 3))
    for k in range(2):
        stage_on_body[:, k] += mid(forces[:, 3 * k]) * speed[k] * dq0
        stage_on_body[:, k + 1] += mid(forces[:, 3 * k + 1]) * speed[k + 1] * dq0
    assert kinetic == pytest.approx(external + stage_on_body.sum(axis=0), abs=1e-7 * scale)
    assert kinetic.sum() == pytest.approx(external.sum() - sum(friction), abs=1e-7 * scale)


# ---- MSL issue 4000: a lifting table held by its gears with both drive and load applied --------------

MSL = EXAMPLES / "msl4000.toml"
MSL_LAMBDA = math.atan(0.010 / (math.pi * 0.016))
MSL_GAMMA = (20 * DEG, MSL_LAMBDA)
MSL_TAN_RHO = (0.05 / math.cos(20 * DEG), 0.05 / math.cos(math.atan(math.tan(15 * DEG) * math.cos(MSL_LAMBDA))))
MSL_WEIGHT_AT_WORM = 1962.0 * 0.02 * math.tan(20 * DEG) / 0.08 * 0.010 / (2 * math.pi)   # ideal ratios, N m


def _msl_band() -> tuple[float, float]:
    """(lowest, highest) worm torque that holds the table, from each stage's efficiencies by hand."""
    rho = [math.atan(t) for t in MSL_TAN_RHO]
    forward = math.prod(math.tan(g) / math.tan(g + r) for g, r in zip(MSL_GAMMA, rho))
    backward = math.prod(math.tan(g - r) / math.tan(g) for g, r in zip(MSL_GAMMA, rho))
    return MSL_WEIGHT_AT_WORM * backward, MSL_WEIGHT_AT_WORM / forward


def test_msl4000_holding_band_is_the_product_of_the_efficiencies():
    """The scene's 0.3 N m lies between the torque that lowers the table (0.1744 N m) and the one that lifts it
    (0.4228 N m): the chain rests, the only consistent mode. 1 % outside the band it breaks away, lifting
    (both stages tractive) or lowering (both inverse-tractive)."""
    low, high = _msl_band()
    assert low == pytest.approx(0.17435, abs=1e-5) and high == pytest.approx(0.42275, abs=1e-5)
    text = MSL.read_text()
    assert 'torque = "0.3 N m"' in text
    for torque, expected in ((0.99 * low, "backward: inverse-tractive (a), inverse-tractive (a)"), (1.01 * low, "stuck"),
                             (0.3, "stuck"), (0.99 * high, "stuck"), (1.01 * high, "forward: tractive (a), tractive (a)")):
        decision = decide(parse_chain(text.replace('torque = "0.3 N m"', f'torque = "{torque!r} N m"'), "msl").values(),
                          0.0)
        assert (decision.outcome, decision.modes) == ("unique", (expected,)), (torque, decision.reason)


def test_msl4000_rests_and_started_upward_stops_and_stays_as_the_hand_model(chain_module):
    """From rest the run rests to its end (one decision: the only consistent mode); started lifting at
    20 rad/s it slows down in the tractive mode, stops when Newton per body with Coulomb per stage says,
    and stays: the table does not lower itself."""
    module = chain_module(MSL.read_text())
    held = simulate_chain(module)
    assert held.status == "finished" and [e["to"] for e in held.events] == ["resting"]
    assert held.events[0]["outcome"] == "unique" and np.all(held.v0 == 0.0)
    hand = HandChain([math.degrees(g) for g in MSL_GAMMA], MSL_TAN_RHO, (0.001, 0.004, 200.0), (0.3, 0.0, -1962.0),
                     levers=[(0.02, 0.08), (0.008, 1.0)])
    log, _, y = hand.run(20.0, 1.0)
    assert [(s, sigma) for _, s, sigma in log] == [(1, (1, 1)), (0, None)]
    lifted = simulate_chain(module, v0=20.0, **TIGHT)
    assert [(p.regime, p.flank) for p in lifted.stages[1].phases] == [("tractive", "a"), ("resting", "")]
    assert lifted.stages[0].switches[0] == pytest.approx(log[1][0], rel=1e-9)
    assert lifted.q0[-1] == pytest.approx(y[0], rel=1e-9) and lifted.v0[-1] == 0.0
