"""``tswm derive``: derive a scene's model, print its modes and audit, write the document."""
from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    derive = sub.add_parser("derive", help="derive a scene's model and write the derivation document")
    derive.add_argument("scene", help="a shipped scene name (derivation/scenes/*.toml) or a .toml path")
    derive.add_argument("--latex", metavar="FILE.tex", help="write a standalone LaTeX document")
    derive.add_argument("--markdown", metavar="FILE.md", help="write the same document as Markdown with $$ math")
    derive.add_argument("--pdf", nargs="?", const=True, metavar="FILE.pdf",
                        help="build a PDF with pdflatex (default name: the --latex file's, else SCENE-derivation.pdf)")
    derive.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from derivation.audit import audit
    from derivation.document import write_documents
    from derivation.model import build_model
    from derivation.scene import load_scene

    scene = load_scene(args.scene)
    model = build_model(scene)
    print(f"scene {scene.name} ({scene.source}): equations {scene.equations}, flanks {', '.join(scene.flanks)}")
    print(f"  modes: {', '.join(f'{m.name} ({m.regime})' for m in model.modes)}")
    print(f"  states: {', '.join(map(str, model.states))}; free parameters: "
          f"{', '.join(p.name for p in scene.free_params()) or 'none'}")
    print("  audit: " + "; ".join(f"eq. {e.equation} {'agrees' if e.agrees else 'differs'}" for e in audit()))
    for path in write_documents(model, latex=args.latex, markdown=args.markdown, pdf=args.pdf):
        print(f"  wrote {path}")
    return 0
