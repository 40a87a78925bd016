"""``tswm sweep``: a scene over a grid or random samples of its free parameters, in chunks
(argument parsing here; the work is imported when the command runs)."""
from __future__ import annotations

import argparse
import logging
import math
import shlex
import sys

from tswm_common.text import printable
from tswm_runtime.common.words import plural
from tswm_runtime.sweeps import CHAIN_CHUNK, DEFAULT_CHUNK, DEFAULT_WAIT_FOR_WORKERS
from tswm_runtime.cli.common import (MAX_MESSAGE, UsageError, add_setting_options, chain_inputs, output_directory,
                                     prepare_kernels, run_method, setting_error, setting_overrides)

SWEEP_SETTINGS = ("t_end", "rtol", "atol", "method", "max_steps", "max_events")


CONNECT_TIMEOUT_S = 10


class ClusterUnreachable(RuntimeError):
    """No dask scheduler answers at the given address (exit 1: the run failed, the input may be right)."""


def _notice(text: str) -> None:
    print(f"tswm sweep: {text}", file=sys.stderr, flush=True)


def _client(address: str):
    """(dask Client, LocalCluster or None) for --scheduler ADDRESS ('local': a cluster in this process)."""
    from distributed import Client, LocalCluster

    _quiet_dask()
    if address == "local":
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None)
        return Client(cluster), cluster
    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S), None
    except ValueError as error:
        raise UsageError(f"--scheduler {address!r}: {error}") from None
    except OSError as error:   # TimeoutError and refused connections
        raise ClusterUnreachable(f"no dask scheduler answers at {address} within {CONNECT_TIMEOUT_S} s "
                                 f"({type(error).__name__}: {error})") from None


def _quiet_dask() -> None:
    """Silence distributed's loggers: a client that lost its scheduler logs reconnect tracebacks
    that say no more than the command's own message about the cluster."""
    for name in [n for n in logging.root.manager.loggerDict if n.split(".")[0] == "distributed"]:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _wait_seconds(text: str) -> float:
    value = float(text)
    if math.isnan(value) or value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected seconds >= 0 (or inf)")
    return value


def run(args: argparse.Namespace) -> int:
    try:
        return _run(args)
    except ClusterUnreachable as error:
        print(f"tswm sweep: cluster problem: {error}", file=sys.stderr)
        return 1


