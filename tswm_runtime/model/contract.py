"""The contract between a generated model module and the runtime, written down once.

A generated module (``tswm generate``) provides the names below; ``check_module`` tells
a stale or foreign module apart with an error that names what is missing.
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from tswm_runtime.jit import cache_guard  # noqa: F401  (numba cache I/O errors never fail a run)

CONSTANTS = {
    "SCENE": "scene name",
    "SCENE_DIGEST": "sha256 of the scene file the module was generated from",
    "EQUATIONS": "'consistent' or 'literal'",
    "STATES": "state names: ('v1',) or ('x1', 'v1'), with a clearance ('x1', 'gap', 'gap_rate', 'v1'), "
              "with lost motion ('x1', 'x3', 'v3', 'v1'); v1 is "
              "always last; without x1 the runtime integrates v1 for it",
    "MODES": "mode names, indexed by the integer mode",
    "MODE_REGIME": "regime of each mode (tractive, inverse-tractive, backward on flank a/b, stick, "
                   "sliding along phi = 0)",
    "MODE_FLANK": "+1 flank a, -1 flank b, 0 stick or sliding along phi = 0",
    "MODE_DIRECTION": "sign of v1 in each mode, 0 for stick",
    "MODE_DECLARED": "per mode: whether a run may enter it (False: slide mode the scene does not declare)",
    "PARAM_NAMES": "free parameters, in the order of the vector p",
    "DESCRIPTION": "the scene's description, as written (data only)",
    "LATCH_NAMES": "the slots of p after the free parameters, len(p) = len(PARAM_NAMES) + len(LATCH_NAMES): "
                   "latched event times (+inf until their guard fires), then each piecewise law's piece "
                   "(set by the runtime at the start and at every event of the law)",
    "GUARD_LATCH": "per guard, the index in p of the latch it sets (a trip time or a law's piece), -1 none",
    "GUARD_PIECES": "per guard, the number of pieces of the law whose piece it latches, 0 none; that guard is "
                    ">= 0 while the state lies in the latched piece and falls through 0 where it leaves it",
    "MODE_D": "per mode, the formula of its denominator D ('' where it has none), for messages",
    "PARAM_CHECKS": "the scene file's rules that involve a free parameter, as data (tswm_runtime.model.checks)",
    "PARAM_UNITS": "SI unit of each free parameter",
    "PARAM_DEFAULTS": "scene value of each free parameter",
    "FIXED": "fixed parameters folded into the code: name -> value",
    "GUARDS": "names of the event functions, in the order guards() fills them",
    "GUARD_DIRECTIONS": "per mode, per guard: -1 falling, +1 rising, 0 either way",
    "OBSERVABLES": "names of the quantities observe() fills: ('S1', 'S2')",
    "OUTPUTS": "names of the quantities outputs() fills: ('a1', 'S1', 'S2', 'F1', 'F2')",
    "HAS_LOAD_FACTORS": "whether load_factors() exists (the scene gives Ft1, Ft2)",
    "RUN": "the scene's run settings: t_end, x1, v1, rtol, atol, method, max_steps",
}
FUNCTIONS = {
    "rhs": "rhs(mode, t, y, p, dy): dy = d(states)/dt; explicit signature RHS_SIG",
    "jac": "jac(mode, t, y, p, J, dfdt): J = df/dy, dfdt = df/dt; explicit signature JAC_SIG",
    "guards": "guards(mode, t, y, p, g): event functions; inactive ones are 1.0; signature GUARDS_SIG",
    "observe": "observe(mode, t, y, p, out): out = OBSERVABLES of `mode` (its reactions); signature GUARDS_SIG",
    "outputs": "outputs(mode, t, y, p, out): out = OUTPUTS of `mode` at an output row; signature GUARDS_SIG",
    "impact": "impact(flank, t, y, p, out): the frame of a collision on flank +1 (a) or -1 (b) (codegen.IMPACT_FRAME), "
              "or with lost motion of the stem's pickup (flank 0, codegen.PICKUP_FRAME); NaN without either; "
              "signature GUARDS_SIG",
    "body2": "body2(x1, v1, gap, gap_rate, p) -> (x2, v2), plain Python on arrays (gap, gap_rate unused without "
             "a clearance)",
    "accel": "accel(mode, t, y, p) -> a1",
    "reactions": "reactions(mode, t, y, p) -> (S1, S2)",
    "switching": "switching(t, y, p) -> phi, zero where the contact force is",
    "drive_force": "drive_force(t, y, p) -> F1",
    "load_force": "load_force(t, y, p) -> F2",
}


# A chain module (derivation/chain/codegen.py, run by tswm_runtime/chains/run.py) provides these instead.
CHAIN_CONSTANTS = {
    "SCENE": "scene name", "SCENE_DIGEST": "sha256 of the scene file", "DESCRIPTION": "the scene's description",
    "STAGES": "number of stages N", "STATES": "('q0', 'v0'): body 0's coordinate and speed; with a clearance in stage k also ('qk', 'vk'), "
              "with several ('qcur', 'vcur'): the current clearance stage's body (the module's CLEARANCE_STAGES, OPEN, P_CONTACT, P_CURRENT, ... describe it: docs/drive-trains.md)",
    "MODES": "sliding mode names: direction and each stage's regime and flank",
    "MODE_DIRECTION": "sign of v0 per mode", "MODE_REGIMES": "per mode, each stage's regime",
    "MODE_FLANKS": "per mode, each stage's loaded flank", "STAGE_KINDS": "per stage its kind",
    "BODY_MOTIONS": "per body 'rotation' or 'translation'",
    "GUARDS": "('D', 'jam', 'N_1', ..., 'N_N', 'v0', 'seat', 'switch', 'delay')",
    "GUARD_DIRECTIONS": "per mode, per guard",
    "OBSERVABLES": "() (observe writes the stage forces, whose maxima the chain kernel locates)", "RUN": "t_end, v0, rtol, atol, max_steps",
    "PARAM_NAMES": "the scene's values, slots P_VALUES.. of p", "PARAM_UNITS": "their SI units",
    "PARAM_KEYS": "their scene keys", "PARAM_DEFAULTS": "the scene's values in SI",
    "PARAM_RANGES": "per value (lo, hi, lo included, hi included); hi may name another value",
    "DERIVED": "what prepare(p) derives into the slots P_DERIVED..",
    "P_NAMES": "every slot of p: the latches ('switch', 't_pick', 'seated', 'voltage'; the first three set by the "
               "runtime at its events), the values, the derived slots, then a motor's table (MOTOR_SPEED, "
               "MOTOR_TORQUE: MOTOR_POINTS each from P_MOTOR_SPEED, P_MOTOR_TORQUE, copied in by the runtime)",
    "P_VALUES": "first value slot", "P_DERIVED": "first derived slot", "P_GAMMA": "per stage its slope",
    "P_RHO": "per stage its friction angle", "P_PSI": "per stage Psi_t, Psi_i of forward sliding",
    "P_LEVER_IN": "per stage", "P_LEVER_OUT": "per stage", "P_SPEED": "v_j / v_0 per body",
    "P_SLACK": "the valve's Coulomb friction magnitude", "P_DELAY": "s from the switch's pick-up to the motor's cut",
    "P_SEAT": "the seat's travel on the last body (-1: no seat)",
    "SWITCH_ON": "-1: no torque switch, 0: on body 0's drive torque, k: on stage k's force on its output body",
    "HAS_SEAT": "whether the last body has a seat",
}
CHAIN_FUNCTIONS = {
    "rhs": "as above", "jac": "as above", "guards": "as above", "observe": "observe(mode, t, y, p, out): the stage forces, as stage_forces",
    "impact": "NaN: nothing collides", "accel": "accel(mode, t, y, p) -> a_0",
    "body_forces": "body_forces(t, y, p, direction) -> (F_0, ..., F_N), the valve's friction against direction",
    "stage_forces": "stage_forces(mode, t, y, p, out): per stage (on its input body, on its output body, N)",
    "prepare": "prepare(p): the derived slots of p from its values, once per run",
}


class ContractError(ImportError):
    """A module that does not provide the generated-module contract."""


def check_module(module: ModuleType) -> ModuleType:
    """Return ``module`` if it has every contract name (a chain module's: CHAIN_*), else raise naming the
    missing ones."""
    names = (*CHAIN_CONSTANTS, *CHAIN_FUNCTIONS) if hasattr(module, "STAGES") else (*CONSTANTS, *FUNCTIONS)
    missing = [name for name in names if not hasattr(module, name)]
    if getattr(module, "HAS_LOAD_FACTORS", False) and not hasattr(module, "load_factors"):
        missing.append("load_factors")
    if missing:
        raise ContractError(f"{module.__name__} is not a tswm model module (missing {', '.join(missing)}); "
                            "regenerate it with `tswm generate SCENE`")
    return module


def load_module(name_or_path: str | Path) -> ModuleType:
    """Import a generated module: a shipped scene name (``paper``) or a path to a .py file."""
    path = Path(name_or_path)
    if path.suffix == ".py":
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such generated module")
        name = f"tswm_model_{path.stem}"
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # numba's disk cache re-imports a function's module by name
        spec.loader.exec_module(module)
        return check_module(module)
    return check_module(importlib.import_module(f"generated.{str(name_or_path).replace('-', '_')}"))
