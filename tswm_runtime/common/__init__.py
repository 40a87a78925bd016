"""Shared leaves: atomic file writes, units, provenance (versions) of results."""
