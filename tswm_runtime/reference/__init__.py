"""Independent references, written by hand and never derived or generated: the paper gear's
force balance (``paper_gear``) and a high-accuracy quadrature of it (``quadrature``). Imports
nothing of tswm, so a comparison with them is a comparison with something else."""
