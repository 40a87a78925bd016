"""Numbers PRINTED IN THE PAPER (Table 3 and section 4), typed in by hand from the paper
(its citation, data and Table 3 are written out in ``docs/paper.md``). Nothing here is
computed; tswm's own numbers come from ``simulate`` (see ``paper_report``). Keep the
values exactly as printed (decimal commas read as points).
"""
from __future__ import annotations

from dataclasses import dataclass

SOURCE = "Two-Sided Wedge Mechanism paper, section 4, Table 3 (printed values)"


@dataclass(frozen=True)
class PrintedCase:
    """One row of the paper's Table 3, as printed: test number, inputs, results."""

    test: int
    m2: float      # kg
    F2: float      # N
    S1m: float     # N
    KD1: float
    S2m: float     # N
    KD2: float


# Table 3 as printed in the paper: test, m2 [kg], F2 [N], S1m [N], KD1, S2m [N], KD2.
TABLE3_PRINTED = (
    PrintedCase(1, 100.0, -5000.0, 800.0, 0.81, -6300.0, 0.76),
    PrintedCase(2, 100.0, -10000.0, 1400.0, 1.40, -11300.0, 1.37),
    PrintedCase(3, 100.0, -15000.0, 1800.0, 1.84, -16500.0, 2.00),
    PrintedCase(4, 200.0, -5000.0, 900.0, 0.91, -7600.0, 0.92),
    PrintedCase(5, 200.0, -10000.0, 1500.0, 1.50, -12100.0, 1.36),
    PrintedCase(6, 200.0, -15000.0, 2000.0, 2.01, -16900.0, 2.00),
)

# Section 4 lists m2 = [100; 200, 300] kg and F2 = [-5000; -10000; -15000] N as inputs,
# but Table 3 prints no row for m2 = 300 kg.
M2_LISTED = (100.0, 200.0, 300.0)
F2_LISTED = (-5000.0, -10000.0, -15000.0)

# The case the paper plots in Figure 2.
FIGURE2 = {"m2": 200.0, "F2": -15000.0}


def printed(m2: float, F2: float) -> PrintedCase | None:
    """The printed Table 3 row for (m2, F2), or None when the paper prints none."""
    return next((c for c in TABLE3_PRINTED if c.m2 == m2 and c.F2 == F2), None)
