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
    from derivation.scene import ChainSceneGiven, load_scene

    try:
        scene = load_scene(args.scene)
    except ChainSceneGiven:
        return _derive_chain(args)
    model = build_model(scene)
    print(f"scene {scene.name} ({scene.source}): equations {scene.equations}, flanks {', '.join(scene.flanks)}")
    print(f"  modes: {', '.join(f'{m.name} ({m.regime})' for m in model.modes)}")
    print(f"  states: {', '.join(map(str, model.states))}; free parameters: "
          f"{', '.join(p.name for p in scene.free_params()) or 'none'}")
    print("  audit: " + "; ".join(f"eq. {e.equation} {'agrees' if e.agrees else 'differs'}" for e in audit()))
    for path in write_documents(model, latex=args.latex, markdown=args.markdown, pdf=args.pdf):
        print(f"  wrote {path}")
    return 0


def _derive_chain(args: argparse.Namespace) -> int:
    """A chain of stages: its stages, its modes, the decision at rest, the document."""
    import math

    from derivation.chain.document import write_chain_documents
    from derivation.chain.dynamics import reachable
    from derivation.chain.scene import load_chain
    from derivation.chain.selector import decide
    from tswm_runtime.common.words import plural

    chain = load_chain(args.scene)
    values = chain.values()
    print(f"chain {chain.name} ({chain.source}): {plural(len(chain.stages), 'stage')} (tswm simulate runs it)")
    for k, stage in enumerate(chain.stages):
        locks = "self-locking" if values.rho[k] >= values.gamma[k] else "not self-locking"
        print(f"  stage {k + 1}: {stage.kind}, gamma {math.degrees(values.gamma[k]):.6g} deg, "
              f"rho' {math.degrees(values.rho[k]):.6g} deg, {locks}")
    print(f"  modes: {len(reachable(values.flanks))} sliding modes the flanks allow, and resting")
    decision = decide(values, 0.0)
    print(f"  at rest under the scene's forces: {decision.outcome}: {', '.join(decision.modes) or 'no mode'}")
    for i, c in enumerate(chain.clearances):
        print(*_clearance_lines(chain, c, i), sep="\n")
    for path in write_chain_documents(chain, latex=args.latex, markdown=args.markdown, pdf=args.pdf):
        print(f"  wrote {path}")
    return 0


def _clearance_lines(chain, c, index: int) -> list[str]:
    """The ``index``-th stage with a clearance ``c``: c, e and the start gap, its open mode's groups, the extra
    states and guards, the document's section that derives them."""
    from derivation.chain.clearance import groups
    from derivation.chain.codegen import CLEARANCE_GUARDS
    from derivation.chain.document import OPEN_STAGE

    k, n = c.stage, len(chain.stages)
    start = "on flank a" if c.gap.value <= 0 else "on flank b" if c.gap.value >= c.clearance.value else "open"
    first = groups(n, (k,)).first
    bodies = [f"bodies {a}..{b - 1}" if b - 1 > a else f"body {a}" for a, b in zip(first, (*first[1:], n + 1))]
    return [f"  clearance: stage {k} ({chain.stages[k - 1].kind}), c = {c.clearance.value:.6g} m along the flanks' "
            f"normal, restitution e = {c.restitution.value:.6g}, start gap {c.gap.value:.6g} m ({start})",
            f"  open mode OPEN{f' + {index}' if index else ''} (stage {k}'s flanks apart): groups "
            f"{' and '.join(bodies)}, each moving as one body with its first body's coordinate",
            (f"  extra states q{k}, v{k} (body {k})" if len(chain.clearances) == 1 else
             "  extra states qcur, vcur (body k of the current clearance stage k)")
            + f"; extra guards {', '.join(CLEARANCE_GUARDS)}",
            f"  document section: \"{OPEN_STAGE}{f': stage {k}' if len(chain.clearances) > 1 else ''}\" (stage {k} open: the groups' accelerations, the gap's rate, "
            "the impact's effective masses)"]
