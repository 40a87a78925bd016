"""Many runs: grids and samples of free parameters on the batch kernel, in verified, resumable
chunks, locally or on dask (``sweep``). Imports simulation/ for its settings and checks."""

DEFAULT_CHUNK = 512   # cases per chunk (--chunk-size)
DEFAULT_WAIT_FOR_WORKERS = 60.0   # seconds a cluster may have no worker before a sweep gives up
