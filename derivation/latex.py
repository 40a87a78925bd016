"""Build a PDF from a LaTeX file with pdflatex, when a TeX engine is installed."""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from tswm_common.files import write_atomic

TEX_PACKAGES = "texlive-latex-base texlive-latex-recommended"


class TexUnavailable(RuntimeError):
    """No pdflatex on PATH."""


def build_pdf(tex_source: str, pdf_path: Path) -> Path:
    """Compile ``tex_source`` to ``pdf_path``; raise with pdflatex's first error on failure."""
    engine = shutil.which("pdflatex")
    if engine is None:
        raise TexUnavailable(f"--pdf needs pdflatex; install it (Debian: apt-get install {TEX_PACKAGES}) "
                             "or use --latex / --markdown")
    with tempfile.TemporaryDirectory() as work:
        tex = Path(work) / "derivation.tex"
        tex.write_text(tex_source)
        # No shell escape, and (openin_any/openout_any = p) no reading or writing outside the work directory.
        env = {**os.environ, "openin_any": "p", "openout_any": "p", "shell_escape": "f"}
        run = subprocess.run([engine, "-no-shell-escape", "-interaction=nonstopmode", "-halt-on-error", tex.name],
                             cwd=work, capture_output=True, text=True, env=env)
        if run.returncode != 0:
            errors = [line for line in run.stdout.splitlines() if line.startswith("!")]
            raise RuntimeError(f"pdflatex failed: {errors[0] if errors else run.stdout[-500:]}")
        return write_atomic(pdf_path, (Path(work) / "derivation.pdf").read_bytes())
