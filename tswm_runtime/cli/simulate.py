"""``tswm simulate``: one run of a scene, summarised; -o writes CSV, NPZ, JSON and a plot."""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

from tswm_runtime.common.words import plural
from tswm_runtime.cli.common import (SETTING_OPTIONS, UsageError, add_setting_options, chain_inputs, output_directory,
                                     parse_sets, prepare_kernels, run_method, setting_error, setting_overrides)

MAX_EVENT_LINES = 40


def add_parser(sub) -> None:
    simulate = sub.add_parser(
        "simulate", help="simulate a scene and summarise the run",
        description="Simulate a scene and print its phases, events, maxima of S1 and S2 and counts. "
                    "Exit status: 0 finished, 1 the run stopped early (status and message printed), "
                    "2 bad input.")
    simulate.add_argument("scene", help="a shipped scene name (paper, paper-literal, ...), a scene file "
                          "(.toml) or a generated module's .py path")
    simulate.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                          help="a free parameter's value (a chain scene: any of its values, mu_1=0.08, and "
                               "voltage): a plain number in SI units (F2=-5000) or a "
                               "number with a unit of the parameter's quantity (F2='-5 kN', "
                               "m2='200 kg'); repeatable")
    add_setting_options(simulate, SETTING_OPTIONS)
    simulate.add_argument("-o", "--output", metavar="DIR",
                          help="write DIR/SCENE.csv, SCENE.npz, SCENE-summary.json and SCENE.png")
    simulate.add_argument("--no-plot", action="store_true", help="with -o: do not write the PNG")
    simulate.set_defaults(run=run)


def _origin(scene: str, module) -> str:
    """Where the model came from, as a path that exists: the module file (relative to the working
    directory when it lies below it), and the scene file it was generated from."""
    path = os.path.relpath(module.__file__) if not os.path.relpath(module.__file__).startswith("..") \
        else module.__file__
    return f"{path}, from {scene}" if scene.endswith(".toml") else path


