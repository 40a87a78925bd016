"""The ``tswm`` command: builds the parser from the subcommand modules and dispatches; each
subcommand imports its work when it runs, so a simulation never loads SymPy."""
from __future__ import annotations

import argparse
import os
import sys

from tswm_common.text import printable
from tswm_runtime.cli import bench, derive, fit, generate, paper, simulate, sweep
from tswm_runtime.cli.common import MAX_MESSAGE, UsageError

SUBCOMMANDS = (derive, generate, simulate, sweep, fit, paper, bench)


def _parser() -> argparse.ArgumentParser:
    from tswm_runtime import __version__

    parser = argparse.ArgumentParser(prog="tswm", description="Derive, generate and simulate wedge mechanisms.")
    parser.add_argument("--version", action="version", version=f"tswm {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in SUBCOMMANDS:
        command.add_parser(sub)
    return parser


def _bad_input() -> tuple[type[Exception], ...]:
    """The exception types that mean bad input (exit 2). derivation/'s own count only if it was
    loaded, so a simulation never imports it (and if it was not loaded, none was raised)."""
    from tswm_common.files import EditedModuleError
    from tswm_runtime.model.scenes import SceneReferenceError

    kinds = [EditedModuleError, FileNotFoundError, UsageError, SceneReferenceError]
    for module, name in (("derivation.scene", "SceneError"), ("derivation.latex", "TexUnavailable")):
        if module in sys.modules:
            kinds.append(getattr(sys.modules[module], name))
    return tuple(kinds)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)   # to rerun the command (startup.warmup)
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
        print(f"tswm {args.command}: error: {printable(error, MAX_MESSAGE)}", file=sys.stderr)
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
    where = f"{printable(name, 160)}: " if name else ""
    print(f"tswm {args.command}: error: {where}{error.strerror or error} (check -o and the paths given)",
          file=sys.stderr)
    return 2


def command() -> None:
    """The ``tswm`` program: ``main`` on the command line, then the process ends at once with its
    status (``exit_now``)."""
    exit_now(main())


def exit_now(status: int) -> None:
    """End the process with ``status`` once stdout, stderr and the log handlers are flushed,
    without the interpreter's teardown: numba's and llvmlite's finalizers then free every
    loaded kernel's LLVM module one by one, 0.30-0.36 s of CPU after a warm one-case sweep had
    written its files. Every file tswm writes is complete (and closed) before ``main`` returns."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):   # a closed or vanished stream: nothing left to lose
            pass
    os._exit(status)


if __name__ == "__main__":
    command()
