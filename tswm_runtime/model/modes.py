"""The integer tables through which the numba mode machine (``hybrid``) reads a model.

A generated module names its modes and guards (``MODES``, ``GUARDS``); the mode
machine needs to know what each one is: a sliding, stick or Filippov slide mode,
and which guard is phi, v1, a friction cone, a law event, ... ``tables(module)``
turns the names into the integer kinds of ``hybrid`` once, in Python.
"""
from __future__ import annotations

import functools
import re
from enum import IntEnum
from types import ModuleType

import numpy as np

from tswm_runtime.hybrid import machine as hybrid
from tswm_runtime.model.contract import ContractError
from tswm_runtime.jit.structures import ModeTables

class GuardKind(IntEnum):
    """The mode machine's guard kinds (hybrid.G_PHI, ...), for Python."""

    PHI = hybrid.G_PHI
    V1 = hybrid.G_V1
    D = hybrid.G_D
    JAM = hybrid.G_JAM
    CONE_FORWARD = hybrid.G_CONE_F
    CONE_BACKWARD = hybrid.G_CONE_B
    FLANK_NORMAL = hybrid.G_FLANK_N
    LAW = hybrid.G_LAW
    SLIDE_EXIT_A = hybrid.G_SLIDE_A
    SLIDE_EXIT_B = hybrid.G_SLIDE_B
    TRIP = hybrid.G_TRIP
    GAP_A = hybrid.G_GAP_A
    GAP_B = hybrid.G_GAP_B
    MESH_NORMAL = hybrid.G_MESH_N
    SLIP = hybrid.G_SLIP
    STEM_GAP = hybrid.G_STEM_GAP
    STEM_CONTACT = hybrid.G_STEM_N


GUARD_KINDS = {
    "phi": GuardKind.PHI, "v1": GuardKind.V1, "D": GuardKind.D, "jam": GuardKind.JAM,
    "cone_forward": GuardKind.CONE_FORWARD, "cone_backward": GuardKind.CONE_BACKWARD,
    "flank_normal": GuardKind.FLANK_NORMAL, "load_step": GuardKind.LAW, "load_contact": GuardKind.LAW,
    "slide_exit_a": GuardKind.SLIDE_EXIT_A, "slide_exit_b": GuardKind.SLIDE_EXIT_B,
    "load_schedule": GuardKind.LAW, "drive_schedule": GuardKind.LAW,
    "torque_switch": GuardKind.TRIP, "gap_a": GuardKind.GAP_A, "gap_b": GuardKind.GAP_B,
    "mesh_normal": GuardKind.MESH_NORMAL, "slip": GuardKind.SLIP,
    "stem_gap": GuardKind.STEM_GAP, "stem_contact": GuardKind.STEM_CONTACT,
}
GUARD_EVENT_NAMES = {
    "phi": "flank switch (phi = 0)", "v1": "v1 = 0", "D": "D = 0", "jam": "jam factor = 0",
    "cone_forward": "breakaway forward", "cone_backward": "breakaway backward",
    "flank_normal": "flank change in stick", "load_step": "load step", "load_contact": "load contact",
    "load_schedule": "load schedule breakpoint", "drive_schedule": "drive schedule breakpoint",
    "slide_exit_a": "leaves phi = 0 to flank a", "slide_exit_b": "leaves phi = 0 to flank b",
    "torque_switch": "torque switch trips",
    "gap_a": "gap closes on flank a", "gap_b": "gap closes on flank b",
    "mesh_normal": "flanks part (mesh force 0)", "slip": "slip stops",
    "stem_gap": "body 2 strikes the stem", "stem_contact": "the stem leaves body 2",
}
SCHEDULE_GUARD = re.compile(r"(load|drive)_schedule")
BREAKPOINT_EVENT = re.compile(r"(load|drive)_at([0-9]+)")


def guard_kind(name: str) -> int | None:
    """hybrid.G_* of a guard name."""
    return GUARD_KINDS.get(name)


def event_guard(guard: str, breakpoint: int) -> str:
    """The name an event goes by: a schedule's event is named after the breakpoint it passed
    (``load_at2``, the name of that breakpoint's parameter), every other after its guard."""
    match = SCHEDULE_GUARD.fullmatch(guard)
    return f"{match[1]}_at{breakpoint}" if match and breakpoint > 0 else guard


def event_name(guard: str) -> str:
    """What an event named ``guard`` (``event_guard``) is, in words."""
    match = BREAKPOINT_EVENT.fullmatch(guard)
    if match:
        return f"{match[1]} schedule breakpoint {match[2]}"
    return GUARD_EVENT_NAMES[guard]


def mode_kind(name: str) -> int:
    """hybrid.M_* of a mode name: stick, free (flight across the clearance), slide_* (Filippov
    on phi = 0) or sliding."""
    if name == "stick":
        return hybrid.M_STICK
    if name == "free":
        return hybrid.M_FREE
    if name.startswith("mesh_"):
        return hybrid.M_MESH
    if name.startswith("slide_"):
        return hybrid.M_FILIPPOV
    return hybrid.M_SLIDING


@functools.lru_cache(maxsize=64)
def tables(module: ModuleType) -> ModeTables:
    """The module's modes and guards as the integer ModeTables of the mode machine."""
    unknown = [g for g in module.GUARDS if guard_kind(g) is None]
    if unknown:
        raise ContractError(f"{module.__name__}: guards {unknown} are unknown to this runtime "
                            f"(known: {', '.join(GUARD_KINDS)}); regenerate the module")
    declared = getattr(module, "MODE_DECLARED", (True,) * len(module.MODES))
    as_int = lambda values: np.ascontiguousarray(values, dtype=np.int64)  # noqa: E731
    return ModeTables(as_int([mode_kind(m) for m in module.MODES]), as_int(module.MODE_FLANK),
            as_int(module.MODE_DIRECTION), as_int([bool(d) for d in declared]),
            as_int(module.GUARD_DIRECTIONS).reshape(len(module.MODES), len(module.GUARDS)),
            as_int([guard_kind(g) for g in module.GUARDS]), as_int(module.GUARD_LATCH), as_int(module.GUARD_PIECES))
