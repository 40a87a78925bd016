"""The chain's derivation document: every stage's kinetostatics, every mode's reduced dynamics and switching
functions, the driving and holding torque, and an audit whose numbers are checked here against formulas
written by hand; scene text reaches LaTeX only escaped."""
from __future__ import annotations

import math

import pytest

from derivation.chain.document import build_chain_document
from derivation.chain.scene import load_chain, parse_chain
from derivation.document import render
from tests.chains import DEG, EXAMPLES
from tests.test_chain_backlash import _scene

# heavy: a chain's whole LaTeX derivation (SymPy) per test module; CI runs it after the default set
pytestmark = pytest.mark.heavy

MSL = EXAMPLES / "msl4000.toml"


def _sections(doc: dict) -> dict:
    return {section.title: section for section in doc["sections"]}


def _tables(section) -> list[list[list[str]]]:
    return [block[3] for block in section.blocks if block[0] == "table"]


def _msl_by_hand() -> tuple[float, float]:
    """(lowest, highest) worm torque holding the lifting table: its weight at the worm over the ideal ratios,
    times the backward efficiencies or over the forward ones, tan(g)/tan(g + r') and tan(g - r')/tan(g),
    with tan(r') = mu / cos(alpha_n) and a thread's tan(alpha_n) = tan(15 deg) cos(lambda)."""
    lam = math.atan(0.010 / (math.pi * 0.016))
    gammas = (20 * DEG, lam)
    rhos = (math.atan(0.05 / math.cos(20 * DEG)), math.atan(0.05 / math.cos(math.atan(math.tan(15 * DEG) * math.cos(lam)))))
    weight = 1962.0 * 0.02 * math.tan(20 * DEG) / 0.08 * 0.010 / (2 * math.pi)
    forward = math.prod(math.tan(g) / math.tan(g + r) for g, r in zip(gammas, rhos))
    backward = math.prod(math.tan(g - r) / math.tan(g) for g, r in zip(gammas, rhos))
    return weight * backward, weight / forward


@pytest.fixture(scope="module")
def msl_document():
    return build_chain_document(load_chain(MSL))


def test_the_document_shows_every_modes_dynamics_and_switching_functions(msl_document):
    sections = _sections(msl_document)
    assert {"Kinetostatics of a stage", "Modes and reduced equation of motion", "Resting chain",
            "Driving and holding torque", "Decision at the scene's forces", "Audit"} <= set(sections)
    (ftf,) = _tables(sections["Kinetostatics of a stage"])
    assert [row[1] for row in ftf] == ["tractive", "inverse-tractive", "inverse-tractive", "tractive"]
    modes = [b[1] for b in sections["Modes and reduced equation of motion"].blocks if b[0] == "text"
             and b[1].startswith("Mode ")]
    assert len(modes) == 8
    equations = [b[1] for b in sections["Modes and reduced equation of motion"].blocks if b[0] == "math"][1:]
    assert len(equations) == 8 and all(len(e) == 3 and e[0].startswith("a_0 = ") for e in equations)


def test_the_msl4000_band_and_audit_agree_with_the_hand_efficiencies(msl_document):
    """The driving and holding torques are the hand band; the audit's hand comparison, power balances and
    the normal forces and a_0 jumps at every switch are zero to rounding; the decision at rest is resting,
    the only consistent mode, each breakaway rejected with its reason."""
    low, high = _msl_by_hand()
    sections = _sections(msl_document)
    (band,) = _tables(sections["Driving and holding torque"])
    assert float(band[0][1]) == pytest.approx(high, rel=5e-6) and float(band[1][1]) == pytest.approx(low, rel=5e-6)
    balance, steady, switches = _tables(sections["Audit"])
    assert len(balance) == 8 and all(abs(float(x)) < 1e-12 for row in balance for x in row[1:])
    assert [float(row[2]) for row in steady] == pytest.approx([high, low], rel=5e-9)   # printed to 9 digits
    assert all(float(row[3]) < 1e-13 for row in steady)
    assert len(switches) == 16
    assert all(float(row[3]) < 1e-9 * 2000 and float(row[4]) < 1e-9 for row in switches)
    audit_text = " ".join(b[1] for b in sections["Audit"].blocks if b[0] == "text")
    assert "DIFFER" not in audit_text and audit_text.count("agree") == 2
    at_rest = next(b[1] for b in sections["Decision at the scene's forces"].blocks if b[0] == "text")
    assert at_rest.startswith("At rest: unique, stuck") and "would not leave rest in its direction" in at_rest


