"""Integration: one step of each method, shared step-size control, dense output, event location,
the segment loop and the Painleve approach. Knows nothing of wedges."""
