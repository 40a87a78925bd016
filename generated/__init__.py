"""Emitted model modules, one per shipped scene. Written by `tswm generate`; never edit by hand."""
