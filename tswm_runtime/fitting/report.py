"""The outputs of ``tswm fit``: fit-report.md, fit.json and the misfit plot (misfit.png)."""
from __future__ import annotations

import io
import json
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tswm_runtime.common.words import plural
from tswm_runtime.fitting.profile import TIGHTER

OPTIMUM_WIDTH = 1.5   # points, the optimum's vertical line

if TYPE_CHECKING:
    from tswm_runtime.fitting.fit import FitResult


def misfit_figure(res: FitResult):
    """The misfit plot: cost over one parameter (curve) or two (contour of log10 cost), the
    optimum, the starts' ends and the confidence band (one parameter) or the linearised joint
    confidence region (two), shaded; the legend, below the axes, says when a band is narrower
    than the optimum's line."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from tswm_runtime.results.plot import fit_text

    g = res.misfit
    fig = Figure(figsize=(7, 5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    names = g["names"]
    label = [f"{n} [{res.units[res.names.index(n)]}]".replace(" []", "") for n in names]
    ends = np.array([s.x for s in res.starts])
    if len(names) == 1:
        xs, cost = np.array(g["axes"][0]), np.array(g["cost"])
        ax.semilogy(xs, np.maximum(cost, 1e-300), "-", color="C0", label="cost 0.5 sum r^2")
        best = res.estimate[names[0]]
        ax.axvline(best, color="C3", linewidth=OPTIMUM_WIDTH, label=f"optimum {names[0]} = {best:.6g}")
        ax.plot(ends[:, 0], [max(s.cost, 1e-300) for s in res.starts], "kx", label="ends of the starts")
        ax.set_xlabel(label[0])
        ax.set_ylabel("cost (log scale)")
        _band(ax, f"{res.confidence:.0%} profile interval", *res.ci[names[0]], xs, "C3")
    else:
        xs, ys = (np.array(a) for a in g["axes"])
        cost = np.log10(np.maximum(np.array(g["cost"]), 1e-300))
        cs = ax.contourf(xs, ys, cost.T, levels=20, cmap="viridis")
        fig.colorbar(cs, ax=ax, label="log10 cost")
        ax.plot(ends[:, 0], ends[:, 1], "X", color="white", markeredgecolor="black", linestyle="none",
                label="ends of the starts")   # seen on the dark contour and in the white legend
        ax.plot([res.estimate[names[0]]], [res.estimate[names[1]]], "r*", ms=14, label="optimum")
        ax.set_xlabel(label[0])
        ax.set_ylabel(label[1])
        _region(ax, res, names)
    extra = f"; {', '.join(g['others_at_optimum'])} at the optimum" if g["others_at_optimum"] else ""
    heading = ax.set_title(f"tswm fit {res.scene}: misfit over the bounds{extra}", fontsize=10)
    fig.legend(fontsize=8, loc="outside lower center")
    fig.draw_without_rendering()
    fit_text(heading, ax.bbox.width)
    fig.draw_without_rendering()
    return fig


def _band(ax, name: str, lo: float, hi: float, xs: np.ndarray, colour: str) -> None:
    """An interval of the one parameter as a shaded band, named with its ends in the legend
    (enough digits to tell them apart)."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        ax.plot([], [], " ", label=f"no finite {name}")
        return
    text = f"{name} {_ends(lo, hi)}"
    ax.get_figure().draw_without_rendering()
    pixels = abs(ax.transData.transform((hi, 1.0))[0] - ax.transData.transform((lo, 1.0))[0])
    if pixels < OPTIMUM_WIDTH * ax.get_figure().dpi / 72:
        text += ", narrower than the optimum's line"
    ax.axvspan(max(lo, xs[0]), min(hi, xs[-1]), color=colour, alpha=0.25, linewidth=0, label=text)


