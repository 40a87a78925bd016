"""What derivation/ and tswm_runtime/ both need and neither owns: atomic file writes and the
units of scene values. Standard library only; imports neither package."""
