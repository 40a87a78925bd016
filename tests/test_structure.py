"""The layout's promises, read from the source (AST), lazy imports included: no import cycle in
tswm_runtime/, derivation/ or tswm_common/; derivation/ never imports tswm_runtime/; tswm_common/
imports neither; no folder of more than ten modules; docs/architecture.md names only modules that
exist."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("tswm_runtime", "derivation", "tswm_common")


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Every tswm module that ``name`` imports anywhere in its source (function bodies included)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                targets.add(sub if sub in MODULES else base)
    return {t for t in targets if t in MODULES and t != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_lazy_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_a_function_level_import_counts():
    source = "def f():\n    from tswm_runtime.cli import main\n"
    tree = Path(ROOT / "tests" / "_probe_module.py")
    try:
        tree.write_text(source)
        assert "tswm_runtime.cli" in _imports("tests._probe_module", tree)
    finally:
        tree.unlink()


def test_no_import_cycle():
    assert _cycles(GRAPH) == []


def test_layering_between_packages():
    for name, targets in GRAPH.items():
        if name.startswith("derivation"):
            assert not any(t.startswith("tswm_runtime") for t in targets), (name, targets)
        if name.startswith("tswm_common"):
            assert all(t.startswith("tswm_common") for t in targets), (name, targets)


def test_the_cli_package_only_dispatches():
    """cli/__init__ imports its subcommands and cli.common; the subcommands import no subcommand."""
    cli = {n for n in MODULES if n.startswith("tswm_runtime.cli.")} - {"tswm_runtime.cli.__main__"}
    for name in cli:
        assert not (GRAPH[name] & (cli - {"tswm_runtime.cli.common"})), name
        assert "tswm_runtime.cli" not in GRAPH[name], name


@pytest.mark.parametrize("folder", sorted({p.parent for p in MODULES.values()}), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_folder_over_ten_modules(folder):
    modules = [p for p in folder.glob("*.py") if p.name != "__init__.py"]
    assert len(modules) <= 10, [p.name for p in modules]


def test_architecture_page_names_only_modules_that_exist():
    text = (ROOT / "docs" / "architecture.md").read_text()
    named = set(re.findall(r"`((?:tswm_runtime|derivation|tswm_common|generated|tools|tests)/[\w/]+\.py)`", text))
    assert named, "the page names no module"
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert missing == []
