"""`tswm paper`: the report's numbers are the runtime's numbers, and the HTML renders."""
import json
import math
import os
import re
import shutil
import struct
import subprocess
import sys

import pytest

from tswm_runtime import paper_report as pr
from tswm_runtime.paper_data import TABLE3_PRINTED, printed
from tswm_runtime.simulate import simulate

NEED_CHROMIUM = os.environ.get("CI") == "true"   # CI installs chromium and must render the report
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CASES = [(200.0, -15000.0), (300.0, -5000.0)]     # Figure 2's case and one the paper does not tabulate
DIRECT = {"consistent": ("paper", lambda m2, F2: {"m2": m2, "F2": F2}),
          "literal": ("paper-literal", lambda m2, F2: {"m2": m2, "F2": F2}),
          "runup": ("paper-runup", lambda m2, F2: {"m2": m2, "F2_after": F2})}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    return pr.build_report(out, CASES, derivation=False, progress=False), out


def _direct(key, m2, F2):
    scene, params = DIRECT[key]
    return simulate(scene, params(m2, F2))


def test_json_numbers_are_direct_simulate_results(report):
    result, out = report
    data = json.loads((out / "paper-report.json").read_text())
    assert [(c["m2"], c["F2"]) for c in data["cases"]] == CASES
    for case in data["cases"]:
        for key in DIRECT:
            r = _direct(key, case["m2"], case["F2"])
            cell = case[key]
            assert cell["values"] == {"S1m": r.S1_max, "KD1": r.KD1, "S2m": r.S2_max, "KD2": r.KD2}, key
            assert cell["status"] == r.status == "finished"
            assert [ph["regime"] for ph in cell["phases"]] == [ph.regime for ph in r.phases]
            assert [e["t"] for e in cell["events"]] == [e.t for e in r.events]


def test_markdown_table3_matches_simulate_and_the_printed_numbers(report):
    _, out = report
    table = pr.read_markdown_table((out / "paper-report.md").read_text(), "Test")
    header, rows = table[0], table[1:]
    assert len(rows) == len(CASES)
    for row, (m2, F2) in zip(rows, CASES):
        cells = dict(zip(header, row))
        assert float(cells["m2 [kg]"]) == m2 and float(cells["F2 [N]"]) == F2
        paper = printed(m2, F2)
        for q, attr, unit in pr.QUANTITIES:
            column = f"{q}{f' [{unit}]' if unit else ''} paper"
            if paper is None:
                assert cells[column] == "not printed"
            else:
                assert float(cells[column]) == getattr(paper, q)
            for label, key in (("(a)", "consistent"), ("(b)", "literal"), ("(c)", "runup")):
                value = getattr(_direct(key, m2, F2), attr)
                shown = cells[f"{q} {label}"].replace("✓", "").strip()
                assert float(shown) == pytest.approx(value, rel=1e-3, abs=1e-3), (q, label)
                assert shown == pr.fmt(value)


def test_regime_words_follow_the_runs(report):
    result, _ = report
    fig = result["data"]["cases"][0]
    assert fig["consistent"]["drive"] == "does not start (self-locked)"
    assert fig["literal"]["drive"] == "runs"
    assert [ph["regime"] for ph in fig["literal"]["phases"]] == ["tractive", "inverse-tractive"]
    assert fig["runup"]["drive"] == "runs" and fig["runup"]["regimes"].startswith("tractive 0–1 s")
    stalled = simulate("paper", {"F2": -15000.0}, v1=2.0)
    assert pr.drive_word(stalled).startswith("stalls (self-locks at t = ")
    short = simulate("paper-literal", {"m2": 200.0, "F2": -15000.0}, max_steps=3)
    assert pr.drive_word(short) == f"stopped early: {short.status}" and short.status != "finished"


def test_statics_and_energy_checks(report):
    result, _ = report
    checks = result["data"]["checks"]
    for s in checks["statics"]:
        gamma, rho0 = math.radians(4.76), math.radians(1 / 0.088)
        assert s["breakaway_F1"] == pytest.approx(math.tan(gamma + rho0) * abs(s["F2"]), rel=1e-9)
        assert s["F1_0"] == pytest.approx(727.6, abs=0.05) and s["F1_0"] < s["breakaway_F1"]
        assert s["cone_margin_module"] == pytest.approx(s["cone_margin_hand"], rel=1e-9) and s["sticks"]
    literal, runup = checks["energy"]["literal"], checks["energy"]["runup"]
    assert literal["E_diss"] < 0 and literal["negative_fraction"] > 0.9
    assert runup["E_diss"] > 0 and runup["negative_fraction"] == 0
    # the energy balance's arithmetic, redone on the direct run
    r = _direct("literal", 200.0, -15000.0)
    ke = 11.8 * r.v1**2 / 2 + 200.0 * r.v2**2 / 2
    w = sum((r.t[i + 1] - r.t[i]) * ((r.F1 * r.v1 + r.F2 * r.v2)[i] + (r.F1 * r.v1 + r.F2 * r.v2)[i + 1]) / 2
            for i in range(r.t.size - 1))
    assert literal["E_diss"] == pytest.approx(w - (ke[-1] - ke[0]), rel=1e-9)


def test_figures_are_print_resolution(report):
    result, out = report
    for key in DIRECT:
        png = (out / f"figure2-{key}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        width, height = struct.unpack(">II", png[16:24])
        assert width >= 1600 and height >= 1600        # 8 in at >= 200 dpi
    assert len(TABLE3_PRINTED) == 6


def test_cli_paper_does_not_load_sympy_without_the_derivation(tmp_path):
    code = ("import sys; from tswm_runtime.cli import main; "
            f"rc = main(['paper', '-o', {str(tmp_path)!r}, '--case', '200,-15000', '--no-derivation', "
            "'--no-progress']); assert rc == 0; assert 'sympy' not in sys.modules, 'sympy loaded'")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert re.search(r"wall time \d+\.\d+ s", run.stdout)
    assert (tmp_path / "paper-report.html").exists() and not (tmp_path / "paper-derivation.md").exists()


@pytest.mark.skipif(CHROMIUM is None and not NEED_CHROMIUM,
                    reason="no chromium here (apt-get install chromium); required when CI=true")
def test_html_renders_in_headless_chromium(report, tmp_path):
    assert CHROMIUM, "CI=true but chromium is not installed"
    _, out = report
    html = (out / "paper-report.html").read_text()
    assert "http://" not in html and "https://" not in html and "<link" not in html
    assert all(src.startswith("data:image/png;base64,") for src in re.findall(r'<img[^>]*src="([^"]*)"', html))
    url = (out / "paper-report.html").as_uri()
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000"]
    dom = subprocess.run([CHROMIUM, *flags, "--dump-dom", url], capture_output=True, text=True, timeout=60).stdout
    title = re.search(r"<title>([^<]*)</title>", dom).group(1)
    assert title == f"ok 3/3 images, {len(CASES)} rows", title
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, *flags, f"--screenshot={shot}", "--window-size=1400,4000", url],
                   capture_output=True, timeout=60)
    png = shot.read_bytes()
    assert struct.unpack(">II", png[16:24]) == (1400, 4000)
    from matplotlib.image import imread

    pixels = imread(shot)
    assert pixels[:, :, :3].std() > 0.05                # not blank
    assert (pixels[:2000, :, :3].mean(axis=2) < 0.5).mean() > 0.01   # text and tables drawn at the top
