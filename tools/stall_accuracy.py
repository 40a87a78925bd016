"""Stall positions of a 10,000-case sweep against an independent reference.

Sweeps paper-runup (run up free, then a load step F2_after at t_step) over the grid m2 x F2_after
x t_step below, through ``tswm_runtime.sweep`` (the parallel batch), and compares each case's x1
at t_end with scipy's DOP853 at rtol 1e-13 on the hand formulas (``reference.runup_stall``): for
a case that stalls, x1 stays where v1 fell to 0 (the self-locking gear sticks). Prints the worst
and median relative error of the stall position, and of x1 at t_end for the cases that do not
stall, in units of rtol too. The reference takes about 0.15 s a case (25 min for the grid).

Run: ``python tools/stall_accuracy.py [--method dopri5|rosenbrock23] [--rtol 1e-6] [--counts 4,50,50] [--save FILE.npz]``
"""
import argparse
import time

import numpy as np

from tswm_runtime import api
from tswm_runtime.reference import runup_stall

T_END = 1.0
M2, F2_AFTER, T_STEP = (100.0, 300.0), (-40000.0, -15000.0), (0.05, 0.3)


def reference(cases):
    """(stalled, x1 at t_end) of every row (m2, F2_after, t_step), one run-up per m2."""
    stalled, x1 = np.zeros(len(cases), bool), np.zeros(len(cases))
    for m2 in np.unique(cases[:, 0]):
        free = runup_stall.run_up(m2, T_STEP[1])
        for c in np.flatnonzero(cases[:, 0] == m2):
            outcome = runup_stall.loaded(free, m2, cases[c, 1], cases[c, 2], T_END)
            stalled[c], x1[c] = outcome.stalled, outcome.x1
    return stalled, x1


def summary(name, errors, rtol):
    if errors.size == 0:
        return f"{name}: no cases"
    worst, median = errors.max(), np.median(errors)
    return (f"{name}: {errors.size} cases, relative error worst {worst:.2e} ({worst / rtol:.3g} rtol), "
            f"median {median:.2e} ({median / rtol:.3g} rtol)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="dopri5", choices=("dopri5", "rosenbrock23"))
    parser.add_argument("--rtol", type=float, default=1e-6)
    parser.add_argument("--counts", default="4,50,50", help="grid points of m2, F2_after, t_step")
    parser.add_argument("--save", help="an .npz file for the cases, tswm's x1, the reference's x1 and stalls")
    args = parser.parse_args()
    counts = [int(n) for n in args.counts.split(",")]
    grid = {name: f"{lo}:{hi}:{n}" for name, (lo, hi), n in zip(("m2", "F2_after", "t_step"),
                                                                 (M2, F2_AFTER, T_STEP), counts)}
    start = time.perf_counter()
    table = api.sweep("paper-runup", grid, method=args.method, rtol=args.rtol, atol=args.rtol * 1e-3,
                      t_end=T_END).table
    swept = time.perf_counter() - start
    cases = table[["m2", "F2_after", "t_step"]].to_numpy()
    stalled, x1 = reference(cases)
    errors = np.abs(table["x1"].to_numpy() / x1 - 1.0)
    sticks = table["regimes"].str.endswith("S").to_numpy()
    print(f"paper-runup, {len(table)} cases ({', '.join(f'{k} {v}' for k, v in grid.items())}), {args.method}, "
          f"rtol {args.rtol:g}, atol {args.rtol * 1e-3:g}; sweep {swept:.1f} s, reference "
          f"{time.perf_counter() - start - swept:.0f} s")
    print(f"statuses {table['status'].value_counts().to_dict()}; stall disagreements with the reference: "
          f"{int(np.sum(sticks != stalled))}")
    print(summary("stall position", errors[stalled], args.rtol))
    print(summary("x1 at t_end without a stall", errors[~stalled], args.rtol))
    if args.save:
        np.savez(args.save, cases=cases, x1=table["x1"].to_numpy(), x1_reference=x1, stalled=stalled)
    worst = np.argmax(np.where(stalled, errors, -1.0))
    print(f"worst stall: m2 = {cases[worst, 0]:.6g} kg, F2_after = {cases[worst, 1]:.6g} N, "
          f"t_step = {cases[worst, 2]:.6g} s: x1 {table['x1'][worst]:.12g} m, reference {x1[worst]:.12g} m")


if __name__ == "__main__":
    main()
