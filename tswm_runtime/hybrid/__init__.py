"""The hybrid mode machine over the generated-module contract, and the parallel batch of runs."""
