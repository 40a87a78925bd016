"""Counts and differences in printed sentences: '1 event', '2 events', 'agree exactly'."""
from __future__ import annotations

IRREGULAR = {"degree of freedom": "degrees of freedom"}


def plural(count: int, noun: str) -> str:
    """``count`` followed by ``noun`` in its number: plural(1, 'event') -> '1 event',
    plural(0, 'event') -> '0 events', plural(2, 'degree of freedom') -> '2 degrees of freedom'."""
    if count == 1:
        return f"{count} {noun}"
    return f"{count} {IRREGULAR.get(noun, noun + 's')}"


def difference(largest: float, unit: str = "") -> str:
    """How far two sets of numbers lie apart, for a sentence: 'agree exactly' when the largest
    difference is 0, else 'differ by at most 3.2e-07 N' (two significant digits, never '0')."""
    if largest == 0:
        return "agree exactly"
    return f"differ by at most {largest:.2g}{f' {unit}' if unit else ''}"


def differences(largest: dict, units: dict) -> str:
    """Several quantities' largest differences in one clause: 'agree exactly in KD1 and differ
    by at most 2.3e-09 N in S1m' (``units``: quantity -> unit, '' for none)."""
    exact = [q for q, d in largest.items() if d == 0]
    off = [f"{d:.2g}{f' {units[q]}' if units[q] else ''} in {q}" for q, d in largest.items() if d != 0]
    parts = ([f"agree exactly in {_listed(exact)}"] if exact else []) + \
        ([f"differ by at most {_listed(off)}"] if off else [])
    return " and ".join(parts) or "have nothing to compare"


def _listed(items: list[str]) -> str:
    """'a', 'a and b', 'a, b and c'."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"
