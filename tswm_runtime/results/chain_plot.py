"""The figure of a chain run: the last body's travel and body 0's speed, then one panel per stage with
its forces on its input and output bodies and its normal force over t (a stage with a clearance also its
gap); the trip marked.

Takes plain arrays (the sliding phases' samples, NaN rows between phases), so it needs nothing of the
simulation; matplotlib's object API with the Agg canvas, as plot.py.
"""
from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from tswm_common.files import write_atomic

DPI = 150
FORCES = ("on input", "on output", "normal")


def plot_stages(path: str | Path, title: str, t: np.ndarray, travel: np.ndarray, speed: np.ndarray,
                forces: np.ndarray, stages: list[tuple[str, str, str]], t_trip: float | None = None,
                gap: tuple[int, np.ndarray, np.ndarray] | None = None) -> Path:
    """Write the figure to ``path`` (.png); ``forces`` has 3 columns per stage, ``stages`` gives each stage's
    label and the units of its input and output forces; ``gap``: (stage index, t, its normal gap in m), drawn
    on a second axis of that stage's panel."""
    figure = Figure(figsize=(8.0, 2.2 * (len(stages) + 1)), dpi=DPI, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(len(stages) + 1, 1, sharex=True, squeeze=False)[:, 0]
    axes[0].plot(t, travel, color="tab:blue", label="last body's travel")
    axes[0].set_ylabel("travel")
    twin = axes[0].twinx()
    twin.plot(t, speed, color="tab:gray", lw=0.8, label="body 0's speed")
    twin.set_ylabel("v0")
    axes[0].set_title(title, fontsize=9)
    for k, (label, unit_in, unit_out) in enumerate(stages):
        ax = axes[k + 1]
        for j, (name, unit) in enumerate(zip(FORCES, (unit_in, unit_out, "N"))):
            ax.plot(t, forces[:, 3 * k + j], lw=1.0, label=f"{name} [{unit}]")
        ax.set_ylabel(label)
        ax.legend(fontsize=7, loc="best")
        if gap is not None and gap[0] == k:
            right = ax.twinx()
            right.plot(gap[1], gap[2], color="tab:purple", lw=0.8, ls=":", label="gap [m]")
            right.set_ylabel("gap [m]")
            right.legend(fontsize=7, loc="lower right")
    for ax in axes:
        if t_trip is not None and math.isfinite(t_trip):
            ax.axvline(t_trip, color="tab:red", lw=0.8, ls="--")
    axes[-1].set_xlabel("t [s]")
    data = io.BytesIO()
    figure.savefig(data, format="png")
    return write_atomic(Path(path), data.getvalue())
