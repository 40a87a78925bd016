"""Independent references, written by hand and never derived or generated: the paper gear's
force balance (``paper_gear``), a high-accuracy quadrature of it (``quadrature``), its dense
sampling (``dense``: the quadrature's events, DOP853 between them), its stall after a load step
by DOP853 (``runup_stall``) and the closed-form stall of a constant drive against a spring
(``spring_stall``). Imports nothing of tswm outside this room, so a comparison with them is a
comparison with something else."""
