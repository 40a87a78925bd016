"""How accurate tswm's output rows are: worst sample error per rtol and method.

For shipped scenes of the paper gear, against the independent reference of
``tswm_runtime.reference.dense`` (the quadrature's events, DOP853 at rtol 1e-13 between
them, on hand-written formulas), prints the worst sample error of x1, v1, S1, S2 in units
of rtol, separately for samples within the first 5 ms after a segment boundary (t0, an
event: "first") and all others ("ordinary"), for rtol 1e-3..1e-9 (atol = 1e-3 rtol) and
each method (dopri5, rosenbrock23, rodas4, auto). Measure: |y(t_i) - y_ref(t_i)| / (rtol max_t |y_ref|) (``dense.worst_ratios``).

Run: ``python tools/sample_accuracy.py [--points N] [--case NAME ...] [--method NAME ...] [--rtol R ...]``
"""
import argparse

from tswm_runtime.reference import dense
from tswm_runtime.simulation.simulate import simulate

METHODS = ("dopri5", "rosenbrock23", "rodas4", "auto")
RTOLS = tuple(10.0 ** -k for k in range(3, 10))
# name: (scene, free parameters, m2, load schedule of the reference, v1 at t = 0)
CASES = {
    "runup-load-step": ("paper-runup", {"F2_after": -5000.0, "t_step": 0.05}, 200.0,
                        [(0.0, 0.0), (0.05, -5000.0)], 0.0),
    "stall-stick-breakaway": ("load-schedule", {}, 200.0, [(0.0, 0.0), (0.3, -30000.0), (0.6, -2000.0)], 0.0),
    "brake-to-stick": ("paper", {"F2": -15000.0}, 200.0, [(0.0, -15000.0)], 2.0),
}


def measure(case, method, rtol, points, reference):
    """dense.worst_ratios of one run of ``case``."""
    scene, params, _, _, v0 = CASES[case]
    r = simulate(scene, params, method=method, rtol=rtol, atol=1e-3 * rtol, v1=v0, points=points)
    if r.status != "finished":
        raise RuntimeError(f"{case} {method} rtol {rtol:.0e}: {r.status}: {r.message}")
    return dense.worst_ratios(r, reference, rtol)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=20001, help="output rows over the run (default 20001)")
    ap.add_argument("--case", action="append", choices=sorted(CASES), help="only these cases")
    ap.add_argument("--method", action="append", choices=METHODS, help="only these methods")
    ap.add_argument("--rtol", action="append", type=float, help="these rtols (default 1e-3 .. 1e-9)")
    args = ap.parse_args(argv)
    cols = [(name, kind) for kind in ("ordinary", "first") for name in dense.QUANTITIES]
    for case in args.case or CASES:
        _, _, m2, schedule, v0 = CASES[case]
        reference = dense.PaperGear(m2, schedule, v0, 1.0)
        print(f"{case}: reference events {reference.events}, DOP853 vs quadrature {reference.check():.1e}")
        print(f"  {'method':12s} {'rtol':>6s} " + " ".join(f"{n + ' ' + k[:3]:>9s}" for n, k in cols))
        for method in args.method or METHODS:
            for rtol in args.rtol or RTOLS:
                w = measure(case, method, rtol, args.points, reference)
                print(f"  {method:12s} {rtol:6.0e} " + " ".join(f"{w[c]:9.2f}" for c in cols), flush=True)


if __name__ == "__main__":
    main()
