"""How long schedules cost: `tswm generate` of a scene with an N-breakpoint schedule, cold, and
the events per second of a run that passes them (tswm_runtime/bench/generation.py, also part of
`tswm bench`).

    python tools/bench_schedules.py [--sizes 3 100 999] [--generate-timeout 600] [--root DIR]

``--root`` times another checkout (an older tswm).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tswm_runtime.bench import generation


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 100, 999])
    parser.add_argument("--generate-timeout", type=float, default=600.0)
    parser.add_argument("--root", type=Path, default=generation.ROOT, help="the checkout to time (default: this one)")
    parser.add_argument("--part", choices=("generate", "events", "both"), default="both")
    args = parser.parse_args(argv)
    if args.part != "events":
        generation.generate_runs(scenes=(), sizes=args.sizes, root=args.root, timeout=args.generate_timeout)
    if args.part != "generate":
        generation.event_runs(args.sizes)
    return 0


if __name__ == "__main__":
    sys.exit(main())
