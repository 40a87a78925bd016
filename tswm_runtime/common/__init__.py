"""Runtime leaves: provenance (tswm's version, the machine and versions) of results. Imports nothing of tswm."""
