"""Which mode a chain is in, decided for all stages at once, at the derived expressions' numbers.

The logic (tswm_common/chain_decision.py, which the runtime applies at its events too): every mode the stages' flanks allow is a candidate; a candidate is consistent when each stage's normal
force is >= 0 and, from rest, the chain breaks away in the candidate's own direction; resting is
consistent when the statics admit internal forces inside every stage's stick cone. Exactly one
consistent candidate is the answer. None, or several (a Painleve-type ambiguity of rigid contact
with friction, where a reduced inertia D < 0), is reported with the reason, never resolved by an
order of preference.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from derivation import mechanics as mech
from derivation.chain import dynamics as dyn
from tswm_common.chain_decision import Candidate, Decision, Statics, decide_numbers


@dataclass(frozen=True)
class ChainValues:
    """Numbers for a chain: per stage (equivalent wedge) and per body, in SI."""

    gamma: tuple[float, ...]
    rho: tuple[float, ...]
    lever_in: tuple[float, ...]
    lever_out: tuple[float, ...]
    inertia: tuple[float, ...]
    force: tuple[float, ...]
    flanks: tuple[tuple[str, ...], ...]        # modelled flanks per stage

    def args(self) -> tuple[float, ...]:
        return (*self.gamma, *self.rho, *self.lever_in, *self.lever_out, *self.inertia, *self.force)


def _arguments(stages: int) -> tuple[sp.Symbol, ...]:
    s = dyn.symbols(stages)
    return (*s.gamma, *s.rho, *s.lever_in, *s.lever_out, *s.inertia, *s.force)


@lru_cache(maxsize=None)
def _sliding_numbers(direction: int, regimes: tuple[str, ...]):
    """(a_0, D, N_1..N_N) of a sliding mode as a function of ChainValues.args()."""
    mode = dyn.sliding(direction, regimes)
    return sp.lambdify(_arguments(len(regimes)), (mode.accel, mode.denominator, *mode.normal), "math")


@lru_cache(maxsize=None)
def _psi_numbers(stages: int):
    """Each stage's FTFs (Psi_t, Psi_i) of forward sliding, from mechanics, as a function of the values."""
    sym = dyn.symbols(stages)
    psi = [tuple(mech.sliding(f, 1).psi.subs({mech.gamma: sym.gamma[i], mech.rho: sym.rho[i]}) for f in "ab")
           for i in range(stages)]
    return sp.lambdify(_arguments(stages), psi, "math")


def decide(values: ChainValues, velocity: float) -> Decision:
    """The chain's mode at speed ``velocity`` of body 0 under values.force."""
    directions = (1, -1) if velocity == 0 else (1 if velocity > 0 else -1,)
    candidates = []
    for direction, regimes in dyn.reachable(values.flanks, directions):
        accel, denominator, *normal = _sliding_numbers(direction, regimes)(*values.args())
        candidates.append(Candidate(dyn.sliding(direction, regimes).name, direction, accel, denominator,
                                    tuple(normal)))
    return decide_numbers(candidates, velocity, statics(values))


def statics(values: ChainValues) -> Statics:
    """The numbers the resting chain's decision takes: each stage's FTFs, levers, the bodies' forces."""
    psi = _psi_numbers(len(values.gamma))(*values.args())
    return Statics(tuple(tuple(s) for s in psi), values.lever_in, values.lever_out, values.force)
