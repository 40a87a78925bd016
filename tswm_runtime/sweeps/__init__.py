"""Many runs: grids and samples of free parameters on the batch kernel, in verified, resumable
chunks, locally or on dask (``sweep``). Imports simulation/ for its settings and checks."""
