"""Calibration against measured peaks or time histories (``fit``): the measured file, the model
as residuals on the sweep's batch, multi-start least squares and statistics, the report.
Imports sweeps/ and simulation/."""
