"""The benchmark's verdicts, tables and plots (from the rows ``bench`` measured).

A row: case, solver, rtol, atol, the errors of ``bench_cases.errors``, median / min /
max wall time of one whole call (t_med, t_min, t_max), repeats, events, nfev, status.
"""
from __future__ import annotations

import math

SPEEDUP_TARGET = 40.0  # simulate() default output vs the fastest peer at equal error
SPEEDUP_GOAL = 50.0    # the long-term goal for the same factor
SPEEDUP_LEVELS = (1e-6, 1e-9)
SWEEP_TARGET = 20_000.0  # cases/s on 2 cores at rtol 1e-6
FLAT_TARGET = 2.0  # cost(T = 100 s) / cost(T = 1 s) at most this on an equilibrium tail
TSWM_SIMULATE = "tswm simulate"
TSWM_FIXED_COST = "tswm simulate, no steps"  # bench_cases.run_fixed_cost: the same call to t_end = 1e-9 s
ERR_FLOOR = 1e-17  # errors of exactly 0 are drawn and interpolated at this floor


def cost_at(points, level: float) -> float:
    """The median time a solver needs for error <= level: on its front (runs ordered by
    time, each kept if it is more accurate than all cheaper ones), log-log interpolation
    between the last run above the level and the first at or below it; the cheapest run's
    time if that one already meets it; NaN if none does (never extrapolated)."""
    front = []
    for t, e in sorted((t, max(e, ERR_FLOOR)) for e, t in points if math.isfinite(e) and math.isfinite(t)):
        if not front or e < front[-1][1]:
            front.append((t, e))
    for i, (t, e) in enumerate(front):
        if e <= level:
            if i == 0:
                return t
            t0, e0 = front[i - 1]
            w = (math.log(level) - math.log(e0)) / (math.log(e) - math.log(e0))
            return math.exp(math.log(t0) + w * (math.log(t) - math.log(t0)))
    return math.nan


def _points(rows, case, solver):
    return [(r["err"], r["t_med"]) for r in rows if r["case"] == case and r["solver"] == solver]


def speedup_verdicts(rows, tswm=TSWM_SIMULATE, levels=SPEEDUP_LEVELS, target=SPEEDUP_TARGET):
    """Per case and error level: tswm's cost, the fastest peer's, the measured factor, the
    verdict text (met, or missed by how much), and what the target allows a call against what
    a call costs without integrating (``TSWM_FIXED_COST``'s median, NaN if not measured)."""
    out = []
    peers = [s for s in dict.fromkeys(r["solver"] for r in rows) if not s.startswith("tswm")]
    for case in dict.fromkeys(r["case"] for r in rows):
        fixed = next((r["t_med"] for r in rows if r["case"] == case and r["solver"] == TSWM_FIXED_COST), math.nan)
        for level in levels:
            t_tswm = cost_at(_points(rows, case, tswm), level)
            costs = {p: cost_at(_points(rows, case, p), level) for p in peers}
            costs = {p: c for p, c in costs.items() if not math.isnan(c)}
            best = min(costs, key=costs.get) if costs else None
            factor = costs[best] / t_tswm if best and not math.isnan(t_tswm) else math.nan
            allowed = costs.get(best, math.nan) / target
            out.append({"case": case, "error": level, "tswm": tswm, "tswm_s": t_tswm, "fastest_peer": best,
                        "peer_s": costs.get(best, math.nan), "factor": factor,
                        "verdict": speedup_text(factor, target, t_tswm, best, _smallest(rows, case, tswm)),
                        "target_allows_s": allowed, "fixed_cost_s": fixed, "floor": floor_text(allowed, fixed)})
    return out


def versus_peers(rows, solvers, levels=SPEEDUP_LEVELS) -> list[dict]:
    """Per case and error level: the time each of ``solvers(case)`` ({label: solver}) needs for that
    error and the fastest peer's (``cost_at`` on each work-precision front: NaN where a front does
    not reach it), as {label}_s, fastest_peer, peer_s."""
    out = []
    peers = [s for s in dict.fromkeys(r["solver"] for r in rows) if not s.startswith("tswm")]
    for case in dict.fromkeys(r["case"] for r in rows):
        for level in levels:
            row = {"case": case, "error": level}
            row |= {f"{label}_s": cost_at(_points(rows, case, solver), level)
                    for label, solver in solvers(case).items()}
            costs = {p: c for p in peers if not math.isnan(c := cost_at(_points(rows, case, p), level))}
            best = min(costs, key=costs.get) if costs else None
            out.append(row | {"fastest_peer": best, "peer_s": costs.get(best, math.nan)})
    return out


def _smallest(rows, case, solver) -> str:
    """The smallest error the solver reached on the case, and which component it was."""
    runs = [r for r in rows if r["case"] == case and r["solver"] == solver and math.isfinite(r["err"])]
    if not runs:
        return "none finished"
    r = min(runs, key=lambda r: r["err"])
    part = max((k for k in ("err_S1", "err_v1", "err_x1", "err_t") if k in r and math.isfinite(r[k])),
               key=lambda k: r[k], default="err")
    return f"{r['err']:.2g}, {part} at rtol {r['rtol']:g}" if "rtol" in r else f"{r['err']:.2g}"


