"""tswm runtime: integrators, event location and the hybrid mode machine (numba, no sympy).

The Python API (``tswm_runtime.api``, docs/api.md) is exported here and loaded on first use::

    import tswm_runtime as tswm
    result = tswm.simulate("paper", {"F2": "-5 kN"})

so ``import tswm_runtime`` loads neither numba's kernels nor SymPy.
"""
from tswm_runtime.common.provenance import TSWM_VERSION as __version__

API = ("simulate", "sweep", "fit", "derive")


def __getattr__(name: str):
    if name in API:
        from tswm_runtime import api

        return getattr(api, name)
    raise AttributeError(f"module 'tswm_runtime' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *API])
