"""Scene text never becomes code or markup: generated modules and derivation documents."""
import ast
import re
from pathlib import Path

import numba
import pytest

from derivation.codegen import GenerationError, generate_module
from derivation.document import build_document, latex_literal, latex_prose, markdown_literal, render
from derivation.model import build_model
from derivation.scene import SceneError, parse_scene
from tswm_runtime.cli import main

PAPER = (Path(__file__).resolve().parents[1] / "derivation" / "scenes" / "paper.toml").read_text()
PAYLOAD = 'x"""\nimport os; os.system("touch /tmp/tswm-pwned")\n"""'
HOSTILE = [PAYLOAD, 'a"""b', "C:\\Users\\x", "'''\n__import__('os')\n'''", "\\N{oops}", "tab\there\x00nul",
           "$\\input{/etc/hostname}$ and `\\input{/etc/passwd}` ^^5cinput"]


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string (every character escaped that TOML needs escaped)."""
    out = []
    for c in text:
        if c in '"\\':
            out.append("\\" + c)
        elif not c.isprintable() or c == "\t":
            out.append(f"\\u{ord(c):04x}" if ord(c) <= 0xFFFF else f"\\U{ord(c):08x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def scene_text(description: str = None, **keys) -> str:
    text = PAPER
    if description is not None:
        text = re.sub(r"^description = .*$", lambda _: f"description = {toml_string(description)}", text, flags=re.M)
    for key, value in keys.items():
        text, n = re.subn(rf"^{key} = .*$", lambda _: f"{key} = {value}", text, flags=re.M)
        assert n == 1, key
    return text


@pytest.fixture(scope="module")
def hostile_modules():
    return {d: generate_module(build_model(parse_scene(scene_text(d), "hostile.toml"))) for d in HOSTILE}


@pytest.mark.parametrize("description", HOSTILE)
def test_description_reaches_the_module_only_as_a_string_constant(description, hostile_modules):
    source = hostile_modules[description]
    tree = ast.parse(source)  # compiles
    assigned = {t.id: node.value for node in tree.body if isinstance(node, ast.Assign)
                for t in node.targets if isinstance(t, ast.Name)}
    assert ast.literal_eval(assigned["DESCRIPTION"]) == description
    doc = ast.get_docstring(tree)
    assert description not in doc and "os.system" not in doc and "Users" not in doc
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))
                for alias in node.names}
    assert imported <= {"math", "njit", "types"}, imported
    calls = {node.func.id for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
    assert "__import__" not in calls and "exec" not in calls and "eval" not in calls
    assert "os" not in {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}


def test_the_payload_module_does_not_run_the_payload(hostile_modules, tmp_path, monkeypatch):
    """Executing the module's top level defines constants only (numba's compiles are switched off:
    the generated functions' bodies are not the top level)."""
    monkeypatch.setattr(numba.config, "DISABLE_JIT", True)
    marker = tmp_path / "pwned"
    source = hostile_modules[PAYLOAD].replace("/tmp/tswm-pwned", str(marker))
    path = tmp_path / "hostile.py"   # numba's cache=True needs the module's file to exist
    path.write_text(source)
    namespace = {}
    exec(compile(source, str(path), "exec"), namespace)
    assert namespace["DESCRIPTION"] == PAYLOAD.replace("/tmp/tswm-pwned", str(marker))
    assert not marker.exists()


LINEAR = (scene_text().replace('law = "kloss"', 'law = "linear"').replace('Fmax = "2178 N"', 'F0 = "2178 N"'))
LINEAR = re.sub(r"^Vmax = .*$", "", LINEAR, flags=re.M)


@pytest.mark.parametrize("text, key", [
    (re.sub(r"^V0 = .*$", 'V0 = "1e-310 m/s"', LINEAR, flags=re.M), "drive.V0"),     # F0 / V0 overflows
    (scene_text(V0='"1e-310 m/s"', Vmax='"1e-311 m/s"'), "drive.V0"),                 # (V0 - Vmax)^2 underflows
])
def test_non_finite_folded_constants_are_refused_naming_the_key(text, key, tmp_path, capsys):
    with pytest.raises(GenerationError, match=re.escape(key)):
        generate_module(build_model(parse_scene(text, "tiny.toml")))
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    assert main(["generate", str(path), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tswm generate: error: ") and key in err and "Traceback" not in err
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())
    assert issubclass(GenerationError, SceneError)


@pytest.fixture(scope="module")
def hostile_document():
    text = scene_text("Evil $\\input{/etc/hostname}$ `\\input{/etc/passwd}` \\write18{rm -rf x} ^^5cinput{y} "
                      "<script>alert(1)</script> %comment\n\\end{document}")
    return build_document(build_model(parse_scene(text, "evil\n\\input{/etc/shadow}.toml")))


def test_scene_text_in_latex_is_inert(hostile_document):
    tex = render(hostile_document, "latex")
    assert "\\input{" not in tex and "\\write18" not in tex and "^^5c" not in tex
    assert tex.count("\\end{document}") == 1
    assert "\\textbackslash{}input\\{/etc/hostname\\}" in tex
    comment = tex.splitlines()[0]
    assert comment.startswith("% Generated by tswm derive from evil \\textbackslash{}input")


def test_scene_text_in_markdown_is_inert(hostile_document):
    md = render(hostile_document, "markdown")
    assert "<script>" not in md and "$\\input" not in md
    assert "\\<script\\>" in md and "\\$\\\\input" in md
    assert md.splitlines()[0].endswith("Do not edit. -->") and md.count("-->") == 1


@pytest.mark.parametrize("text", ["$x$ \\input{a}", "`\\input{b}`", "a~b^c<d>|e", "x\ny\rz"])
def test_literal_escapes_leave_no_markup(text):
    tex = latex_literal(text)
    assert "\\input" not in tex and "$" not in tex.replace("\\$", "")
    assert "\n" not in tex and "\r" not in tex
    assert re.search(r"(?<!\\)[~^]", tex) is None
    assert "\\input" not in latex_prose(f"code `{text}`")
    assert "$" not in markdown_literal(text).replace("\\$", "")
