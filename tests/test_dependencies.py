"""Every library the product imports is installed by `pip install -e .` (pyproject's dependencies), or
by the extra whose commands import it, and only there: the README's main job on a fresh install once
failed on a missing pyarrow that only the test extra brought."""
from __future__ import annotations

import ast
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("tswm_runtime", "derivation", "tswm_common", "generated")
# Import names that differ from their distribution's name.
DISTRIBUTION = {"sksundae": "scikit-sundae"}
# Installed with the dependency that needs them: markupsafe with jinja2, mpmath with sympy, optimistix with diffrax.
WITH = {"markupsafe": "jinja2", "mpmath": "sympy", "optimistix": "diffrax"}
# Libraries of an extra, with the only modules that may import them (lazily or in modules of that extra).
EXTRA_ONLY = {
    "distributed": ("sweep", {"tswm_runtime/sweeps/cluster.py", "tswm_runtime/cli/sweep.py"}),
    "sksundae": ("bench", {"tswm_runtime/bench/peers.py"}),
    "jax": ("bench-jax", {"tswm_runtime/bench/diffrax_peer.py"}),
    "diffrax": ("bench-jax", {"tswm_runtime/bench/diffrax_peer.py"}),
    "optimistix": ("bench-jax", {"tswm_runtime/bench/diffrax_peer.py"}),
}


def _names(requirements: list[str]) -> set[str]:
    return {re.match(r"[A-Za-z0-9_.-]+", r).group(0).lower() for r in requirements}


def _third_party_imports() -> dict[str, set[str]]:
    """Top-level import name -> the product's files importing it (lazy imports included)."""
    found: dict[str, set[str]] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    top = name.partition(".")[0]
                    if top not in sys.stdlib_module_names and top not in PACKAGES:
                        found.setdefault(top, set()).add(path.relative_to(ROOT).as_posix())
    return found


def test_every_import_comes_with_the_install_that_runs_it():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    core = _names(project["dependencies"])
    extras = {name: _names(reqs) for name, reqs in project["optional-dependencies"].items()}
    found = _third_party_imports()
    assert {"numba", "sympy", "pyarrow"} <= set(found)   # the walk sees the product's imports
    for name, files in found.items():
        distribution = DISTRIBUTION.get(name, name).lower()
        if distribution in core or WITH.get(name) in core:
            continue
        assert name in EXTRA_ONLY, f"{name} (imported by {sorted(files)}) is in no dependency of pyproject.toml"
        extra, allowed = EXTRA_ONLY[name]
        assert {distribution, WITH.get(name)} & extras[extra], f"{name}: not in the extra [{extra}]"
        assert files <= allowed, f"{name} of the extra [{extra}] imported outside {sorted(allowed)}: {sorted(files)}"
