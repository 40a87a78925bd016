"""What the subcommands share: the usage error (exit 2), output directories, the run-setting
options and their errors, and the model a scene names. Imports no subcommand."""
from __future__ import annotations

import argparse
from pathlib import Path

from tswm_common.text import printable


# An error or warning is one line: every value it echoes went through printable() already; the whole
# message goes through it once more where it is printed, so that no path that forgot reaches the
# terminal raw (at most MAX_MESSAGE characters).
MAX_MESSAGE = 4000


class UsageError(ValueError):
    """A command-line input that cannot be used; the message names it (exit status 2)."""


def output_directory(path: str | None, option: str = "-o") -> Path | None:
    """``path`` as an output directory, checked before any work: it may be missing, not a file."""
    if path is None:
        return None
    directory = Path(path)
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"{option} {printable(path)}: exists and is not a directory; name a directory (it is created "
                         "if missing)")
    return directory


# simulate's setting names -> the option that sets them, for error messages
SETTING_OPTIONS = {  # run setting: (option, type, metavar, help)
    "t_end": ("--t-end", float, "T", "end time [s] (default: the scene's)"),
    "rtol": ("--rtol", float, "R", "relative tolerance (default: the scene's)"),
    "atol": ("--atol", float, "A", "absolute tolerance (default: the scene's)"),
    "method": ("--method", str, None, "integrator, dopri5, rosenbrock23, rodas4 or auto (default: the scene's)"),
    "points": ("--points", int, "N", "number of output points (default: 1001)"),
    "max_steps": ("--max-steps", int, "N", "step attempts allowed per run (default: the scene's)"),
    "max_events": ("--max-events", int, "N", "size of the event log per run (default: 1000)"),
}


def add_setting_options(parser: argparse.ArgumentParser, keys) -> None:
    """The run-setting options (SETTING_OPTIONS) that simulate, sweep and fit share."""
    for key in keys:
        option, kind, metavar, help_text = SETTING_OPTIONS[key]
        if key == "method":
            parser.add_argument(option, choices=("dopri5", "rosenbrock23", "rodas4", "auto"), help=help_text)
        else:
            parser.add_argument(option, type=kind, metavar=metavar, help=help_text)


def setting_overrides(args: argparse.Namespace, keys) -> dict:
    return {key: getattr(args, key) for key in keys}


def chain_inputs(args: argparse.Namespace, keys):
    """A chain command's module, its run-setting overrides (without the method) and the method's name
    (--method, else dopri5: a chain's default)."""
    from tswm_runtime.model.scenes import load_chain_model

    module = load_chain_model(args.scene)
    overrides = setting_overrides(args, keys)
    return module, overrides, overrides.pop("method") or "dopri5"


def setting_error(error: Exception, overrides: dict) -> UsageError:
    """A SimulationInputError as a usage error naming the option (or the scene's [run] key)."""
    message = str(error)
    key = message.split(" = ", 1)[0]
    if key in overrides and overrides[key] is None:
        message = f"the scene's [run] setting {message}"
    elif key in SETTING_OPTIONS:
        message = f"{SETTING_OPTIONS[key][0]}: {message}"
    return UsageError(message)


def prepare_kernels(scene: str, groups, *, many_runs: bool = False):
    """Resolve the scene (``scenes.model_spec``) and, before anything compiles, choose how this
    command gets its kernels (``warmup.interpret_if_cold``: cached, compiled now with a message saying
    what and about how long, or run interpreted). ``many_runs``: the command runs the model hundreds
    of times (a fit), so it compiles first (with the message) unless TSWM_COLD_START is 'interpret'.
    Returns (spec for ``load_model``, the ColdStart to pass to ``warmup.begin`` once the run's method
    is known, or None)."""
    from tswm_runtime.jit import coldstart
    from tswm_runtime.model.scenes import model_spec
    from tswm_runtime.startup import warmup

    spec = model_spec(scene)
    try:
        if many_runs and warmup.mode() != "interpret":
            coldstart.announce(groups, spec)
            return spec, None
        return spec, warmup.interpret_if_cold(groups, spec)
    except warmup.ColdStartError as error:
        raise UsageError(str(error)) from None


def run_method(args: argparse.Namespace, module) -> str | None:
    """The integration method a command runs: its --method, else the scene's [run] method."""
    return args.method or module.RUN.get("method")


def parse_sets(items: list[str]) -> dict:
    """``--set name=value`` items as {name: value text}; the library converts the text (a number
    in SI or "<number> <unit>") and refuses names the scene does not have."""
    params = {}
    for item in items:
        name, sep, raw = item.partition("=")
        name, raw = name.strip(), raw.strip()
        if not sep or not name or not raw:
            raise UsageError(f"--set {item!r}: expected NAME=VALUE, e.g. F2=-5000")
        params[name] = raw
    return params