def _ends(lo: float, hi: float) -> str:
    """'[lo, hi]' with enough significant digits (at least 4) to show the interval's width."""
    width, scale = hi - lo, max(abs(lo), abs(hi))
    digits = 4 if width <= 0 or scale == 0 else max(4, min(12, math.ceil(math.log10(scale / width)) + 2))
    return f"[{lo:.{digits}g}, {hi:.{digits}g}]"


def _region(ax, res: FitResult, names: list[str]) -> None:
    """The linearised joint confidence region of two parameters, an ellipse (p - p*)^T C^-1
    (p - p*) <= 2 F(2, dof) (C the covariance), shaded."""
    from matplotlib.patches import Polygon
    from scipy import stats

    k = [res.names.index(n) for n in names]
    cov = np.array(res.covariance)[np.ix_(k, k)]
    centre = np.array([res.estimate[n] for n in names])
    if res.dof <= 0 or not np.all(np.isfinite(cov)) or np.linalg.matrix_rank(cov) < 2:
        ax.plot([], [], " ", label=f"no finite {res.confidence:.0%} confidence region")
        return
    radius = math.sqrt(2 * stats.f.ppf(res.confidence, 2, res.dof))
    angle = np.linspace(0, 2 * math.pi, 121)
    points = centre + radius * (np.linalg.cholesky(cov) @ np.array([np.cos(angle), np.sin(angle)])).T
    text = f"{res.confidence:.0%} confidence region (linearised)"
    ax.get_figure().draw_without_rendering()
    pixels = np.ptp(ax.transData.transform(points), axis=0)
    if min(pixels) < 14 * ax.get_figure().dpi / 72:
        text += ", smaller than the optimum's marker"
    ax.add_patch(Polygon(points, closed=True, facecolor="C3", edgecolor="C3", alpha=0.35, label=text))


def misfit_png(res: FitResult) -> bytes:
    """The misfit plot (``misfit_figure``) as PNG bytes."""
    buffer = io.BytesIO()
    misfit_figure(res).savefig(buffer, format="png", dpi=120)
    return buffer.getvalue()


