"""The ``tswm`` command. Subcommands import what they need, so simulation never loads SymPy."""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path


def _derive(args: argparse.Namespace) -> int:
    from derivation.audit import audit
    from derivation.document import build_document, render
    from derivation.latex import build_pdf
    from derivation.model import build_model
    from derivation.scene import load_scene
    from tswm_runtime.common.files import write_atomic

    scene = load_scene(args.scene)
    model = build_model(scene)
    print(f"scene {scene.name} ({scene.source}): equations {scene.equations}, flanks {', '.join(scene.flanks)}")
    print(f"  modes: {', '.join(f'{m.name} ({m.regime})' for m in model.modes)}")
    print(f"  states: {', '.join(map(str, model.states))}; free parameters: "
          f"{', '.join(p.name for p in scene.free_params()) or 'none'}")
    print("  audit: " + "; ".join(f"eq. {e.equation} {'agrees' if e.agrees else 'differs'}" for e in audit()))
    if not (args.latex or args.markdown or args.pdf):
        return 0
    doc = build_document(model)
    if args.markdown:
        print(f"  wrote {write_atomic(args.markdown, render(doc, 'markdown'))}")
    latex = render(doc, "latex")
    if args.latex:
        print(f"  wrote {write_atomic(args.latex, latex)}")
    if args.pdf:
        pdf = Path(args.pdf if isinstance(args.pdf, str) else (args.latex or f"{scene.name}-derivation.tex"))
        print(f"  wrote {build_pdf(latex, pdf.with_suffix('.pdf'))}")
    return 0


def _generate(args: argparse.Namespace) -> int:
    from derivation.codegen import write_module
    from derivation.model import build_model
    from derivation.scene import load_scene

    output_directory(args.output)
    model = build_model(load_scene(args.scene))
    path = write_module(model, args.output, force=args.force)
    print(f"wrote {path}: modes {', '.join(m.name for m in model.modes)}; "
          f"free parameters {', '.join(p.name for p in model.scene.free_params()) or 'none'}")
    return 0


class UsageError(ValueError):
    """A command-line input that cannot be used; the message names it (exit status 2)."""


def output_directory(path: str | None, option: str = "-o") -> Path | None:
    """``path`` as an output directory, checked before any work: it may be missing, not a file."""
    if path is None:
        return None
    directory = Path(path)
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"{option} {path}: exists and is not a directory; name a directory (it is created "
                         "if missing)")
    return directory


# simulate's setting names -> the option that sets them, for error messages
SETTING_OPTIONS = {  # run setting: (option, type, metavar, help)
    "t_end": ("--t-end", float, "T", "end time [s] (default: the scene's)"),
    "rtol": ("--rtol", float, "R", "relative tolerance (default: the scene's)"),
    "atol": ("--atol", float, "A", "absolute tolerance (default: the scene's)"),
    "method": ("--method", str, None, "integrator, dopri5 or rosenbrock23 (default: the scene's)"),
    "points": ("--points", int, "N", "number of output points (default: 1001)"),
    "max_steps": ("--max-steps", int, "N", "step attempts allowed per run (default: the scene's)"),
    "max_events": ("--max-events", int, "N", "size of the event log per run (default: 1000)"),
}
MAX_EVENT_LINES = 40


def _shipped_modules() -> list[str]:
    """Scene names of the generated modules shipped in ``generated/``."""
    import pkgutil

    import generated

    return sorted(m.name.replace("_", "-") for m in pkgutil.iter_modules(generated.__path__))


def _model_spec(scene: str) -> str:
    """A shipped scene name or a generated module's .py path, as ``load_module`` takes it (a
    scene file, .toml, is generated into the user cache on first use: derivation.model_cache)."""
    if Path(scene).suffix == ".toml":
        from derivation.model_cache import module_for_scene

        return str(module_for_scene(scene))
    if Path(scene).suffix != ".py" and ("/" in scene or "\\" in scene or Path(scene).suffix):
        raise UsageError(f"scene {scene!r}: expected a shipped scene name, a scene file (.toml) or a "
                         "generated module (.py)")
    return scene


def prepare_kernels(scene: str, groups):
    """Resolve the scene (``_model_spec``) and, before anything compiles, choose how this command
    gets its kernels (``warmup.interpret_if_cold``: cached, compiled now with a message saying what
    and about how long, or run interpreted). Returns (spec for ``_load_model``, the ColdStart to
    pass to ``warmup.begin`` once the run's method is known, or None)."""
    from tswm_runtime.apps import warmup

    spec = _model_spec(scene)
    try:
        return spec, warmup.interpret_if_cold(groups, spec)
    except warmup.ColdStartError as error:
        raise UsageError(str(error)) from None


