"""Method auto against dopri5, rosenbrock23, rodas4 and the scipy peers, on the benchmark's cases.

Each configuration is one whole ``simulate()`` call (``bench.cases.run_simulate`` with the
method, at each rtol the method accepts: ``METHOD_RTOL_MIN``) or one careful user's peer call (``bench.peers``), measured by ``bench.measure``:
one untimed warm-up, then rounds over all configurations in shuffled order, medians. Errors
against each case's reference (``bench.cases.reference``). Prints, and writes to DIR/auto.json
and DIR/auto.md: per run the error, median time, rhs calls and steps; per case and error
level the time each tswm method needs (interpolated on its work-precision front) against
the fastest peer's.

    python tools/bench_auto.py [--cases NAME ...] [--tols 1e-4 1e-6 ...] [--repeats N] [-o DIR]
"""
from __future__ import annotations

import argparse
import json
import math
import os
from functools import partial
from pathlib import Path

from tswm_runtime.bench import report
from tswm_runtime.bench.bench import ATOL_PER_RTOL, measure
from tswm_runtime.bench.cases import CASES, reference, run_peer, run_simulate
from tswm_runtime.bench.peers import SCIPY_METHODS
from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN

METHODS = ("dopri5", "rosenbrock23", "rodas4", "auto")
LEVELS = (1e-6, 1e-9)


def configurations(cases, tols, peers):
    out = []
    for case in cases:
        for rtol in tols:
            atol = rtol * ATOL_PER_RTOL
            out += [(case, f"tswm {m}", rtol, partial(run_simulate, case, rtol, atol, method=m), 1) for m in METHODS
                    if rtol >= METHOD_RTOL_MIN[m][0]]
            out += [(case, p, rtol, partial(run_peer, case, p, rtol, atol), 1) for p in peers]
    return out


def comparisons(rows):
    """``report.versus_peers`` for each tswm method, and each other's time over auto's (> 1: auto is faster)."""
    out = report.versus_peers(rows, lambda case: {m: f"tswm {m}" for m in METHODS}, LEVELS)
    for row in out:
        row |= {f"{k}_over_auto": row[f"{k}_s"] / row["auto_s"] for k in ("dopri5", "rosenbrock23", "rodas4", "peer")}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", default=list(CASES), help="case names (default: all)")
    parser.add_argument("--tols", nargs="*", type=float, default=[1e-4, 1e-6, 1e-8, 1e-10])
    parser.add_argument("--peers", nargs="*", default=list(SCIPY_METHODS))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("-o", "--output", default="tswm-report/bench-auto")
    args = parser.parse_args(argv)
    unknown = [c for c in args.cases if c not in CASES]
    if unknown:
        parser.error(f"--cases: unknown {unknown}; known: {list(CASES)}")
    cases = [CASES[c] for c in args.cases]
    for case in cases:
        reference(case)
    load_before = os.getloadavg()
    rows = measure(configurations(cases, args.tols, args.peers), args.repeats, log=lambda s: print(s, flush=True))
    load_after = os.getloadavg()
    table = comparisons(rows)
    fmt = {"rtol": "{:.0e}", "err": "{:.2e}", "t_med": "{:.3e}", "t_min": "{:.3e}", "t_max": "{:.3e}"}
    cfmt = {"error": "{:.0e}"} | {k: ("{:.2f}" if "_over_" in k else "{:.3e}") for k in table[0] if k.endswith("_s")
                                   or "_over_" in k}
    md = "\n".join([
        "# Method auto against dopri5, rosenbrock23, rodas4 and the scipy peers", "",
        f"{args.repeats} shuffled rounds, medians of whole calls; load (1, 5, 15 min) before "
        f"{', '.join(f'{x:.1f}' for x in load_before)}, after {', '.join(f'{x:.1f}' for x in load_after)}.", "",
        report.md_table(rows, ["case", "solver", "rtol", "err", "err_S1", "err_v1", "err_x1", "err_t", "t_med",
                               "t_min", "t_max", "nfev", "steps", "events", "status"],
                        fmt | {k: "{:.2e}" for k in ("err_S1", "err_v1", "err_x1", "err_t")}), "",
        "Seconds per call at equal error (interpolated on each front); x_over_auto: x's time over auto's "
        "(> 1: auto faster):", "", report.md_table(table, list(table[0]), cfmt), ""])
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    (out / "auto.md").write_text(md)
    (out / "auto.json").write_text(json.dumps({"rows": rows, "comparisons": table, "load_before": load_before,
                                               "load_after": load_after}, indent=1, default=str))
    print(md)
    return 0 if all(not math.isnan(r["t_med"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
