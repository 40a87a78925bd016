"""The integer tables through which the numba mode machine (``hybrid``) reads a model.

A generated module names its modes and guards (``MODES``, ``GUARDS``); the mode
machine needs to know what each one is: a sliding, stick or Filippov slide mode,
and which guard is phi, v1, a friction cone, a law event, ... ``tables(module)``
turns the names into the integer kinds of ``hybrid`` once, in Python.
"""
from __future__ import annotations

import re
from types import ModuleType

import numpy as np

from tswm_runtime import hybrid
from tswm_runtime.contract import ContractError

GUARD_KINDS = {
    "phi": hybrid.G_PHI, "v1": hybrid.G_V1, "D": hybrid.G_D, "jam": hybrid.G_JAM,
    "cone_forward": hybrid.G_CONE_F, "cone_backward": hybrid.G_CONE_B,
    "flank_normal": hybrid.G_FLANK_N, "load_step": hybrid.G_LAW, "load_contact": hybrid.G_LAW,
    "slide_exit_a": hybrid.G_SLIDE_A, "slide_exit_b": hybrid.G_SLIDE_B,
    "torque_switch": hybrid.G_TRIP,
}
GUARD_EVENT_NAMES = {
    "phi": "flank switch (phi = 0)", "v1": "v1 = 0", "D": "D = 0", "jam": "jam factor = 0",
    "cone_forward": "breakaway forward", "cone_backward": "breakaway backward",
    "flank_normal": "flank change in stick", "load_step": "load step", "load_contact": "load contact",
    "slide_exit_a": "leaves phi = 0 to flank a", "slide_exit_b": "leaves phi = 0 to flank b",
    "torque_switch": "torque switch trips",
}
SCHEDULE_GUARD = re.compile(r"(load|drive)_at([0-9]+)")


def guard_kind(name: str) -> int | None:
    """hybrid.G_* of a guard name; a schedule's breakpoints (load_at1, ...) are law events."""
    return hybrid.G_LAW if SCHEDULE_GUARD.fullmatch(name) else GUARD_KINDS.get(name)


def event_name(guard: str) -> str:
    """What an event of ``guard`` is, in words."""
    match = SCHEDULE_GUARD.fullmatch(guard)
    if match:
        return f"{match[1]} schedule breakpoint {match[2]}"
    return GUARD_EVENT_NAMES[guard]


def mode_kind(name: str) -> int:
    """hybrid.M_* of a mode name: stick, slide_* (Filippov on phi = 0) or sliding."""
    if name == "stick":
        return hybrid.M_STICK
    if name.startswith("slide_"):
        return hybrid.M_FILIPPOV
    return hybrid.M_SLIDING


def tables(module: ModuleType) -> tuple[np.ndarray, ...]:
    """(mode_kind, mode_flank, mode_direction, mode_declared, guard_directions, guard_kind,
    guard_latch)."""
    unknown = [g for g in module.GUARDS if guard_kind(g) is None]
    if unknown:
        raise ContractError(f"{module.__name__}: guards {unknown} are unknown to this runtime "
                            f"(known: {', '.join(GUARD_KINDS)}); regenerate the module")
    declared = getattr(module, "MODE_DECLARED", (True,) * len(module.MODES))
    as_int = lambda values: np.ascontiguousarray(values, dtype=np.int64)  # noqa: E731
    return (as_int([mode_kind(m) for m in module.MODES]), as_int(module.MODE_FLANK),
            as_int(module.MODE_DIRECTION), as_int([bool(d) for d in declared]),
            as_int(module.GUARD_DIRECTIONS).reshape(len(module.MODES), len(module.GUARDS)),
            as_int([guard_kind(g) for g in module.GUARDS]), as_int(module.GUARD_LATCH))