def profile_png(res: FitResult) -> bytes:
    """One panel per parameter: its profile (cost above the minimum, others re-optimised), the
    threshold (noise + numerical floor) and the numerical floor as lines, the interval shaded,
    the estimate and any edge (a mode-sequence change) marked."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(res.names)
    fig = Figure(figsize=(7, 2.6 + 2.4 * n))
    FigureCanvasAgg(fig)
    for j, (name, unit) in enumerate(zip(res.names, res.units)):
        p = res.profiles[name]
        ax = fig.add_subplot(n, 1, j + 1)
        xs, rise = np.array(p["values"]), np.array(p["cost"]) - p["cost_min"]
        floor, limit = p["numerical"]["floor"], p["threshold"] - p["cost_min"]
        bottom = max(min(floor, limit) / 10, 1e-300) if limit > 0 else 1e-300
        ax.semilogy(xs, np.maximum(rise, bottom), "o-", ms=3, color="C0", label="profile: cost - minimum")
        ax.axhline(max(limit, bottom), color="C3", ls="--", label=f"threshold {limit:.3g} ({p['confidence']:.0%})")
        ax.axhline(max(floor, bottom), color="C7", ls=":", label=f"numerical floor {floor:.3g}")
        lo, hi = (p["range"] if p["verdict"] == "not determined" else (p["lo"], p["hi"]))
        ax.axvspan(lo, hi, color="C3", alpha=0.15, label=f"{p['verdict']}: [{lo:.5g}, {hi:.5g}]")
        ax.axvline(res.estimate[name], color="k", lw=1, label=f"estimate {res.estimate[name]:.6g}")
        for end in (p["lower"], p["upper"]):
            if end and end["edge"]:
                ax.axvline(end["at"], color="C1", lw=2, label=f"edge (mode sequence changes) {end['at']:.5g}")
        ax.set_xlabel(f"{name} [{unit}]".replace(" []", ""))
        ax.set_ylabel("cost rise (log)")
        ax.legend(fontsize=7)
    fig.suptitle(f"tswm fit {res.scene}: profiles (other parameters re-optimised)", fontsize=10)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


def _md(text: str) -> str:
    """Escape what Markdown would read as markup (file names are user text)."""
    return re.sub(r"([\\`*_{}\[\]<>()#+!|])", r"\\\1", text)


def report_markdown(res: FitResult) -> str:
    f = res.to_dict()
    L = [f"# tswm fit: scene {res.scene}", ""]
    L.append(f"Measured: {_md(Path(res.measured['file']).name)} ({res.measured['form']}, "
             f"{plural(res.measured['cases'], 'case')}, {plural(res.measured['rows'], 'row')}; quantities "
             f"{', '.join(res.measured['quantities'])}, compared "
             f"as {res.measured['compared']}; known per case: {', '.join(res.measured['known']) or 'none'}).")
    L.append("")
    L.append(f"| parameter | estimate | verdict | {res.confidence:.0%} profile interval | linearised interval "
             "(std. error) | bounds |")
    L.append("| --- | --- | --- | --- | --- | --- |")
    for n, u in zip(res.names, res.units):
        p = res.profiles[n]
        ci = (f"none: any value in [{p['range'][0]:.6g}, {p['range'][1]:.6g}]" if p["verdict"] == "not determined"
              else f"[{p['lo']:.6g}, {p['hi']:.6g}]")
        if p["minimum_on_edge"]:
            ci += " (minimum on an edge)"
        lo, hi = res.ci_linear[n]
        lin = "none" if math.isnan(lo) else "unbounded" if not (math.isfinite(lo) and math.isfinite(hi)) \
            else f"[{lo:.6g}, {hi:.6g}]"
        L.append(f"| {n} [{u}] | {res.estimate[n]:.8g} | {p['verdict']} | {ci} | {lin} ({res.stderr[n]:.3g}) | "
                 f"[{res.bounds[n][0]:g}, {res.bounds[n][1]:g}] ({res.bound_source[n]}) |")
    L.append("")
    noise = (", ".join(f"{q} {v:g}" for q, v in res.noise.items()) + " (stated, SI)" if res.noise
             else "estimated from the residuals")
    L.append(f"Profile intervals: the values whose cost, with the other parameters re-optimised, stays within the "
             f"threshold of the minimum: the data's noise ({noise}) plus the numerical floor (the integrator's "
             f"error at the fit's tolerances, from a rerun at {TIGHTER:g}x tighter ones). See profile.png.")
    L.append("")
    L.append(f"Cost 0.5 sum r^2 = {res.cost:.6g} over {plural(len(res.jacobian), 'scaled residual')}, "
             f"{plural(res.dof, 'degree of freedom')}, s^2 = {res.s2:.6g}; singular values of J (columns scaled to the "
             "bounds) "
             f"{', '.join(f'{v:.4g}' for v in res.singular_values)}, condition {res.condition:.4g}, rank {res.rank}.")
    L.append("")
    L.append("## Identifiability and warnings")
    L.append("")
    L += [f"- {n}" for n in res.notes] or ["- none: every parameter is determined by the data (its profile rises "
                                           "above the noise floor on both sides inside the bounds, starts agree)"]
    L.append("")
    if len(res.names) > 1:
        L.append("## Correlation")
        L.append("")
        L.append("| | " + " | ".join(res.names) + " |")
        L.append("|---" * (len(res.names) + 1) + "|")
        for n, row in zip(res.names, res.correlation):
            L.append(f"| {n} | " + " | ".join("n/a" if not math.isfinite(c) else f"{c:+.4f}" for c in row) + " |")
        L.append("")
    L.append("## Starts")
    L.append("")
    L.append("| start | from | to | cost | status | evaluations | failed cases |")
    L.append("| --- | --- | --- | --- | --- | --- | --- |")
    for k, s in enumerate(res.starts):
        mark = " (best)" if k == res.best_start else ""
        L.append(f"| {k + 1}{mark} | {', '.join(f'{v:.6g}' for v in s.x0)} | {', '.join(f'{v:.8g}' for v in s.x)} | "
                 f"{s.cost:.6g} | {s.status} | {s.nfev} | {s.failed_cases} |")
    L.append("")
    L.append("## Residuals per case")
    L.append("")
    if res.measured["form"] == "peaks":
        L.append("| case | known | status | quantity | measured | model | residual | relative |")
        L.append("| --- | --- | --- | --- | --- | --- | --- | --- |")
        for c in res.cases:
            known = ", ".join(f"{k} = {v:g}" for k, v in c["known"].items())
            for q, d in c["quantities"].items():
                L.append(f"| {c['case']} | {known} | {c['status']} | {q} | {d['measured']:.6g} | {d['model']:.6g} | "
                         f"{d['residual']:.4g} | {d['relative']:.3g} |")
    else:
        L.append("| case | known | status | samples | quantity | RMS measured | RMS residual | max residual "
                 "| relative |")
        L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for c in res.cases:
            known = ", ".join(f"{k} = {v:g}" for k, v in c["known"].items())
            for q, d in c["quantities"].items():
                L.append(f"| {c['case']} | {known} | {c['status']} | {c['samples']} | {q} | {d['rms_measured']:.6g} | "
                         f"{d['rms_residual']:.4g} | {d['max_residual']:.4g} | {d['relative']:.3g} |")
    L.append("")
    L.append("![profiles](profile.png)" if res.profiles else "")
    L.append("")
    L.append("![misfit](misfit.png)" if res.misfit else "")
    L.append("")
    L.append("## Settings and provenance")
    L.append("")
    run = res.settings
    L.append(f"- run: t_end {run['t_end']:g} s, {run['method']}, rtol {run['rtol']:g}, atol {run['atol']:g}, "
             f"max_steps {run['max_steps']}; model runs {res.fit_settings.get('model_runs')}; wall time "
             f"{res.seconds:.3g} s")
    fs = res.fit_settings
    L.append(f"- fit: {fs['method']}, {plural(fs['starts'], 'start')} ({fs['sampler']}, seed {fs['seed']}), cost "
             f"{fs['cost']}, scale per quantity " + ", ".join(f"{q} {v:.6g}" for q, v in res.measured["scale"].items())
             + f", penalty {fs['penalty']:g} per residual of a failed case")
    if res.measured["fixed"]:
        L.append("- fixed at the scene's values: "
                 + ", ".join(f"{k} = {v:g}" for k, v in res.measured["fixed"].items()))
    p = res.provenance
    L.append(f"- scene digest {p['scene_digest']}, model {p['model_digest']}, runtime {p['runtime_version']} "
             f"({p['runtime_digest'][:16]}), measured file sha256 {res.measured['sha256'][:16]}")
    L.append("- versions: " + ", ".join(f"{k} {v}" for k, v in f["provenance"]["versions"].items()))
    L.append("")
    L.append("A fitted value is the parameter that makes this model reproduce these numbers; it is a fit, "
             "not a measurement of the parameter.")
    return "\n".join(L) + "\n"


def write_outputs(res: FitResult, directory: str | Path, plot: bool = True) -> list[Path]:
    """DIR/fit-report.md, fit.json, and with plot: misfit.png (with a misfit grid) and profile.png,
    each written atomically."""
    from tswm_common.files import write_atomic

    directory = Path(directory)
    paths = [write_atomic(directory / "fit.json", json.dumps(res.to_dict(), indent=2, allow_nan=False))]
    if plot and res.misfit:
        paths.append(write_atomic(directory / "misfit.png", misfit_png(res)))
    if plot and res.profiles:
        paths.append(write_atomic(directory / "profile.png", profile_png(res)))
    paths.append(write_atomic(directory / "fit-report.md", report_markdown(res)))
    return paths
