"""Independent references, written by hand and never derived or generated: the paper gear's
force balance (``paper_gear``), a high-accuracy quadrature of it (``quadrature``) and its dense
sampling (``dense``: the quadrature's events, DOP853 between them). Imports
nothing of tswm, so a comparison with them is a comparison with something else."""
