"""``tswm generate``: emit a scene's numba module."""
from __future__ import annotations

import argparse

from tswm_runtime.cli.common import output_directory


def add_parser(sub) -> None:
    generate = sub.add_parser("generate", help="emit the scene's numba module")
    generate.add_argument("scene", help="a shipped scene name or a .toml path")
    generate.add_argument("-o", "--output", default="generated", metavar="DIR",
                          help="directory for the module (default: generated)")
    generate.add_argument("--force", action="store_true", help="overwrite a module that was edited by hand")
    generate.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from derivation.codegen import write_module
    from derivation.model import build_model
    from derivation.scene import load_scene

    output_directory(args.output)
    model = build_model(load_scene(args.scene))
    path = write_module(model, args.output, force=args.force)
    print(f"wrote {path}: modes {', '.join(m.name for m in model.modes)}; "
          f"free parameters {', '.join(p.name for p in model.scene.free_params()) or 'none'}")
    return 0
