"""The background compile on a cold numba cache (``warmup``): a detached process that runs
simulate and the sweep's batch once so their kernels land in numba's cache. It sits above
simulation/ and sweeps/ because it runs them; only the CLI and the bench import it."""