def speedup_text(factor: float, target: float, t_tswm: float = 1.0, best: str | None = "peer",
                 smallest: str = "") -> str:
    if math.isnan(t_tswm):
        return f"tswm does not reach this error at the tolerances run (smallest: {smallest})"
    if best is None:
        return "no peer reaches this error at the tolerances run"
    if factor >= target:
        return f"met: {factor:.3g}x faster (target {target:g}x)"
    return f"missed: {factor:.3g}x, {target / factor:.3g}x short of the {target:g}x target"


def floor_text(allowed: float, fixed: float) -> str:
    """Whether the target's time per call leaves room for integrating at all, given what a call
    costs without integrating."""
    if math.isnan(allowed) or math.isnan(fixed):
        return "not measured"
    if fixed >= allowed:
        return f"out of reach: a call without steps takes {fixed / allowed:.3g}x the target's time"
    return f"room for integration: {allowed - fixed:.3g} s"


def threshold_text(measured: float, target: float, unit: str, higher_is_better: bool = True) -> str:
    """'met: ...' or 'missed: ... by how much' for a throughput or a ratio target."""
    ok = measured >= target if higher_is_better else measured <= target
    if ok:
        return f"met: {measured:.4g} {unit} (target {'>=' if higher_is_better else '<='} {target:g})"
    off = target / measured if higher_is_better else measured / target
    return (f"missed: {measured:.4g} {unit}, {off:.3g}x "
            f"{'below' if higher_is_better else 'above'} the target {target:g}")


def md_table(rows, keys, fmt=None) -> str:
    fmt = fmt or {}
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        cells = []
        for k in keys:
            v = r.get(k)
            cells.append(fmt.get(k, "{:.3g}").format(v) if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def work_precision_figure(rows, note: str = ""):
    """Work-precision: error (largest of the four) against median time per call, log-log,
    one panel per case, one curve per solver (tswm's methods and the peers); the solvers named in
    one legend below the panels; ``note`` (the machine and its load) as the figure's title."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from tswm_runtime.results.plot import fit_text

    cases = list(dict.fromkeys(r["case"] for r in rows))
    ncol = min(3, len(cases))
    nrow = math.ceil(len(cases) / ncol)
    fig = Figure(figsize=(5.2 * ncol, 4.2 * nrow + 0.6 + 0.3 * bool(note)), layout="constrained")
    FigureCanvasAgg(fig)
    if note:
        fig.suptitle(note, fontsize=8)
    axes = fig.subplots(nrow, ncol, squeeze=False)
    for ax, case in zip(axes.flat, cases):
        for solver in dict.fromkeys(r["solver"] for r in rows):
            pts = sorted((-r["rtol"], r["t_med"], max(r["err"], ERR_FLOOR)) for r in rows if r["case"] == case
                         and r["solver"] == solver and math.isfinite(r["err"]) and math.isfinite(r["t_med"]))
            if pts:  # joined in order of tolerance
                _, x, y = zip(*pts)
                ax.loglog(x, y, "o-" if solver.startswith("tswm") else ".--", label=solver, ms=4)
        ax.set_title(case, fontsize=10)
        ax.set_xlabel("median wall time per call [s]")
        ax.set_ylabel("error (max of S1, v1, x1, event times)")
        ax.grid(True, which="both", alpha=0.3)
    for ax in list(axes.flat)[len(cases):]:
        ax.axis("off")
    named = {}
    for ax in axes.flat:
        named.update({label: handle for handle, label in zip(*ax.get_legend_handles_labels()) if label not in named})
    fig.legend(list(named.values()), list(named), loc="outside lower center", ncols=max(1, min(len(named), 4)),
               fontsize=7)
    fig.draw_without_rendering()
    for ax in list(axes.flat)[:len(cases)]:
        fit_text(ax.title, ax.bbox.width)
    fig.draw_without_rendering()
    return fig


def plot(rows, path, note: str = "") -> None:
    """The work-precision figure (``note``: the machine and its load) written as a PNG."""
    work_precision_figure(rows, note).savefig(path, dpi=90)


def plot_per_case(rows, directory, note: str = "") -> list[str]:
    """``plot`` of each case alone, as work-precision-CASE.png in ``directory`` (CASE: the case's name in
    lower-case letters, digits and dashes); the file names."""
    import re

    names = []
    for case in dict.fromkeys(r["case"] for r in rows):
        names.append(f"work-precision-{re.sub(r'[^a-z0-9]+', '-', case.lower()).strip('-')}.png")
        plot([r for r in rows if r["case"] == case], directory / names[-1], note)
    return names


def machine_note(info: dict) -> str:
    """The machine and its load in one line, for a figure: cpu, cores, 1-minute load before and after."""
    return (f"{info.get('cpu') or info.get('machine', '?')}, {info.get('cores', '?')} cores; 1-minute load "
            f"{info['loadavg_before'][0]:.1f} before, {info['loadavg_after'][0]:.1f} after")
