"""``tswm paper``: the paper's Table 3 and Figure 2 against tswm, as a Markdown/HTML report."""
from __future__ import annotations

import argparse
import math
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


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    output_directory(args.output)
    from tswm_runtime.paper.report import build_report, wall_time_text

    cases = None
    if args.case:
        try:
            cases = [tuple(float(v) for v in item.split(",")) for item in args.case]
        except ValueError:
            cases = []
        if not cases or any(len(c) != 2 for c in cases):
            raise UsageError(f"--case {args.case!r}: expected M2,F2 in SI, e.g. --case 200,-15000")
        for m2, F2 in cases:
            if not (math.isfinite(m2) and math.isfinite(F2) and m2 > 0):
                raise UsageError(f"--case {m2:g},{F2:g}: M2 must be a finite mass > 0 kg and F2 a finite force [N]")
    from tswm_runtime.simulation.simulate import SimulationInputError

    try:
        report = build_report(args.output, cases, derivation=not args.no_derivation, progress=not args.no_progress,
                              started=start)
    except SimulationInputError as error:
        raise UsageError(f"--case: {error}") from None
    for path in report["paths"].values():
        print(f"  wrote {path}")
    print(f"tswm paper: report in {Path(args.output) / 'paper-report.html'}; "
          f"{wall_time_text(report['data']['timing'])}")
    return 0