def run_method(args: argparse.Namespace, module) -> str | None:
    """The integration method a command runs: its --method, else the scene's [run] method."""
    return args.method or module.RUN.get("method")


def _load_model(scene: str):
    """The generated module of a shipped scene name, a scene file (.toml: generated into the
    user cache on first use, see derivation.model_cache) or a module's .py path."""
    from tswm_runtime.model.contract import ContractError, load_module

    scene = _model_spec(scene)
    try:
        return load_module(scene)
    except ModuleNotFoundError as error:
        if not (error.name or "").startswith("generated."):
            raise
        raise UsageError(f"scene {scene!r}: no generated module (shipped: {', '.join(_shipped_modules())}); "
                         f"run `tswm generate SCENE` or pass a module's .py path") from None
    except ContractError as error:
        raise UsageError(f"scene {scene!r}: {error}") from None


def add_setting_options(parser: argparse.ArgumentParser, keys) -> None:
    """The run-setting options (SETTING_OPTIONS) that simulate and sweep share."""
    for key in keys:
        option, kind, metavar, help_text = SETTING_OPTIONS[key]
        if key == "method":
            parser.add_argument(option, choices=("dopri5", "rosenbrock23"), help=help_text)
        else:
            parser.add_argument(option, type=kind, metavar=metavar, help=help_text)


def setting_overrides(args: argparse.Namespace, keys) -> dict:
    return {key: getattr(args, key) for key in keys}


def setting_error(error: Exception, overrides: dict) -> UsageError:
    """A SimulationInputError as a usage error naming the option (or the scene's [run] key)."""
    message = str(error)
    key = message.split(" = ", 1)[0]
    if key in overrides and overrides[key] is None:
        message = f"the scene's [run] setting {message}"
    elif key in SETTING_OPTIONS:
        message = f"{SETTING_OPTIONS[key][0]}: {message}"
    return UsageError(message)


def _parse_sets(items: list[str], module) -> dict:
    """``--set name=value`` items as {name: value}; values in SI or "<number> <unit>".

    Names the module does not have are passed on as written: ``simulate`` rejects them
    with a message listing the free parameters."""
    from tswm_runtime.common import units

    quantity_of = {units.si_unit(q): q for q in units.UNITS}
    unit_of = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS))
    params = {}
    for item in items:
        name, sep, raw = item.partition("=")
        name, raw = name.strip(), raw.strip()
        if not sep or not name or not raw:
            raise UsageError(f"--set {item!r}: expected NAME=VALUE, e.g. F2=-5000")
        value: object = raw
        try:
            value = float(raw)
        except ValueError:
            quantity = quantity_of.get(unit_of.get(name))
            if quantity is not None:
                try:
                    value = units.to_si(raw, quantity)
                except units.UnitError as error:
                    raise UsageError(f"parameter {name} = {raw!r}: {error}") from None
        params[name] = value
    return params


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
          f"{run['method']}, rtol {run['rtol']:g}, atol {run['atol']:g}, {run['points']} points")
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
        shown = f"{value:.6g} N" if math.isfinite(value) else f"unbounded ({'+' if value > 0 else '-'}inf)"
        print(f"  {name} max = {shown} at t = {t:.6g} s")
    if result.impacts:
        print(f"  impacts: {len(result.impacts)}, kinetic energy lost {result.impact_energy:.6g} J "
              "(rigid impacts: impulses, not forces; S1, S2 and KD cover the contact phases)")
    if result.KD1 is not None or result.KD2 is not None:
        print(f"  KD1 = {result.KD1:.6g}, KD2 = {result.KD2:.6g}".replace("inf", "unbounded"))
    print(f"  steps {result.n_steps} (rejected {result.n_rejected}), rhs calls {result.nfev}, "
          f"jacobian calls {result.njev}")
    print(f"  wall time {t_load + t_run:.3g} s (runtime and module load {t_load:.3g} s, simulation {t_run:.3g} s)")


def _simulate(args: argparse.Namespace) -> int:
    import time

    start = time.perf_counter()
    output_directory(args.output)
    spec, cold = prepare_kernels(args.scene, ("integrate",))
    from tswm_runtime.apps import warmup
    from tswm_runtime.apps.simulate import SimulationInputError, simulate
    from tswm_runtime.model.contract import ContractError

    module = _load_model(spec)
    if cold is not None:
        warmup.begin(cold, run_method(args, module))
    t_load = time.perf_counter() - start
    params = _parse_sets(args.set, module)
    overrides = setting_overrides(args, SETTING_OPTIONS)
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
    origin = args.scene if args.scene.endswith(".py") else f"generated/{args.scene.replace('-', '_')}.py"
    _print_summary(result, module, origin, t_load, t_run)
    if args.output:
        from tswm_runtime.results.export import write_outputs

        for path in write_outputs(result, module, args.output, plot=not args.no_plot,
                                  wall_time=t_load + t_run):
            print(f"  wrote {path}")
    return 0 if result.success else 1


