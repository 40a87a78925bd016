"""A test grid whose default run keeps a part of it: the rest runs with ``pytest -m slow``.

Each kept part is chosen so that it still fails on the defects its grid was written for (the
test module says which cases those were). CI (``.ci/run``) runs the default set and the heavy one;
the slow set is run by hand.
"""
from __future__ import annotations

import pytest


def slow_unless_kept(grid, kept) -> list:
    """The tuples of ``grid`` as ``pytest.param``s, each one not in ``kept`` marked slow."""
    kept = set(kept)
    missing = kept.difference(grid)
    assert not missing, f"kept cases not in the grid: {sorted(missing)}"
    return [pytest.param(*case, marks=() if case in kept else pytest.mark.slow) for case in grid]
