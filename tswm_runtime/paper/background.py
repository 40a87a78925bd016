"""What ``tswm paper`` does in a second process, on the second core, while the first process
compiles the mode machine, the sweep kernel and most models: compile the segment kernel
(``hybrid.segments``, more than half of the integration kernels), the dopri5 step and the
models of ``plan.BACKGROUND_SCENES`` into numba's cache, then write the derivation document
(SymPy and pdflatex, about 10 s). None of them needs the mode machine, so on a cold cache the
two processes overlap; on a warm one the document is written while the first process runs the fit.

Run as ``python -m tswm_runtime.paper.background DIR [--model SCENE ...] [--derivation]``: it
prints ``models`` once the models, the segment kernel and the step are in the cache, then the
document's description as one line of JSON. ``Background`` starts it and reads those lines.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from tswm_common.files import write_atomic

MODELS_DONE = "models"


def derivation_document(out_dir: Path) -> dict:
    """Write the derivation of scene ``paper`` exactly as ``tswm derive paper`` does (the same
    functions); PDF when pdflatex is present, else the Markdown is the linked document."""
    from derivation.document import build_document, render
    from derivation.latex import TexUnavailable, build_pdf
    from derivation.model import build_model
    from derivation.scene import load_scene

    doc = build_document(build_model(load_scene("paper")))
    md = write_atomic(out_dir / "paper-derivation.md", render(doc, "markdown"))
    latex = render(doc, "latex")
    tex = write_atomic(out_dir / "paper-derivation.tex", latex)
    try:
        pdf = build_pdf(latex, out_dir / "paper-derivation.pdf")
        return {"link": pdf.name, "note": "PDF built with pdflatex; Markdown and LaTeX beside it",
                "files": [md.name, tex.name, pdf.name]}
    except TexUnavailable:
        return {"link": md.name, "note": "no pdflatex here: the Markdown version (LaTeX source beside it)",
                "files": [md.name, tex.name]}


class BackgroundError(RuntimeError):
    """The second process failed; the message holds the end of its error output."""


class Background:
    """The second process of one ``tswm paper`` run."""

    def __init__(self, out_dir: Path, models: list[str], derivation: bool):
        argv = [sys.executable, "-m", __name__, str(out_dir), *(a for m in models for a in ("--model", m))]
        self.derivation = derivation
        self._models_read = False
        self._errors = tempfile.TemporaryFile("w+")   # a file, not a pipe: a full pipe would block the process
        self._process = subprocess.Popen(argv + (["--derivation"] if derivation else []), stdin=subprocess.DEVNULL,
                                         stdout=subprocess.PIPE, stderr=self._errors, text=True)

    def _line(self) -> str:
        line = self._process.stdout.readline()
        if not line:
            self._process.wait()
            self._errors.seek(0)
            error = self._errors.read().strip().splitlines()
            raise BackgroundError("the second process (models, derivation document) stopped with exit status "
                                  f"{self._process.returncode}: " + "\n".join(error[-20:]))
        return line.strip()

    def models(self) -> None:
        """Return once the segment kernel, the dopri5 step and the models are in numba's cache."""
        if not self._models_read:
            line = self._line()
            if line != MODELS_DONE:
                raise BackgroundError(f"the second process said {line[:200]!r} where it should say {MODELS_DONE!r}")
            self._models_read = True

    def document(self) -> dict | None:
        """The derivation document's description (None without one), once it is written."""
        self.models()
        if not self.derivation:
            return None
        doc = json.loads(self._line())
        self._process.wait()
        return doc

    def stop(self) -> None:
        """End the process if it still runs (the main one failed or was interrupted)."""
        if self._process.poll() is None:
            self._process.kill()
        self._process.wait()
        self._process.stdout.close()
        self._errors.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog=f"python -m {__name__}", description=__doc__.split("\n\n")[0])
    parser.add_argument("directory", type=Path)
    parser.add_argument("--model", action="append", default=[], help="a shipped scene name to compile")
    parser.add_argument("--derivation", action="store_true", help="write the derivation document")
    args = parser.parse_args(argv)
    from tswm_runtime.model.contract import load_module

    for model in args.model:
        load_module(model)
    import tswm_runtime.hybrid.segments  # noqa: F401  (the segment kernel: compiled on import, if not cached)
    from tswm_runtime.integration import segment

    segment.attempt_function(segment.DOPRI5)   # the paper's scenes integrate with dopri5
    print(MODELS_DONE, flush=True)
    if args.derivation:
        print(json.dumps(derivation_document(args.directory)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
