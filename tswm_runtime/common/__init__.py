"""Runtime leaves: provenance (machine and versions) of results. Imports nothing of tswm."""
