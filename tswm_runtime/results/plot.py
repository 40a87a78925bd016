"""The figure of a simulation: a1, S1, S2 against t with the mode bands and the events.

Uses matplotlib's object API with the Agg canvas (no pyplot, no display, no global state).
"""
from __future__ import annotations

import io
import math
import textwrap
from types import ModuleType

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.text import Text

from tswm_runtime.common.words import plural
from tswm_runtime.results.result import Result

DPI = 200
REGIME_COLOURS = {
    "tractive": "tab:blue", "inverse-tractive": "tab:orange", "stick": "tab:gray",
    "backward on flank a": "tab:green", "backward on flank b": "tab:red",
    "free flight": "white",
}
FREE_HATCH = "////"   # free flight (a clearance open) is hatched, not tinted
SPARE_COLOURS = ("tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
ZOOM_BELOW = 0.02       # a free-flight phase shorter than this fraction of the run gets the zoom panel
ZOOM_SPAN = 0.2         # ... when all of them lie within this fraction of it
EVENT_LABEL_GAP = 9.0   # points between two event labels above the top panel
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


def fit_text(text: Text, width: float) -> None:
    """Wrap ``text`` at spaces until its drawn width is at most ``width`` display pixels."""
    renderer = text.get_figure().canvas.get_renderer()
    lines = text.get_text().split("\n")
    for columns in range(max(len(line) for line in lines), 8, -2):
        if text.get_window_extent(renderer).width <= width:
            return
        text.set_text("\n".join(textwrap.fill(line, columns, break_long_words=False) for line in lines))


def zoom_window(result: Result) -> tuple[float, float] | None:
    """The time span of the short phases (free flight under ZOOM_BELOW of the run, impacts), padded
    by half its width, when it covers under ZOOM_SPAN of the run; else None (nothing to zoom)."""
    span = result.t_stop
    short = [(ph.t_start, ph.t_end) for ph in result.phases
             if ph.regime == "free flight" and ph.t_end - ph.t_start < ZOOM_BELOW * span]
    short += [(e.t, e.t) for e in result.impacts]
    if not short or span <= 0:
        return None
    lo, hi = min(a for a, _ in short), max(b for _, b in short)
    pad = max(0.5 * (hi - lo), 1e-3 * span)
    return (max(0.0, lo - pad), min(span, hi + pad)) if hi - lo < ZOOM_SPAN * span else None


def _shade(ax, result: Result, colours: dict) -> None:
    """The phases shaded by regime (free flight hatched), events dashed, impacts red."""
    for ph in result.phases:
        free = ph.regime == "free flight"
        ax.axvspan(ph.t_start, ph.t_end, facecolor=colours[ph.regime], alpha=0.15 if not free else 0.4,
                   hatch=FREE_HATCH if free else None, edgecolor="tab:gray" if free else None, linewidth=0)
    for e in result.events:
        if e.jump is None:
            ax.axvline(e.t, color="black", linestyle="--", linewidth=0.6, alpha=0.6)
        else:
            ax.axvline(e.t, color="tab:red", linestyle="-", linewidth=0.8, alpha=0.7)


def _event_labels(ax, result: Result) -> None:
    """Each event's guard and time above the top panel, outside its frame; an event closer to the
    previous label than a line of text is left out (the full list is in the summary)."""
    last = -math.inf
    for e in result.events:
        x = ax.transData.transform((e.t, 0.0))[0]
        if x - last < EVENT_LABEL_GAP * ax.get_figure().dpi / 72:
            continue
        ax.annotate(f"{e.guard}: t = {e.t:.4g} s", (e.t, 1.0), xycoords=("data", "axes fraction"),
                    xytext=(0, 3), textcoords="offset points", rotation=90, ha="center", va="bottom", fontsize=7)
        last = x


def figure(result: Result, module: ModuleType, *, heading: str | None = None,
           event_labels: bool = False) -> Figure:
    """Stacked panels sharing t: a1, S1, S2 (and the gap with a clearance, the stem's travel with
    lost motion); phases shaded by regime (free flight hatched), events as dashed vertical
    lines, impacts as red lines with their energy loss, the maxima of S1 and S2 marked and named
    in a legend placed off the curve. Short impact phases get a zoom panel of the last quantity
    at the bottom. ``heading`` replaces the title (wrapped to the figure's width);
    ``event_labels`` writes each event's guard and time above the top panel."""
    panels = (PANELS + ((("gap", "gap [mm]", None),) if result.gap.size else ())
              + ((("x3", "stem travel x3 [mm]", None),) if result.x3.size else ()))
    zoom = zoom_window(result) if panels[-1][0] in ("gap", "x3") else None
    rows = len(panels) + (zoom is not None)
    fig = Figure(figsize=(8.0, 2.7 * rows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = list(fig.subplots(rows, 1))
    for ax in axes[1:len(panels)]:
        ax.sharex(axes[0])
    colours = regime_colours(ph.regime for ph in result.phases)
    for ax, (name, label, peak) in zip(axes, panels):
        _shade(ax, result, colours)
        values = getattr(result, name) * (1e3 if name in ("gap", "x3") else 1.0)
        ax.plot(result.t, values, color="black", linewidth=1.0)
        if peak is not None and result.t.size:
            value, at = getattr(result, peak[0]), getattr(result, peak[1])
            ax.plot([at], [value], marker="o", color="tab:red", markersize=5, linestyle="none",
                    label=f"{name} = {force_text(value)} at t = {at:.4g} s")
            ax.legend(loc="best", fontsize=8, framealpha=0.9)
        ax.set_ylabel(label)
        ax.grid(True, linewidth=0.3, alpha=0.5)
    for ax in axes[:len(panels) - 1]:
        ax.tick_params(labelbottom=False)
    axes[len(panels) - 1].set_xlabel("t [s]")
    if zoom is not None:
        name, label, _ = panels[-1]
        ax = axes[-1]
        _shade(ax, result, colours)
        inside = (result.t >= zoom[0]) & (result.t <= zoom[1])
        points = sorted([*zip(result.t[inside], getattr(result, name)[inside]),
                         *((e.t, e.state[name]) for e in result.events if name in e.state)])
        ax.plot([t for t, _ in points], [v * 1e3 for _, v in points], color="black", linewidth=1.0,
                marker=".", markersize=2)
        ax.set_xlim(*zoom)
        ax.set_ylabel(label)
        ax.set_xlabel(f"t [s], zoomed to {zoom[0]:.4g}-{zoom[1]:.4g} s (the short phases; dots: output points "
                      "and events)")
        ax.grid(True, linewidth=0.3, alpha=0.5)
    handles = [Patch(facecolor=c, alpha=0.3, label=r, hatch=FREE_HATCH if r == "free flight" else None,
                     edgecolor="tab:gray" if r == "free flight" else None) for r, c in colours.items()]
    if result.impacts:
        handles.append(Line2D([], [], color="tab:red", linewidth=0.8,
                              label=f"{plural(len(result.impacts), 'impact')}, {result.impact_energy:.3g} J lost"))
    if len(result.events) > len(result.impacts):
        handles.append(Line2D([], [], color="black", linestyle="--", linewidth=0.6, label="event"))
    handles.append(Line2D([], [], color="tab:red", marker="o", linestyle="none", label="largest |S|"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4), fontsize=8)
    fig.draw_without_rendering()
    if event_labels:
        _event_labels(axes[0], result)
    fit_text(fig.suptitle(heading or title(result, module), fontsize=10), 0.96 * fig.bbox.width)
    fig.draw_without_rendering()
    return fig


def png_bytes(result: Result, module: ModuleType, dpi: int = DPI, **options) -> bytes:
    """The figure rendered as PNG into memory (for an atomic write); ``options`` go to ``figure``."""
    buffer = io.BytesIO()
    figure(result, module, **options).savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()
