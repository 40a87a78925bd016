"""The ``tswm`` command. Subcommands import what they need, so simulation never loads SymPy."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _derive(args: argparse.Namespace) -> int:
    from derivation.audit import audit
    from derivation.document import build_document, render
    from derivation.latex import build_pdf
    from derivation.model import build_model
    from derivation.scene import load_scene
    from tswm_runtime.files import write_atomic

    scene = load_scene(args.scene)
    model = build_model(scene)
    print(f"scene {scene.name} ({scene.source}): equations {scene.equations}, flanks {', '.join(scene.flanks)}")
    print(f"  modes: {', '.join(f'{m.name} ({m.regime})' for m in model.modes)}")
    print(f"  states: {', '.join(map(str, model.states))}; free parameters: "
          f"{', '.join(p.name for p in scene.free_params()) or 'none'}")
    print("  audit: " + "; ".join(f"eq. {e.equation} {'agrees' if e.agrees else 'differs'}" for e in audit()))
    if not (args.latex or args.markdown or args.pdf):
        return 0
    doc = build_document(model)
    if args.markdown:
        print(f"  wrote {write_atomic(args.markdown, render(doc, 'markdown'))}")
    latex = render(doc, "latex")
    if args.latex:
        print(f"  wrote {write_atomic(args.latex, latex)}")
    if args.pdf:
        pdf = Path(args.pdf if isinstance(args.pdf, str) else (args.latex or f"{scene.name}-derivation.tex"))
        print(f"  wrote {build_pdf(latex, pdf.with_suffix('.pdf'))}")
    return 0


def _generate(args: argparse.Namespace) -> int:
    from derivation.codegen import write_module
    from derivation.model import build_model
    from derivation.scene import load_scene

    model = build_model(load_scene(args.scene))
    path = write_module(model, args.output, force=args.force)
    print(f"wrote {path}: modes {', '.join(m.name for m in model.modes)}; "
          f"free parameters {', '.join(p.name for p in model.scene.free_params()) or 'none'}")
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tswm", description="Derive, generate and simulate wedge mechanisms.")
    sub = parser.add_subparsers(dest="command", required=True)
    derive = sub.add_parser("derive", help="derive a scene's model and write the derivation document")
    derive.add_argument("scene", help="a shipped scene name (paper, paper-literal, one-sided, asymmetric) or a .toml path")
    derive.add_argument("--latex", metavar="FILE.tex", help="write a standalone LaTeX document")
    derive.add_argument("--markdown", metavar="FILE.md", help="write the same document as Markdown with $$ math")
    derive.add_argument("--pdf", nargs="?", const=True, metavar="FILE.pdf",
                        help="build a PDF with pdflatex (default name: the --latex file's, else SCENE-derivation.pdf)")
    derive.set_defaults(run=_derive)
    generate = sub.add_parser("generate", help="emit the scene's numba module")
    generate.add_argument("scene", help="a shipped scene name or a .toml path")
    generate.add_argument("-o", "--output", default="generated", metavar="DIR",
                          help="directory for the module (default: generated)")
    generate.add_argument("--force", action="store_true", help="overwrite a module that was edited by hand")
    generate.set_defaults(run=_generate)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from derivation.latex import TexUnavailable
    from derivation.scene import SceneError
    from tswm_runtime.files import EditedModuleError

    try:
        return args.run(args)
    except (SceneError, TexUnavailable, EditedModuleError, FileNotFoundError) as error:
        print(f"tswm {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
