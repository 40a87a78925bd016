"""Work-precision report: tswm's integrators against scipy's solve_ivp and SUNDIALS CVODE
(scikit-sundae), error against a high-accuracy reference versus wall time per scene, and
sweep throughput (cases per second) against a plain solve_ivp loop. The code lives in
tswm_runtime/bench.py (also behind `tswm bench`). Run:
    .venv/bin/python tools/bench_work_precision.py [--quick] [-o DIR] [--cases N]
"""
from __future__ import annotations

import argparse
import sys

from tswm_runtime import bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("-o", "--output", default="tswm-report/bench")
    parser.add_argument("--cases", type=int, default=1000)
    args = parser.parse_args()
    sys.exit(bench.main(quick=args.quick, output=args.output, cases=args.cases))
