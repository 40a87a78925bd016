"""Runtime leaves: provenance (tswm's version, the machine and versions) of results; words (counts and
differences in printed sentences). Imports nothing of tswm."""
