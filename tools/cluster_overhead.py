"""Measure what running a sweep's chunks on dask costs per chunk (docs/cluster.md).

Starts a local ``dask scheduler`` and WORKERS ``dask worker`` processes of one thread each
(no nanny), runs one warm-up sweep on the cluster (the workers load the kernels), then the
same sweep REPEAT times in this process (numba on all cores) and on the cluster, and prints
the best time of each and (cluster - local) / chunks.

    .venv/bin/python tools/cluster_overhead.py --cases 20000 --chunk-size 512
"""
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--cases", type=int, default=20000)
    parser.add_argument("--chunk-size", type=int, default=512)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from distributed import Client

    from tswm_runtime.model.contract import load_module
    from tswm_runtime.sweeps.sweep import sample_cases, sweep

    module = load_module(args.scene)
    bounds = sorted((0.5 * module.PARAM_DEFAULTS[-1], 1.5 * module.PARAM_DEFAULTS[-1]))
    P = sample_cases(module, args.cases, {module.PARAM_NAMES[-1]: tuple(bounds)}, 0)   # the last parameter +-50 %
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    processes = []
    with tempfile.TemporaryDirectory() as scratch:
        info = Path(scratch) / "scheduler.json"
        try:
            processes.append(subprocess.Popen([str(bin_dir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                               "--no-dashboard", "--scheduler-file", str(info)], env=env, cwd=scratch,
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            while not (info.exists() and info.stat().st_size):
                time.sleep(0.1)
            time.sleep(0.3)
            address = json.loads(info.read_text())["address"]
            for i in range(args.workers):
                processes.append(subprocess.Popen([str(bin_dir / "dask"), "worker", address, "--nthreads", "1",
                                                   "--no-nanny", "--no-dashboard", "--name", f"w{i}"], env=env,
                                                  cwd=scratch, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            with Client(address, timeout=30) as client:
                client.wait_for_workers(args.workers, timeout=120)
                sweep(module, P[:args.workers * 4], chunk_size=4, client=client)   # workers load the kernels
                sweep(module, P[:8], chunk_size=4)
                local, remote = [], []
                for _ in range(args.repeat):
                    start = time.perf_counter()
                    reference = sweep(module, P, chunk_size=args.chunk_size).table
                    local.append(time.perf_counter() - start)
                    start = time.perf_counter()
                    table = sweep(module, P, chunk_size=args.chunk_size, client=client).table
                    remote.append(time.perf_counter() - start)
                    assert table.equals(reference), "the cluster's table differs from the local one"
        finally:
            for process in processes:
                process.kill()
                process.wait()
    chunks = -(-args.cases // args.chunk_size)
    print(f"{args.scene}: {args.cases} cases in {chunks} chunks of {args.chunk_size}; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"  local ({os.cpu_count()} numba threads): best {min(local):.3f} s of {args.repeat}")
    print(f"  cluster ({args.workers} workers x 1 thread): best {min(remote):.3f} s of {args.repeat}")
    print(f"  overhead per chunk: {(min(remote) - min(local)) / chunks * 1e3:.1f} ms; tables identical")


if __name__ == "__main__":
    main()
