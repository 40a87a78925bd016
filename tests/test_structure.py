"""The layout's promises, read from the source (AST), lazy imports included: no import cycle in
tswm_runtime/, derivation/ or tswm_common/; derivation/ never imports tswm_runtime/; tswm_common/
imports neither; no folder of more than ten modules; docs/architecture.md names only modules that
exist; the core kernels take their arguments as named bundles."""
from __future__ import annotations

import ast
import importlib.util
import re
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("import_map", ROOT / "tools" / "import_map.py")
import_map = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(import_map)

MODULES = {name: path for name, path in import_map.modules(ROOT).items() if not name.startswith("generated")}


@lru_cache(maxsize=1)
def graph() -> dict[str, set[str]]:
    """Each module's imports, lazy ones included (read when a test first asks: not while every worker collects)."""
    return {name: import_map.imports_of(name, path, MODULES) for name, path in MODULES.items()}


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
        assert "tswm_runtime.cli" in import_map.imports_of("tests._probe_module", tree, MODULES)
    finally:
        tree.unlink()


def test_no_import_cycle():
    assert _cycles(graph()) == []


def test_layering_between_packages():
    for name, targets in graph().items():
        if name.startswith("derivation"):
            assert not any(t.startswith("tswm_runtime") for t in targets), (name, targets)
        if name.startswith("tswm_common"):
            assert all(t.startswith("tswm_common") for t in targets), (name, targets)


def test_the_cli_package_only_dispatches():
    """cli/__init__ imports its subcommands and cli.common; the subcommands import no subcommand."""
    cli = {n for n in MODULES if n.startswith("tswm_runtime.cli.")} - {"tswm_runtime.cli.__main__"}
    for name in cli:
        assert not (graph()[name] & (cli - {"tswm_runtime.cli.common"})), name
        assert "tswm_runtime.cli" not in graph()[name], name


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


# The rooms of docs/architecture.md, lowest first: a room imports only from rooms before it.
ROOM_ORDER = ("tswm_common", "tswm_runtime/common", "tswm_runtime/jit", "tswm_runtime/integration",
              "tswm_runtime/hybrid", "tswm_runtime/chains", "tswm_runtime/model", "tswm_runtime/results", "tswm_runtime/simulation",
              "tswm_runtime/sweeps", "tswm_runtime/fitting", "tswm_runtime/reference", "tswm_runtime/bench",
              "tswm_runtime/paper", "tswm_runtime/startup", "tswm_runtime/cli")
# Outside the order: derivation/ and generated/ (scene files and documents, imported lazily by the
# rooms that turn a .toml into a module or write the derivation) and the package face.
OUTSIDE = {"derivation", "generated", "tswm_runtime"}


def test_rooms_import_only_from_lower_rooms():
    packages = {name.rpartition(".")[0] for name in graph()}
    upward = []
    for name, targets in graph().items():
        here = import_map.room(name, packages)
        if here not in ROOM_ORDER:
            continue
        for target in targets:
            there = import_map.room(target, packages)
            if there in OUTSIDE or there == here:
                continue
            if ROOM_ORDER.index(there) > ROOM_ORDER.index(here):
                upward.append(f"{name} -> {target}")
    assert upward == []


def test_every_runtime_room_is_in_the_order():
    packages = {name.rpartition(".")[0] for name in graph()}
    rooms = {import_map.room(name, packages) for name in graph() if name.startswith("tswm_runtime.")}
    assert rooms - set(ROOM_ORDER) - OUTSIDE == set()


# The core kernels take their arguments as named bundles (jit/structures.py: functions, settings,
# state, record, work arrays), not as long positional lists.
CORE_KERNELS = {"tswm_runtime/integration/segment.py": "run", "tswm_runtime/integration/painleve.py": "approach",
                "tswm_runtime/hybrid/machine.py": "integrate_hybrid", "tswm_runtime/hybrid/entry.py": "integrate_at",
                "tswm_runtime/hybrid/batch.py": "run_batch", "tswm_runtime/hybrid/segments.py": "run_segment"}
MAX_KERNEL_PARAMETERS = 8


def test_core_kernels_take_named_bundles():
    counts = {}
    for path, name in CORE_KERNELS.items():
        tree = ast.parse((ROOT / path).read_text())
        (function,) = [node for node in tree.body if isinstance(node, ast.FunctionDef) and node.name == name]
        counts[f"{path} {name}"] = len(function.args.args)
    assert max(counts.values()) <= MAX_KERNEL_PARAMETERS, counts
