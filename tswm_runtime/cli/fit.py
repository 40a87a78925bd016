"""The ``tswm fit`` subcommand (argument parsing only; the work is imported when it runs)."""
from __future__ import annotations

import argparse
import sys
import time

from tswm_runtime.common.words import plural
from tswm_runtime.cli.common import (add_setting_options, output_directory, prepare_kernels, run_method,
                                     setting_error, setting_overrides)

FIT_SETTINGS = ("t_end", "rtol", "atol", "method", "max_steps", "max_events", "points")


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    output_directory(args.output)
    spec, cold = prepare_kernels(args.scene, ("integrate", "batch"), many_runs=True)
    from tswm_runtime.fitting.fit import FitInputError, fit
    from tswm_runtime.fitting.report import write_outputs
    from tswm_runtime.model.scenes import load_model
    from tswm_runtime.simulation.simulate import SimulationInputError
    from tswm_runtime.startup import warmup

    module = load_model(spec)
    if cold is not None:
        warmup.begin(cold, run_method(args, module))
    overrides = setting_overrides(args, FIT_SETTINGS)
    try:
        result = fit(module, args.measured, args.free, overrides=overrides, starts=args.starts,
                     sampler=args.sampler, seed=args.seed, magnitude=args.magnitude, confidence=args.confidence,
                     grid_points=args.grid_points, progress=not args.no_progress, misfit=not args.no_plot,
                     noise=args.noise, profile_points=args.profile_points)
    except KeyboardInterrupt:
        print(f"tswm fit {args.scene}: interrupted (Ctrl-C) after {time.perf_counter() - start:.3g} s; "
              "nothing written", file=sys.stderr)
        return 130
    except (FitInputError, SimulationInputError) as error:   # a run setting's is named by its option
        raise setting_error(error, overrides) from None
    except warmup.PYTHON_ONLY_ERRORS as error:
        if cold is None:
            raise
        return warmup.rerun_compiled(args.argv, error)
    print(f"scene {result.scene}: {result.measured['form']} of {plural(result.measured['cases'], 'case')} from "
          f"{args.measured}; {plural(len(result.starts), 'start')}, "
          f"{plural(result.fit_settings['model_runs'], 'model run')}, "
          f"{time.perf_counter() - start:.3g} s")
    for name, unit in zip(result.names, result.units):
        p = result.profiles[name]
        ci = (f"not determined by these data: any value in [{p['range'][0]:.6g}, {p['range'][1]:.6g}]"
              if p["verdict"] == "not determined" else
              f"{result.confidence:.0%} profile CI [{p['lo']:.6g}, {p['hi']:.6g}], {p['verdict']}")
        print(f"  {name} = {result.estimate[name]:.8g} {unit}  ({ci}; bounds {result.bounds[name][0]:g} to "
              f"{result.bounds[name][1]:g})")
    print(f"  cost {result.cost:.6g}, {result.dof} degrees of freedom, condition {result.condition:.4g}")
    for k, s in enumerate(result.starts):
        print(f"  start {k + 1}{' (best)' if k == result.best_start else ''}: "
              f"{', '.join(f'{v:.6g}' for v in s.x0)} -> {', '.join(f'{v:.8g}' for v in s.x)}, cost {s.cost:.6g}, "
              f"{s.nfev} evaluations")
    for note in result.notes:
        print(f"  note: {note}")
    for path in write_outputs(result, args.output, plot=not args.no_plot):
        print(f"  wrote {path}")
    return 0 if result.success else 1


def add_parser(sub) -> None:
    fit = sub.add_parser(
        "fit", help="identify free parameters from measured peaks or time histories (least squares)",
        description="Fit free parameters of a scene to measured values: peaks (one row per case: known "
                    "parameters, S1m, S2m, KD1, KD2) or a time history (columns t, case, S1, S2, v1), from a "
                    "CSV or Parquet file (the tables tswm sweep -o and tswm simulate -o write, as written), "
                    "with scipy.optimize.least_squares from several starts, and profile-likelihood intervals. "
                    "Writes DIR/fit-report.md, fit.json, misfit.png and profile.png (see docs/fit.md). Exit "
                    "status: 0 fitted, 1 "
                    "fitted but a case does not finish at the optimum (or no start converged), 2 bad input, "
                    "130 interrupted.")
    fit.add_argument("scene", help="a shipped scene name, a scene file (.toml) or a generated module's .py path")
    fit.add_argument("--measured", required=True, metavar="FILE",
                     help="the measured table, .csv or .parquet: one of docs/fit.md, or as tswm simulate -o or "
                          "tswm sweep -o wrote it")
    fit.add_argument("--free", action="append", default=[], required=True, metavar="NAME[=LO:HI]",
                     help="a free parameter to fit, within LO..HI (numbers in SI or with a unit: "
                          "m2='50 kg:0.6 t'; bare NAME: the scene's range, where it gives one); repeatable")
    fit.add_argument("--starts", type=int, default=4, metavar="K", help="starting points (default 4, at most 64)")
    fit.add_argument("--sampler", choices=("sobol", "lhs"), default="sobol",
                     help="how the starts are spread in the bounds (scipy.stats.qmc; default sobol)")
    fit.add_argument("--seed", type=int, default=0, help="seed of the starts (default 0)")
    fit.add_argument("--magnitude", action="store_true", help="compare |S1m| and |S2m| (default: signed values "
                     "as the sweep reports them)")
    fit.add_argument("--confidence", type=float, default=0.95, help="confidence level of the intervals "
                     "(default 0.95)")
    fit.add_argument("--noise", action="append", metavar="QUANTITY=SIGMA",
                     help="measurement noise (one standard deviation) of a measured quantity, SI or with a unit: "
                          "S1m='50 N'; give every quantity or none (default: estimated from the residuals)")
    fit.add_argument("--profile-points", type=int, metavar="N",
                     help="grid points of each parameter's profile (default 21, 5 to 201)")
    fit.add_argument("--grid-points", type=int, metavar="N",
                     help="misfit plot: points per axis (default 41 for one parameter, 15 for two)")
    add_setting_options(fit, FIT_SETTINGS)
    fit.add_argument("-o", "--output", default="tswm-report/fit", metavar="DIR",
                     help="write DIR/fit-report.md, fit.json, misfit.png, profile.png (default tswm-report/fit)")
    fit.add_argument("--no-plot", action="store_true", help="no misfit grid, no misfit.png and no profile.png")
    fit.add_argument("--no-progress", action="store_true", help="no progress bars")
    fit.set_defaults(run=run)
