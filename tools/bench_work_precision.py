"""The bench: every speed figure beside its target, with the work-precision report (tswm's
simulate() and sweep() against careful-user peers, scipy's solve_ivp and SUNDIALS CVODE via
scikit-sundae, error against the independent quadrature reference versus median wall time per
whole call). The code lives in tswm_runtime/bench/bench.py (also behind `tswm bench`). Run:
    .venv/bin/python tools/bench_work_precision.py [--quick] [-o DIR] [--cases N]
"""
from __future__ import annotations

import argparse
import sys

from tswm_runtime.bench import bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("-o", "--output", default="tswm-report/bench")
    parser.add_argument("--cases", type=int, help="throughput grid size (default 10000, --quick 1000)")
    args = parser.parse_args()
    sys.exit(bench.main(quick=args.quick, output=args.output, cases=args.cases))
