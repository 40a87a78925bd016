"""The repository stands alone: no pointers outside it, and the documents it points to exist."""
import re
import subprocess
from pathlib import Path

from derivation.scene import shipped_scenes
from tswm_runtime.paper.data import TABLE3_PRINTED

ROOT = Path(__file__).resolve().parents[1]
CHECKED = ("README.md", "docs", "derivation", "tswm_runtime", "tests", "tools", "pyproject.toml")
OUTSIDE = (re.compile(r"\.\./" + "shared"), re.compile(r"(?<![\w.])/" + r"work/"))


def _tracked_text_files():
    listed = subprocess.run(["git", "ls-files", *CHECKED], cwd=ROOT, capture_output=True, text=True)
    paths = [ROOT / p for p in listed.stdout.split()] if listed.returncode == 0 else [
        p for name in CHECKED for p in ([ROOT / name] if (ROOT / name).is_file() else (ROOT / name).rglob("*"))]
    return [p for p in paths if p.is_file() and p.suffix in {".md", ".py", ".toml", ".j2", ".txt", ""}]


def test_no_pointer_leaves_the_repository():
    found = []
    for path in _tracked_text_files():
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if any(p.search(line) for p in OUTSIDE):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)


def test_every_docs_file_named_in_the_repository_exists():
    named = set()
    for path in _tracked_text_files():
        named |= set(re.findall(r"docs/[\w-]+\.md", path.read_text(errors="replace")))
    assert {"docs/paper.md", "docs/architecture.md"} <= named
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, missing


def test_paper_md_table3_is_paper_data():
    """docs/paper.md's Table 3 and tswm_runtime/paper/data.py hold the same printed numbers."""
    text = (ROOT / "docs" / "paper.md").read_text()
    rows = [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in text[text.index("## Table 3"):].splitlines() if re.match(r"\| \d+ \|", line)]
    assert [[int(r[0]), *(float(c) for c in r[1:])] for r in rows] == [
        [c.test, c.m2, c.F2, c.S1m, c.KD1, c.S2m, c.KD2] for c in TABLE3_PRINTED]


def test_readme_lists_every_shipped_scene():
    readme = (ROOT / "README.md").read_text()
    listed = re.search(r"`SCENE` is a shipped name \(([^)]*)\)", readme.replace("\n", " "))
    assert listed, "README: the list of shipped scene names is gone"
    assert sorted(re.findall(r"`([\w-]+)`", listed.group(1))) == sorted(shipped_scenes())

