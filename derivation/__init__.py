"""Symbolic derivation of wedge-mechanism models, scene files and code export."""
