"""The figure of a simulation: a1, S1, S2 against t with the mode bands and the events.

Uses matplotlib's object API with the Agg canvas (no pyplot, no display, no global state).
"""
from __future__ import annotations

import io
import math
from types import ModuleType

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from tswm_runtime.results.result import Result

DPI = 200
REGIME_COLOURS = {
    "tractive": "tab:blue", "inverse-tractive": "tab:orange", "stick": "tab:gray",
    "backward on flank a": "tab:green", "backward on flank b": "tab:red",
    "free flight": "white",
}
FREE_HATCH = "////"   # free flight (a clearance open) is hatched, not tinted
SPARE_COLOURS = ("tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
PANELS = (("a1", "a1 [m/s^2]", None), ("S1", "S1 [N]", ("S1_max", "t_S1_max")),
          ("S2", "S2 [N]", ("S2_max", "t_S2_max")))


def force_text(value: float) -> str:
    """A force for a label, never in exponent notation: up to 4 significant digits in N below
    10 kN, else in kN (-15000 -> '-15 kN', -16932.7 -> '-16.93 kN', 727.63 -> '727.6 N')."""
    if not math.isfinite(value):
        return f"{value} N"
    unit, scaled = ("kN", value / 1000.0) if abs(value) >= 1e4 else ("N", value)
    if scaled == 0:
        return f"0 {unit}"
    decimals = max(0, 3 - math.floor(math.log10(abs(scaled))))
    text = f"{round(scaled, decimals):.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return f"{text} {unit}"


def regime_colours(regimes) -> dict[str, str]:
    """A colour for each regime: fixed ones for the known regimes, spares for the others."""
    colours, spare = {}, iter(SPARE_COLOURS * 4)
    for regime in regimes:
        if regime not in colours:
            colours[regime] = REGIME_COLOURS.get(regime) or next(spare, "tab:gray")
    return colours


def title(result: Result, module: ModuleType) -> str:
    """Scene, free parameters with units and, for a failed run, its status."""
    units = dict(zip(module.PARAM_NAMES, module.PARAM_UNITS))
    params = ", ".join(f"{k} = {v:g} {units.get(k, '')}".rstrip() for k, v in result.params.items())
    text = f"{result.scene}: {params or 'no free parameters'}"
    if not result.success:
        text += f"\nstatus {result.status} at t = {result.t_stop:.6g} s"
    return text


def figure(result: Result, module: ModuleType, *, heading: str | None = None,
           event_labels: bool = False) -> Figure:
    """Stacked panels sharing t: a1, S1, S2 (and the gap with a clearance, the stem's travel with
    lost motion); phases shaded by regime (free flight hatched), events as dashed vertical
    lines, impacts as red lines with their energy loss, the maxima of S1 and S2 marked. ``heading`` replaces the title;
    ``event_labels`` writes each event's guard and time beside its line in the top panel."""
    panels = (PANELS + ((("gap", "gap [mm]", None),) if result.gap.size else ())
              + ((("x3", "stem travel x3 [mm]", None),) if result.x3.size else ()))
    fig = Figure(figsize=(8.0, 2.7 * len(panels)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(panels), 1, sharex=True)
    colours = regime_colours(ph.regime for ph in result.phases)
    for ax, (name, label, peak) in zip(axes, panels):
        for ph in result.phases:
            free = ph.regime == "free flight"
            ax.axvspan(ph.t_start, ph.t_end, facecolor=colours[ph.regime], alpha=0.15 if not free else 0.4,
                       hatch=FREE_HATCH if free else None, edgecolor="tab:gray" if free else None, linewidth=0)
        for e in result.events:
            if e.jump is None:
                ax.axvline(e.t, color="black", linestyle="--", linewidth=0.6, alpha=0.6)
            else:
                ax.axvline(e.t, color="tab:red", linestyle="-", linewidth=0.8, alpha=0.7)
        values = getattr(result, name) * (1e3 if name in ("gap", "x3") else 1.0)
        ax.plot(result.t, values, color="black", linewidth=1.0)
        if peak is not None and result.t.size:
            value, at = getattr(result, peak[0]), getattr(result, peak[1])
            ax.plot([at], [value], marker="o", color="tab:red", markersize=5, linestyle="none")
            ax.annotate(f"{name} = {force_text(value)} at t = {at:.4g} s", (at, value),
                        textcoords="offset points", xytext=(6, 4), fontsize=8, color="tab:red")
        ax.set_ylabel(label)
        ax.grid(True, linewidth=0.3, alpha=0.5)
    if event_labels:
        for e in result.events[:12]:
            axes[0].annotate(f"{e.guard}: t = {e.t:.4g} s", (e.t, 1.0), xycoords=("data", "axes fraction"),
                             xytext=(3, -3), textcoords="offset points", rotation=90, va="top",
                             fontsize=7)
    axes[-1].set_xlabel("t [s]")
    handles = [Patch(facecolor=c, alpha=0.3, label=r, hatch=FREE_HATCH if r == "free flight" else None,
                     edgecolor="tab:gray" if r == "free flight" else None) for r, c in colours.items()]
    if result.impacts:
        handles.append(Line2D([], [], color="tab:red", linewidth=0.8,
                              label=f"impact ({len(result.impacts)}, {result.impact_energy:.3g} J lost)"))
    if len(result.events) > len(result.impacts):
        handles.append(Line2D([], [], color="black", linestyle="--", linewidth=0.6, label="event"))
    handles.append(Line2D([], [], color="tab:red", marker="o", linestyle="none", label="largest |S|"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4), fontsize=8)
    fig.suptitle(heading or title(result, module), fontsize=10)
    return fig


def png_bytes(result: Result, module: ModuleType, dpi: int = DPI, **options) -> bytes:
    """The figure rendered as PNG into memory (for an atomic write); ``options`` go to ``figure``."""
    buffer = io.BytesIO()
    figure(result, module, **options).savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()