def _table(rows: list[tuple[str, ...]], indent: str = "    ") -> list[str]:
    """Rows of strings as left-aligned columns."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return [indent + "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def _print_summary(result, module, origin: str, t_load: float, t_run: float) -> None:
    """The run at a glance: inputs, status, phases, events, maxima, KD, counts, wall time."""
    units = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS))
    run = result.settings
    print(f"scene {result.scene} ({module.EQUATIONS} equations, {origin})")
    params = ", ".join(f"{k} = {v:g} {units[k]}".rstrip() for k, v in result.params.items())
    print(f"  parameters: {params or 'none free'}")
    print(f"  run: t_end = {run['t_end']:g} s, x1(0) = {run['x1']:g} m, v1(0) = {run['v1']:g} m/s, "
          f"{run['method']}, rtol {run['rtol']:g}, atol {run['atol']:g}, {plural(run['points'], 'point')}")
    print(f"  status: {result.status}: {result.message}")
    print(f"  phases ({len(result.phases)}):")
    rows = [("regime", "mode", "t_start [s]", "t_end [s]")]
    rows += [(ph.regime, ph.mode, f"{ph.t_start:.9g}", f"{ph.t_end:.9g}") for ph in result.phases]
    print("\n".join(_table(rows)))
    print(f"  events ({len(result.events)}):")
    if result.events:
        shown = result.events[:MAX_EVENT_LINES]
        rows = [("t [s]", "kind", "from -> to", "impact: P_n [N s], energy lost [J]")]
        rows += [(f"{e.t:.9g}", e.kind, f"{e.from_mode} -> {e.to_mode or '(stop)'}",
                  f"{e.jump.P_n:.6g}, {e.jump.energy_lost:.6g}" if e.jump else "") for e in shown]
        print("\n".join(_table(rows)))
        if len(result.events) > len(shown):
            print(f"    ... {len(result.events) - len(shown)} more (all in the -o summary JSON)")
    for name, value, t in (("S1", result.S1_max, result.t_S1_max), ("S2", result.S2_max, result.t_S2_max)):
        if math.isnan(value):
            print(f"  {name} max: none (the run stopped at its start: nothing was integrated)")
            continue
        shown = f"{value:.6g} N" if math.isfinite(value) else f"unbounded ({'+' if value > 0 else '-'}inf)"
        print(f"  {name} max = {shown} at t = {t:.6g} s")
    if result.impacts:
        print(f"  impacts: {len(result.impacts)}, kinetic energy lost {result.impact_energy:.6g} J "
              "(rigid impacts: impulses, not forces; S1, S2 and KD cover the contact phases)")
    if result.KD1 is not None or result.KD2 is not None:
        print(f"  KD1 = {result.KD1:.6g}, KD2 = {result.KD2:.6g}".replace("inf", "unbounded"))
    print(f"  steps {result.n_steps} (rejected {result.n_rejected}), rhs calls {result.nfev}, "
          f"jacobian calls {result.njev}"
          + (f", method switches {result.n_switches}" if result.settings.get("method") == "auto" else ""))
    print(f"  wall time {t_load + t_run:.3g} s (runtime and module load {t_load:.3g} s, simulation {t_run:.3g} s)")


def _warn_if_edited(module) -> None:
    """A warning on stderr when a generated module's body no longer matches its header's digest."""
    from tswm_common.files import body_digests
    from tswm_common.text import printable

    stated, actual = body_digests(open(module.__file__, encoding="utf-8", errors="replace").read())
    if stated is not None and stated != actual:
        print(f"tswm simulate: warning: {printable(module.__file__)}: its body no longer matches its "
              "'# body-sha256:' header (edited by hand since it was generated); running the edited code",
              file=sys.stderr)


def _run_chain(args: argparse.Namespace) -> int:
    """A chain scene ([[stage]] tables; a file or a shipped chain's name): its run, per stage regimes, switch
    times, force maxima, a drive train's answers; with -o the summary (JSON) and the figure per stage."""
    import json

    from tswm_common.files import write_atomic
    from tswm_runtime.simulation.chain import plot, simulate_chain, summary
    from tswm_runtime.simulation.simulate import METHODS, SimulationInputError

    module, overrides, method = chain_inputs(args, SETTING_OPTIONS)
    params = parse_sets(args.set)
    try:
        result = simulate_chain(module, params, method=METHODS[method], **overrides)
    except SimulationInputError as error:
        raise setting_error(error, overrides) from None
    print(f"chain {module.SCENE} ({plural(module.STAGES, 'stage')}, {_origin(args.scene, module)})")
    print(f"  run: t_end = {result.t[-1]:g} s, v0(0) = {module.RUN['v0']:g} (body 0, SI), {method}")
    if params:
        slot = {name: (module.P_VALUES + j, unit) for j, (name, unit) in enumerate(zip(module.PARAM_NAMES,
                                                                                       module.PARAM_UNITS))}
        slot["voltage"] = (module.P_VOLTAGE, "")
        print("  values set: " + ", ".join(f"{name} = {result.p[slot[name][0]]:g} {slot[name][1]}".rstrip()
                                           for name in params))
    print("\n".join(summary(result, module)))
    if args.output:
        path = write_atomic(os.path.join(args.output, f"{module.SCENE}-summary.json"),
                            json.dumps(result.to_dict(), indent=1, allow_nan=True))
        print(f"  wrote {path}")
        print(f"  wrote {plot(result, module, os.path.join(args.output, f'{module.SCENE}-stages.png'))}")
    return 0 if result.status == "finished" else 1


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    output_directory(args.output)
    from tswm_runtime.model.scenes import is_chain

    if is_chain(args.scene):
        return _run_chain(args)
    spec, cold = prepare_kernels(args.scene, ("integrate",))
    from tswm_runtime.model.contract import ContractError
    from tswm_runtime.model.scenes import load_model
    from tswm_runtime.simulation.simulate import SimulationInputError, parameter_vector, settings, simulate
    from tswm_runtime.startup import warmup

    module = load_model(spec)
    _warn_if_edited(module)
    params = parse_sets(args.set)
    overrides = setting_overrides(args, SETTING_OPTIONS)
    try:  # bad input exits 2 before any background compile starts
        parameter_vector(module, params)
        settings(module, overrides)
    except SimulationInputError as error:
        raise setting_error(error, overrides) from None
    if cold is not None:
        warmup.begin(cold, run_method(args, module))
    t_load = time.perf_counter() - start
    start = time.perf_counter()
    try:
        result = simulate(module, params, interruptible=True, **overrides)
    except KeyboardInterrupt:
        print(f"tswm simulate {args.scene}: interrupted (Ctrl-C) after {time.perf_counter() - start:.3g} s; "
              "nothing written", file=sys.stderr)
        return 130
    except SimulationInputError as error:
        raise setting_error(error, overrides) from None
    except ContractError as error:
        raise UsageError(f"scene {args.scene!r}: {error}") from None
    except warmup.PYTHON_ONLY_ERRORS as error:
        if cold is None:
            raise
        return warmup.rerun_compiled(args.argv, error)
    t_run = time.perf_counter() - start
    origin = _origin(args.scene, module)
    _print_summary(result, module, origin, t_load, t_run)
    if args.output:
        from tswm_runtime.results.export import write_outputs

        for path in write_outputs(result, module, args.output, plot=not args.no_plot,
                                  wall_time=t_load + t_run):
            print(f"  wrote {path}")
    return 0 if result.success else 1
