"""Applications: simulate, sweep, the benchmark, the paper report and their references."""
