"""Measure numba's compile times with an empty cache and store them for the cold-start message.

Writes tswm_runtime/jit/compile_times.json (read by ``tswm_runtime.jit.coldstart``): seconds
for each group of kernels and each shipped model, each measured in a fresh process with a
fresh NUMBA_CACHE_DIR:

    segment       import hybrid.segments (the segment kernel run_segment, part of "integrate";
                  ``tswm paper`` compiles it in its second process), everything cold
    integrate     import hybrid.entry, hybrid.rows and hybrid.segments (compiles integrate_hybrid, run_segment,
                  integrate_at, fill_rows, states_at and no_jacobian), everything cold
    batch         import hybrid.batch (run_batch, parallel) with the integrate group cached
    chain         import chains.answers (run_chain_at, a drive train's whole run, and answer_run, its answers)
                  with the integrate group cached
    chain-batch   import chains.batch (run_chain_batch, parallel) with the chain group cached
    METHOD        segment.attempt_function(METHOD): the step of dopri5, rosenbrock23, rodas4, with the
                  integrate group cached
    model:SCENE   load_module(SCENE) and a first simulate(points=2) with the kernels cached

Run on the machine the numbers should describe (here: 2 cores) with nothing else busy:
``.venv/bin/python tools/measure_compile_times.py [--scenes paper,...]``; the load average
before and after is stored with the numbers.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "tswm_runtime" / "jit" / "compile_times.json"


def timed(code: str, cache_dir: str, setup: str = "") -> float:
    """Seconds ``code`` takes in a fresh interpreter (after ``setup``) with NUMBA_CACHE_DIR=cache_dir."""
    prog = f"{setup}\nimport time\nt0 = time.perf_counter()\n{code}\nprint(time.perf_counter() - t0)"
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    run = subprocess.run([sys.executable, "-c", prog], capture_output=True, text=True, env=env, cwd=ROOT)
    if run.returncode:
        raise RuntimeError(run.stderr)
    return float(run.stdout.split()[-1])


def main() -> int:
    import numba

    from derivation.scene import shipped_scenes   # single-stage scenes; chains compile through the chain kernel

    from tswm_runtime.common import provenance

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    shipped = sorted(shipped_scenes())
    parser.add_argument("--scenes", default=",".join(shipped), help="comma-separated scene names")
    args = parser.parse_args()
    load_before = os.getloadavg()
    seconds = {}
    with tempfile.TemporaryDirectory() as cache:   # its own cache: "integrate" below includes it
        seconds["segment"] = timed("import tswm_runtime.hybrid.segments", cache, "import numpy, numba")
        print(f"segment {seconds['segment']:.1f} s", flush=True)
    with tempfile.TemporaryDirectory() as cache:
        seconds["integrate"] = timed("import tswm_runtime.hybrid.entry, tswm_runtime.hybrid.rows, "
                                     "tswm_runtime.hybrid.segments", cache,
                                     "import numpy, numba")
        print(f"integrate {seconds['integrate']:.1f} s", flush=True)
        seconds["batch"] = timed("import tswm_runtime.hybrid.batch", cache,
                                 "import tswm_runtime.hybrid.entry, tswm_runtime.hybrid.rows")
        print(f"batch {seconds['batch']:.1f} s", flush=True)
        seconds["chain"] = timed("import tswm_runtime.chains.answers", cache,
                                 "import tswm_runtime.hybrid.entry, tswm_runtime.hybrid.rows, tswm_runtime.hybrid.segments")
        print(f"chain {seconds['chain']:.1f} s", flush=True)
        seconds["chain-batch"] = timed("import tswm_runtime.chains.batch", cache, "import tswm_runtime.chains.answers")
        print(f"chain-batch {seconds['chain-batch']:.1f} s", flush=True)
        for name, code in (("dopri5", "DOPRI5"), ("rosenbrock23", "ROSENBROCK23"),
                           ("rodas4", "RODAS4")):  # simulate.METHODS
            seconds[name] = timed(f"segment.attempt_function(segment.{code})", cache,
                                  "import tswm_runtime.hybrid.machine\nfrom tswm_runtime.integration import segment")
            print(f"{name} {seconds[name]:.1f} s", flush=True)
        for scene in args.scenes.split(","):
            seconds[f"model:{scene}"] = timed(
                f"simulate(load_module({scene!r}), points=2)", cache,
                "from tswm_runtime.simulation.simulate import simulate\n"
                "from tswm_runtime.model.contract import load_module")
            print(f"model {scene} {seconds[f'model:{scene}']:.1f} s", flush=True)
    info = {**provenance.machine(), "numba": numba.__version__, "python": sys.version.split()[0],
            "loadavg_before": load_before, "loadavg_after": os.getloadavg(),
            "date": time.strftime("%Y-%m-%d %H:%M"), "command": "python tools/measure_compile_times.py"}
    OUT.write_text(json.dumps({"seconds": {k: round(v, 1) for k, v in seconds.items()}, "measured": info},
                              indent=2) + "\n")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
