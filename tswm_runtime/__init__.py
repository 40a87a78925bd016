"""tswm runtime: integrators, event location and the hybrid mode machine (numba, no sympy)."""
