"""tswm runtime: integrators, event location and the hybrid mode machine (numba, no sympy)."""
from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("tswm")
except _metadata.PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0.1.0+source"
