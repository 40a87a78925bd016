"""``tswm bench``: work-precision against scipy and SUNDIALS, and sweep throughput."""
from __future__ import annotations

import argparse

from tswm_runtime.cli.common import UsageError, output_directory


def add_parser(sub) -> None:
    bench = sub.add_parser(
        "bench", help="work-precision benchmark against scipy and SUNDIALS, and sweep throughput",
        description="Error against an independent quadrature reference versus median wall time per whole "
                    "call for tswm (simulate(), sweep()) and careful-user peers (scipy solve_ivp, CVODE via "
                    "scikit-sundae) on five cases, configurations interleaved; sweep throughput; `tswm sweep` as "
                    "whole processes (10,000 and 100,000 cases, start-up) and against a vmapped diffrax batch "
                    "(optional: jax, or an interpreter in TSWM_BENCH_JAX_PYTHON) at equal accuracy; the "
                    "targets reported with the measured factor. Writes DIR/work-precision.md, runs.csv, "
                    "verdicts.csv, bench.json and work-precision.png.")
    bench.add_argument("--quick", action="store_true",
                       help="four tolerances, two rounds, a 1000-case throughput grid (about a minute)")
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
