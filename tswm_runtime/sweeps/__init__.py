"""Many runs: grids and samples of free parameters on the batch kernel, in verified, resumable
chunks, locally or on dask (``sweep``). Imports simulation/ for its settings and checks."""

DEFAULT_CHUNK = 16384   # cases per chunk (--chunk-size); 2048 cost 4-5 % more CPU on 20,000 cases (per-chunk table and file work)
DEFAULT_WAIT_FOR_WORKERS = 60.0   # seconds a cluster may have no worker before a sweep gives up
CHAIN_CHUNK = 256       # a chain scene's cases per chunk: a chain case costs milliseconds, a chunk of them about a second