HOSTILE = '\\input{/etc/passwd} $x^2$ 100% & #1 _a ~ {} \\\\ \\end{document}'


def test_scene_text_reaches_latex_escaped():
    """A description full of LaTeX's specials is printed as text, never run; the name is limited to
    [a-z0-9-] by the scene reader."""
    text = MSL.read_text().replace('description = "Motor at', 'description = "' + HOSTILE.replace("\\", "\\\\")
                                   .replace('"', '\\"') + ' Motor at')
    chain = parse_chain(text, "hostile.toml")
    assert chain.description.startswith(HOSTILE)
    tex = render(build_chain_document(chain), "latex")
    assert "\\input{" not in tex and "\\end{document}" in tex and tex.count("\\end{document}") == 1
    assert "\\textbackslash{}input\\{/etc/passwd\\}" in tex and "100\\%" in tex and "\\&" in tex and "\\#1" in tex
    assert "\\$x" in tex


def test_the_document_shows_the_last_stage_open(msl_document):
    """Stage 2 of the two-stage chain open: groups from bodies 0 and 2, the gap's rate in both groups' speeds,
    the effective masses; the stem (body 2) alone has m2 = M_2 / r_out,2^2."""
    section = _sections(msl_document)["An open stage (clearance)"]
    texts = " ".join(b[1] for b in section.blocks if b[0] == "text")
    assert "Were stage 2 open" in texts and "groups that start at bodies 0, 2" in texts
    equations = [line for b in section.blocks if b[0] == "math" for line in b[1]]
    assert [e.split(" = ")[0] for e in equations] == ["a_{0}", "a_{2}", "\\dot g_{2}", "m_1", "m_2", "W_{nn}"]
    assert "v_{0}" in equations[2] and "v_{2}" in equations[2]
    assert equations[4] == "m_2 = \\frac{M_{2}}{r_{\\mathrm{out},2}^{2}}", equations[4]


def test_derive_of_a_chain_with_a_clearance_prints_it_and_its_section(tmp_path, capsys):
    """tswm derive of the two-stage chain with stage 2's clearance (1 mm, e = 0.5, start gap 0.5 mm): its summary
    names the stage, c, e and the start gap, the open mode's groups (bodies 0..1 and body 2), the extra states q2, v2
    and guards, and the document's section on it, which the LaTeX file holds with the scene's clearance."""
    from tswm_runtime.cli import main

    path, tex = tmp_path / "gap.toml", tmp_path / "gap.tex"
    path.write_text(_scene("gap-derive"))
    assert main(["derive", str(path), "--latex", str(tex)]) == 0
    out = capsys.readouterr().out
    assert ("  clearance: stage 2 (wedge), c = 0.001 m along the flanks' normal, restitution e = 0.5, start gap "
            "0.0005 m (open)") in out
    assert "  open mode OPEN (stage 2's flanks apart): groups bodies 0..1 and body 2," in out
    assert "  extra states q2, v2 (body 2); extra guards gap_a, gap_b, v_out" in out
    assert '  document section: "An open stage (clearance)"' in out
    text = tex.read_text()
    assert "\\section{An open stage (clearance)}" in text
    assert "Stage 2 has a clearance of 0.001 m along its flanks' normal (restitution 0.5, gap 0.0005 m" in text