def _paper(args: argparse.Namespace) -> int:
    import time

    start = time.perf_counter()
    output_directory(args.output)
    from tswm_runtime.apps.paper_report import build_report, wall_time_text

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
    from tswm_runtime.apps.simulate import SimulationInputError

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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tswm", description="Derive, generate and simulate wedge mechanisms.")
    sub = parser.add_subparsers(dest="command", required=True)
    derive = sub.add_parser("derive", help="derive a scene's model and write the derivation document")
    derive.add_argument("scene", help="a shipped scene name (derivation/scenes/*.toml) or a .toml path")
    derive.add_argument("--latex", metavar="FILE.tex", help="write a standalone LaTeX document")
    derive.add_argument("--markdown", metavar="FILE.md", help="write the same document as Markdown with $$ math")
    derive.add_argument("--pdf", nargs="?", const=True, metavar="FILE.pdf",
                        help="build a PDF with pdflatex (default name: the --latex file's, else SCENE-derivation.pdf)")
    derive.set_defaults(run=_derive)
    generate = sub.add_parser("generate", help="emit the scene's numba module")
    generate.add_argument("scene", help="a shipped scene name or a .toml path")
    generate.add_argument("-o", "--output", default="generated", metavar="DIR",
                          help="directory for the module (default: generated)")
    generate.add_argument("--force", action="store_true", help="overwrite a module that was edited by hand")
    generate.set_defaults(run=_generate)
    simulate = sub.add_parser(
        "simulate", help="simulate a scene's generated module and summarise the run",
        description="Simulate a scene and print its phases, events, maxima of S1 and S2 and counts. "
                    "Exit status: 0 finished, 1 the run stopped early (status and message printed), "
                    "2 bad input.")
    simulate.add_argument("scene", help="a shipped scene name (one with a module in generated/: paper, "
                          "paper-literal, ...) or a path to a generated module .py")
    simulate.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                          help="a free parameter's value: a plain number in SI units (F2=-5000) or a "
                               "number with a unit of the parameter's quantity (F2='-5 kN', "
                               "m2='200 kg'); repeatable")
    add_setting_options(simulate, SETTING_OPTIONS)
    simulate.add_argument("-o", "--output", metavar="DIR",
                          help="write DIR/SCENE.csv, SCENE.npz, SCENE-summary.json and SCENE.png")
    simulate.add_argument("--no-plot", action="store_true", help="with -o: do not write the PNG")
    simulate.set_defaults(run=_simulate)
    from tswm_runtime.cli import sweep as sweep_cli  # sweep and bench: argument parsing only, work imported lazily

    sweep_cli.add_parsers(sub)
    from tswm_runtime.cli import fit as fit_cli

    fit_cli.add_parser(sub)
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
    paper.set_defaults(run=_paper)
    return parser


def _bad_input() -> tuple[type[Exception], ...]:
    """The exception types that mean bad input (exit 2). derivation/'s own count only if it was
    loaded, so a simulation never imports it (and if it was not loaded, none was raised)."""
    from tswm_runtime.common.files import EditedModuleError

    kinds = [EditedModuleError, FileNotFoundError, UsageError]
    for module, name in (("derivation.scene", "SceneError"), ("derivation.latex", "TexUnavailable")):
        if module in sys.modules:
            kinds.append(getattr(sys.modules[module], name))
    return tuple(kinds)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)   # to rerun the command (apps.warmup)
    try:
        status = args.run(args)
        sys.stdout.flush()  # a reader that went away shows here at the latest, not at exit
        return status
    except BrokenPipeError:
        return _stdout_closed()
    except Exception as error:
        if not isinstance(error, _bad_input()):
            if isinstance(error, OSError):
                return _os_error(args, error)
            raise
        print(f"tswm {args.command}: error: {error}", file=sys.stderr)
        return 2


SIGPIPE_EXIT = 141  # 128 + SIGPIPE (13): what a shell reports for a Unix tool whose reader went away


def _stdout_closed() -> int:
    """stdout's reader went away (``tswm ... | head``): stop quietly as a Unix tool stopped by
    SIGPIPE does (no message, exit 141). stdout is pointed at the null device, so that
    Python's flush at exit finds no broken pipe either."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout replaced by an object without a file (in-process callers)
        pass
    return SIGPIPE_EXIT


def _os_error(args: argparse.Namespace, error: OSError) -> int:
    """-o naming a file, a name too long, no permission: the path the user gave (exit 2)."""
    name = str(error.filename or "")
    where = f"{name if len(name) <= 200 else name[:160] + '...'}: " if name else ""
    print(f"tswm {args.command}: error: {where}{error.strerror or error} (check -o and the paths given)",
          file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
