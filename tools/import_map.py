"""Print the rooms of the code and the imports between them, read from the source (AST, imports
inside functions included): one line per room (a folder of tswm_runtime/, or derivation/,
tswm_common/, generated/) with its module count and the rooms it imports from.

    python tools/import_map.py            # this checkout
    python tools/import_map.py --dot      # Graphviz dot of the same graph
    python tools/import_map.py --root DIR # another checkout (e.g. a git worktree of an older commit)

tests/test_structure.py uses ``module_graph`` to check that no import cycle exists.
"""
from __future__ import annotations

import argparse
import ast
from collections import defaultdict
from pathlib import Path

PACKAGES = ("tswm_runtime", "derivation", "tswm_common", "generated")


def modules(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every module of PACKAGES under ``root``."""
    found = {}
    for package in PACKAGES:
        for path in (root / package).rglob("*.py"):
            parts = path.relative_to(root).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def imports_of(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The modules of ``known`` that module ``name`` imports anywhere in its source."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                targets.add(sub if sub in known else base)
    return {t for t in targets if t in known and t != name}


def module_graph(root: Path) -> dict[str, set[str]]:
    known = modules(root)
    return {name: imports_of(name, path, known) for name, path in known.items()}


def room(module: str, packages: set[str]) -> str:
    """tswm_runtime.sweeps.chunks and tswm_runtime.sweeps -> tswm_runtime/sweeps; tswm_runtime.api
    -> tswm_runtime (the package face); derivation.scene -> derivation."""
    parts = module.split(".")
    inside = parts[0] == "tswm_runtime" and (len(parts) > 2 or (len(parts) == 2 and module in packages))
    return "/".join(parts[:2]) if inside else parts[0]


def room_graph(graph: dict[str, set[str]]) -> tuple[dict[str, int], dict[str, set[str]]]:
    packages = {name.rpartition(".")[0] for name in graph}
    sizes, arrows = defaultdict(int), defaultdict(set)
    for name, targets in graph.items():
        here = room(name, packages)
        if name not in packages:
            sizes[here] += 1
        arrows[here].update(room(t, packages) for t in targets if room(t, packages) != here)
    return dict(sizes), dict(arrows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--dot", action="store_true")
    args = parser.parse_args()
    sizes, arrows = room_graph(module_graph(args.root))
    if args.dot:
        print("digraph rooms {")
        for source, targets in sorted(arrows.items()):
            for target in sorted(targets):
                print(f'  "{source}" -> "{target}";')
        print("}")
        return
    for name in sorted(set(sizes) | set(arrows)):
        print(f"{name:28s} {sizes.get(name, 0):3d} modules -> {', '.join(sorted(arrows.get(name, ()))) or '-'}")


if __name__ == "__main__":
    main()