def _run_chain(args: argparse.Namespace) -> int:
    """A chain scene: its sizing table over --grid NAME=... of its values and voltage, one module for all
    cases (tswm_runtime/sweeps/chain.py)."""
    from tswm_runtime.jit import coldstart

    coldstart.announce(("integrate", "chain", "chain-batch"))   # one message before any of them compiles
    from tswm_runtime.simulation.simulate import METHODS, SimulationInputError
    from tswm_runtime.sweeps.chain import ChainSweepError, parse_grid, sizing
    from tswm_runtime.sweeps.sweep import SweepInputError, SweepInterrupted

    if args.samples is not None or args.range or args.scheduler:
        raise UsageError("--samples/--range/--scheduler: a chain sweep takes --grid only")
    module, overrides, method = chain_inputs(args, SWEEP_SETTINGS)
    overrides = {k: v for k, v in overrides.items() if v is not None}
    try:
        grid = parse_grid(args.grid, module)
        outcome = sizing(module, grid, {**overrides, "method": METHODS[method]}, output=args.output,
                         chunk_size=CHAIN_CHUNK if args.chunk_size is None else args.chunk_size,
                         progress=not args.no_progress, prune=args.prune, notice=_notice)
    except (ChainSweepError, SweepInputError) as error:
        raise UsageError(str(error)) from None
    except SimulationInputError as error:
        raise setting_error(error, overrides) from None
    except SweepInterrupted as stop:
        print(f"tswm sweep: {stop}", file=sys.stderr)
        return 1
    for warning in outcome.warnings:
        _notice(warning)
    table = outcome.table
    print(f"chain {module.SCENE}: sizing table, {plural(len(table), 'case')}")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.6g}"))
    counts = table["status"].value_counts()
    print("  status: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if outcome.csv is not None:
        print(f"  wrote {outcome.csv} (and .parquet, .json; chunks in {args.output}/chunks)")
    return 0


def _run(args: argparse.Namespace) -> int:
    output_directory(args.output)
    from tswm_runtime.model.scenes import is_chain

    if is_chain(args.scene):
        return _run_chain(args)
    args.chunk_size = DEFAULT_CHUNK if args.chunk_size is None else args.chunk_size
    spec, cold = prepare_kernels(args.scene, ("integrate", "batch"))
    from tswm_runtime.model.scenes import load_model
    from tswm_runtime.simulation.simulate import SimulationInputError
    from tswm_runtime.startup import warmup
    from tswm_runtime.sweeps.sweep import SweepClusterLost, SweepInputError, SweepInterrupted, sweep, sweep_cases

    module = load_model(spec)
    overrides = setting_overrides(args, SWEEP_SETTINGS)
    try:
        P = sweep_cases(module, args.grid, samples=args.samples, ranges=args.range, seed=args.seed,
                        chunk_size=args.chunk_size, large=args.large)
        if cold is not None:
            method = run_method(args, module)
            if not warmup.interpreting_is_quicker(cold, module, P, overrides, method):
                return warmup.rerun_compiled(args.argv)
            warmup.begin(cold, method)
        client, cluster = _client(args.scheduler) if args.scheduler else (None, None)
        try:
            outcome = sweep(module, P, overrides, output=args.output, chunk_size=args.chunk_size,
                            client=client, progress=not args.no_progress, prune=args.prune,
                            wait_for_workers=args.wait_for_workers, notice=_notice)
        except SweepInterrupted as stop:
            print(f"tswm sweep: {stop}", file=sys.stderr)
            return 1
        except SweepClusterLost as lost:
            print(f"tswm sweep: cluster problem: {lost}\n  resume with: tswm {shlex.join(args.argv)}",
                  file=sys.stderr)
            return 1
        except warmup.PYTHON_ONLY_ERRORS as error:
            if cold is None or isinstance(error, (SweepInputError, SimulationInputError)):
                raise
            return warmup.rerun_compiled(args.argv, error)
        finally:
            if client is not None:
                client.close(timeout=5)
            if cluster is not None:
                cluster.close()
    except SweepInputError as error:
        raise UsageError(str(error)) from None
    except SimulationInputError as error:
        raise setting_error(error, overrides) from None
    for warning in outcome.warnings:
        print(f"tswm sweep: warning: {printable(warning, MAX_MESSAGE)}", file=sys.stderr)
    n = outcome.rows.num_rows
    print(f"scene {module.SCENE}: {plural(n, 'case')} in {outcome.seconds:.3g} s "
          f"({n / outcome.seconds if outcome.seconds else 0:.4g} cases/s incl. load and writing); "
          f"chunks computed {len(outcome.computed)} (of them {len(outcome.rejected)} rejected on disk), "
          f"reused {len(outcome.skipped)}")
    print("  status: " + ", ".join(f"{k} {v}" for k, v in _counts(outcome.rows.column("status"))))
    print("  regime codes (T tractive, I inverse-tractive, S stick, A/B backward, F phi = 0, G free flight): "
          + ", ".join(f"{k or '-'} {v}" for k, v in _counts(outcome.rows.column("regimes"))[:8]))
    if outcome.parquet:
        print(f"  wrote {outcome.parquet}\n  wrote {outcome.csv}\n"
              f"  wrote {outcome.parquet.with_name(f'{module.SCENE}-sweep.json')}")
    return 0


def _counts(column) -> list[tuple[str, int]]:
    """(value, how many rows hold it) of a text column, most frequent first (ties in order of appearance)."""
    import pyarrow.compute

    counts = pyarrow.compute.value_counts(column)
    pairs = zip(counts.field("values").to_pylist(), counts.field("counts").to_pylist())
    return sorted(pairs, key=lambda pair: -pair[1])


def add_parser(sub) -> None:
    sweep = sub.add_parser(
        "sweep", help="run a scene over a grid or random samples of its free parameters, in parallel",
        description="Run a scene over a grid (--grid) or seeded random samples (--samples, --range) of "
                    "its free parameters on all cores; one row per case (parameters, status, S1/S2 "
                    "maxima, KD1/KD2, final state, regime code, counts; units in the column names) in "
                    "DIR/SCENE-sweep.parquet and .csv. Work is done in chunks written to DIR/chunks/, each holding its key "
                    "(model, runtime, settings, rows); a rerun reuses only chunks that prove they hold "
                    "the asked rows and recomputes others with a warning. Exit status: 0 done, 1 "
                    "interrupted or the cluster failed (complete chunks are kept: rerun to resume), 2 bad "
                    "input. With --scheduler the model's source travels with the work and every worker is "
                    "checked first (docs/cluster.md).")
    sweep.add_argument("scene", help="a shipped scene name, a scene file (.toml) or a generated module's .py path")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=START:STOP:COUNT",
                       help="COUNT values from START to STOP (both included), or NAME=VALUE; numbers in SI or "
                            "with a unit (F2='-15 kN:-5 kN:11'); repeatable: all combinations")
    sweep.add_argument("--samples", type=int, metavar="N", help="N random cases (with --range)")
    sweep.add_argument("--range", action="append", default=[], metavar="NAME=LO:HI",
                       help="with --samples: NAME uniform in [LO, HI) (numbers in SI or with a unit); repeatable")
    sweep.add_argument("--seed", type=int, default=0, help="random seed for --samples (default 0)")
    sweep.add_argument("-o", "--output", metavar="DIR", help="write DIR/chunks/, DIR/SCENE-sweep.parquet, "
                       ".csv and .json (without -o: print the summary only, no resume)")
    sweep.add_argument("--chunk-size", type=int, metavar="N",
                       help=f"cases per chunk (default {DEFAULT_CHUNK}; a chain scene's {CHAIN_CHUNK})")
    sweep.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the chunks on a dask.distributed scheduler at ADDRESS; 'local' starts a "
                            "LocalCluster in this process")
    sweep.add_argument("--wait-for-workers", type=_wait_seconds, default=DEFAULT_WAIT_FOR_WORKERS, metavar="SECONDS",
                       help="with --scheduler: give up (exit 1) when the cluster has had no worker for SECONDS "
                            f"(default {DEFAULT_WAIT_FOR_WORKERS:g}; inf waits for ever); a status line says so every 10 s")
    add_setting_options(sweep, SWEEP_SETTINGS)
    sweep.add_argument("--large", action="store_true",
                       help="allow a sweep of more than 10^6 cases (its size is stated when refused)")
    sweep.add_argument("--prune", action="store_true",
                       help="delete files in DIR/chunks/ that belong to no chunk of this sweep (stale: another "
                            "model, runtime, setting or grid); without it they are only reported")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")
    sweep.set_defaults(run=run)
