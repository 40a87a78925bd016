"""``tswm bench``: every speed figure beside its target."""
from __future__ import annotations

import argparse

from tswm_runtime.cli.common import UsageError, output_directory


def add_parser(sub) -> None:
    bench = sub.add_parser(
        "bench", help="every speed figure beside its target: work-precision against scipy and SUNDIALS, sweeps, "
             "generate, cold start, drive train",
        description="Every speed figure beside its target (DIR/targets.csv and the first table of "
                    "DIR/work-precision.md): the fixed cost of simulate(); error against an independent "
                    "quadrature reference versus median wall time per whole call for tswm (simulate(), sweep()) "
                    "and careful-user peers (scipy solve_ivp, CVODE via scikit-sundae), configurations "
                    "interleaved, and method auto against them; `tswm sweep` as whole processes and against a "
                    "vmapped diffrax batch (optional: jax, or an interpreter in TSWM_BENCH_JAX_PYTHON) at equal "
                    "accuracy; `tswm generate` of the shipped scenes and of a 999-breakpoint schedule, and its "
                    "events; the first run on an empty numba cache; a two-stage drive train against scipy. "
                    "Also writes runs.csv, verdicts.csv, bench.json and the work-precision plots.")
    bench.add_argument("--quick", action="store_true",
                       help="smaller counts for every row: four tolerances, two rounds, a tenth of the sweep "
                            "cases, the forced compile only (a few minutes)")
    bench.add_argument("-o", "--output", default="tswm-report/bench", metavar="DIR",
                       help="output directory (default tswm-report/bench)")
    bench.add_argument("--cases", type=int, metavar="N",
                       help="cases in the sweep-throughput grid (default 10000, --quick 1000)")
    bench.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from tswm_runtime.bench import bench
    from tswm_runtime.sweeps.sweep import MAX_SWEEP_CASES

    output_directory(args.output)
    if args.cases is not None and not 1 <= args.cases <= MAX_SWEEP_CASES:
        raise UsageError(f"--cases {args.cases}: must be in [1, {MAX_SWEEP_CASES:.0e}]")
    return bench.main(quick=args.quick, output=args.output, cases=args.cases)
