"""The audit verdicts, the derivation document and `tswm derive`."""
import math
from importlib import resources
import os
import shutil

import pytest
import sympy as sp

from derivation import audit, mechanics as M, paper
from derivation.document import build_document, latex_prose, render
from derivation.model import build_model
from derivation.scene import load_scene, shipped_scenes
from tswm_runtime.cli import main

NEED_TEX = os.environ.get("CI") == "true"      # CI installs TeX and must compile the document


def test_audit_verdicts_match_independent_numbers():
    entries = {e.equation: e for e in audit.audit()}
    assert all(e.checked for e in entries.values())
    assert [k for k, e in entries.items() if e.agrees] == ["(2)", "(3)", "(8)"]
    # eq. (1) as printed makes body 2 faster than body 1; the worm data say 0.08.
    g = math.radians(4.76)
    assert 0.16 / (40 * 0.05) == pytest.approx(math.tan(g), rel=0.05)
    assert float(sp.solve(paper.EQ1_RESIDUAL.subs(M.gamma, g), M.x2)[0].subs(M.x1, 1)) > 10
    # eq. (6) as printed: with a resisting load and no drive force, body 1 accelerates forward.
    point = {M.F1: 0, M.F2: -15000, M.m1: 11.8, M.m2: 200, M.gamma: g, M.rho: math.radians(2)}
    printed = float(paper.EQ6_ACCEL.subs(M.Psi, paper.PSI_TRACTIVE).subs(point))
    derived = float(M.sliding("a", 1).accel.subs(point))
    assert printed > 0 > derived


def test_literal_model_jumps_at_its_switching_surface():
    jump = audit.literal_jump()
    point = {M.F2: -5000.0, M.m1: 11.8, M.m2: 200.0, M.gamma: math.radians(4.76)}
    assert float(jump.subs(point).subs(M.rho, math.radians(3))) != 0
    assert float(jump.subs(point).subs(M.rho, 0)) == 0


def test_latex_prose_escapes_outside_math_only():
    assert latex_prose("a_b $x_1$ `m_2` 50% \"q\"") == "a\\_b $x_1$ \\texttt{m\\_2} 50\\% ``q''"


@pytest.fixture(scope="module")
def paper_doc():
    return build_document(build_model(load_scene("paper")))


def test_markdown_has_every_step(paper_doc):
    md = render(paper_doc, "markdown")
    for title in ("Assumptions", "Geometry", "force transfer", "Reduced equation", "switching function",
                  "Power balance", "Stick", "load factors", "Audit"):
        assert title.lower() in md.lower()
    assert "\\tan{\\left(\\gamma + \\rho \\right)}" in md and md.count("$$") % 2 == 0
    assert "| (6) | differs | yes |" in md


@pytest.mark.heavy
@pytest.mark.skipif(not shutil.which("pdflatex") and not NEED_TEX, reason="no TeX engine here")
@pytest.mark.parametrize("name", shipped_scenes())
def test_latex_compiles_to_pdf(tmp_path, name):
    from derivation.latex import build_pdf
    doc = build_document(build_model(load_scene(name)))
    pdf = build_pdf(render(doc, "latex"), tmp_path / f"{name}.pdf")
    assert pdf.read_bytes()[:5] == b"%PDF-"


def test_literal_document_shows_the_slide_mode_and_seating_the_latch():
    md = render(build_document(build_model(load_scene("paper-literal"))), "markdown")
    assert "Mode `slide_fwd` (sliding along phi = 0; not declared by the scene" in md
    assert "a_1 = \\lambda a_{1,a} + (1 - \\lambda) a_{1,b} = 0" in md
    assert "slide_fwd" not in render(build_document(build_model(load_scene("paper"))), "markdown")
    md = render(build_document(build_model(load_scene("seating"))), "markdown")
    assert "Latch $t_{\\mathrm{trip}}$" in md and "guard $- S_{1} + S_{1,\\mathrm{trip}}$" in md


def test_laws_read_well(tmp_path):
    """A constant law is stated in words, not as F_1 = F_1; parameter names with underscores are
    typeset as subscripts or as the identifier, never as SymPy's friction_{rho}."""
    shipped = (resources.files("derivation") / "scenes" / "one-sided.toml").read_text()
    assert 'law = "linear"' in shipped
    drive = shipped[shipped.index("[drive]"):shipped.index("[load]")]
    constant_drive = shipped.replace(drive, '[drive]\nlaw = "constant"\nF1 = "800 N"\n\n')
    assert constant_drive != shipped
    path = tmp_path / "constant-drive.toml"
    path.write_text(constant_drive)
    md = render(build_document(build_model(load_scene(str(path)))), "markdown")
    assert "F_{1} = F_{1}" not in md and "friction_{\\rho}" not in md
    assert "drive force (constant): $F_{1}$ is the scene parameter `F1` (fixed, 800 N)." in md
    assert "\\rho = \\mathtt{friction\\_rho}" in md and "x_{2,\\mathrm{contact}}" in md
    md = render(build_document(build_model(load_scene("paper"))), "markdown")
    assert "F_{2} = F_{2}" not in md
    assert "load force (constant): $F_{2}$ is the scene parameter `F2` (free, default -15000 N)." in md
    assert "\\mathtt{friction\\_a}" in md and "friction_{a}" not in md
    md = render(build_document(build_model(load_scene("load-schedule"))), "markdown")
    assert "F_{2,0}" in md and "F_{2 0}" not in md


def test_cli_derive_writes_documents(tmp_path, capsys):
    assert main(["derive", "asymmetric", "--markdown", str(tmp_path / "a.md"),
                 "--latex", str(tmp_path / "a.tex")]) == 0
    out = capsys.readouterr().out
    assert "fwd_a (tractive)" in out and "bwd_b" in out and "eq. (6) differs" in out
    assert (tmp_path / "a.tex").read_text().startswith("% Generated by tswm derive")
    assert "rho_{b}" in (tmp_path / "a.md").read_text()


def test_cli_derive_bad_scene_names_the_key(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    shipped = (resources.files("derivation") / "scenes" / "paper.toml").read_text()
    bad.write_text(shipped.replace('Vmax = "6.5 m/s"', 'Vmax = "8 m/s"'))
    assert main(["derive", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "drive.Vmax" in err and "V0" in err
    assert main(["derive", "no-such-scene"]) == 2
    assert "shipped scenes" in capsys.readouterr().err
