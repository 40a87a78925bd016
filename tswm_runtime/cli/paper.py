"""``tswm paper``: the paper's Table 3 and Figure 2 against tswm, as a Markdown/HTML report."""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from tswm_runtime.cli.common import UsageError, output_directory


def add_parser(sub) -> None:
    paper = sub.add_parser("paper", help="the paper's Table 3 and Figure 2 against tswm: a Markdown/HTML report",
                           description="Run the paper's cases in four readings (consistent, printed equations, "
                                       "run-up then load, lost motion fitted to Table 3 with tswm fit) and write "
                                       "DIR/paper-report.{md,html,json}, DIR/lostmotion/ (the fit), the Figure 2 "
                                       "PNGs and the derivation document.")
    paper.add_argument("-o", "--output", default="tswm-report", metavar="DIR",
                       help="directory for the report (default: tswm-report)")
    paper.add_argument("--case", action="append", metavar="M2,F2",
                       help="only this case (m2 [kg], F2 [N]); repeatable (default: all the paper lists)")
    paper.add_argument("--no-derivation", action="store_true",
                       help="do not build the derivation document (and do not load SymPy)")
    paper.add_argument("--no-progress", action="store_true", help="no progress bar")
    paper.set_defaults(run=run)


def _cases(items: list[str] | None) -> list[tuple[float, float]] | None:
    """The --case values as (m2, F2) pairs, or None for all the paper lists."""
    if not items:
        return None
    try:
        cases = [tuple(float(v) for v in item.split(",")) for item in items]
    except ValueError:
        cases = []
    if not cases or any(len(c) != 2 for c in cases):
        raise UsageError(f"--case {items!r}: expected M2,F2 in SI, e.g. --case 200,-15000")
    for m2, F2 in cases:
        if not (math.isfinite(m2) and math.isfinite(F2) and m2 > 0):
            raise UsageError(f"--case {m2:g},{F2:g}: M2 must be a finite mass > 0 kg and F2 a finite force [N]")
    return cases


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _cold_parts() -> tuple[dict[str, float], str | None]:
    """The compile seconds of what numba's cache lacks (plan's KERNELS: the mode machine and the
    first process's models; BATCH; MODELS: the segment kernel, the dopri5 step and the second
    process's models), and the words for it (None if nothing is cold). Marks it announced
    (``coldstart.check``), so the kernels' own modules do not say it again."""
    from tswm_runtime.jit import coldstart
    from tswm_runtime.paper import plan

    groups = list((coldstart.check(("integrate", "dopri5", "batch")) or ([], None))[0])
    models = [m for m in plan.SCENES.values() if coldstart.check((), m) is not None]
    integrate = [g for g in groups if g == "integrate"]
    segment = coldstart.estimate(["segment"] if integrate else [], None)   # in "integrate", compiled in the second
    seconds = {plan.KERNELS: coldstart.estimate(integrate, None) - segment
               + sum(coldstart.estimate((), m) for m in models if m not in plan.BACKGROUND_SCENES),
               plan.BATCH: coldstart.estimate([g for g in groups if g == "batch"], None),
               plan.MODELS: segment + coldstart.estimate([g for g in groups if g == "dopri5"], None)
               + sum(coldstart.estimate((), m) for m in models if m in plan.BACKGROUND_SCENES)}
    seconds = {stage: s for stage, s in seconds.items() if s > 0}
    if not groups and not models:
        return seconds, None
    what = coldstart.describe(groups, None) if groups else ""
    if models:
        what += (" and " if what else "") + "the models " + ", ".join(f"`{m}`" for m in models)
    here = seconds.get(plan.KERNELS, 0.0) + seconds.get(plan.BATCH, 0.0)
    return seconds, (f"compiling {what} into numba's cache, once (later runs load them from there): about "
                     f"{coldstart.about(here)} s here and {coldstart.about(seconds.get(plan.MODELS, 0.0))} s "
                     "in a second process meanwhile (measured on 2 cores)")


def _compile_first_part() -> None:
    """This process's share of a cold compile (compiled on import, else loaded): the mode machine,
    the output rows and the machine's entry (``hybrid.entry``), then the models not in
    plan.BACKGROUND_SCENES. Not the segment kernel (``hybrid.segments``, which entry imports at its
    first run only): the second process compiles it meanwhile."""
    import tswm_runtime.hybrid.machine  # noqa: F401
    import tswm_runtime.hybrid.rows  # noqa: F401
    import tswm_runtime.hybrid.entry  # noqa: F401
    from tswm_runtime.model.contract import load_module
    from tswm_runtime.paper import plan

    for scene in plan.first_process_scenes():
        load_module(scene)


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    output_directory(args.output)
    cases = _cases(args.case)
    _say(f"tswm paper: the paper's cases in four readings, report into {args.output}/; checking numba's cache")
    from tswm_runtime.common.progress import Stages
    from tswm_runtime.paper import plan
    from tswm_runtime.paper.background import Background, BackgroundError

    compile_s, cold = _cold_parts()
    if cold:
        _say(f"tswm paper: {cold}")
    background = Background(Path(args.output), list(plan.BACKGROUND_SCENES), derivation=not args.no_derivation)
    stages = Stages(plan.estimates(compile_s, derivation=not args.no_derivation), desc="tswm paper",
                    enabled=not args.no_progress)
    try:
        stages.begin(plan.KERNELS)
        _compile_first_part()
        stages.begin(plan.BATCH)
        import tswm_runtime.hybrid.batch  # noqa: F401  (compiled on import, if not cached)
        stages.begin(plan.MODELS, waiting=True)
        background.models()   # the segment kernel is in the cache now: importing entry loads it
        from tswm_runtime.paper.report import build_report, wall_time_text
        from tswm_runtime.simulation.simulate import SimulationInputError

        try:
            report = build_report(args.output, cases, document=background.document, stages=stages, started=start)
        except SimulationInputError as error:
            raise UsageError(f"--case: {error}") from None
    except BackgroundError as error:
        _say(f"tswm paper: error: {error}")
        return 1
    finally:
        stages.close()
        background.stop()
    for path in report["paths"].values():
        print(f"  wrote {path}")
    print(f"tswm paper: report in {Path(args.output) / 'paper-report.html'}; "
          f"{wall_time_text(report['data']['timing'])}")
    return 0
