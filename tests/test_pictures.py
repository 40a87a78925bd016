"""Pictures and printed facts: titles fit, legends and labels keep off the data, short impact
phases get a zoom panel, a fit's confidence band is drawn, counts read in their number."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from tswm_runtime.common.words import difference, differences, plural
from tswm_runtime.fitting.fit import Start
from tswm_runtime.fitting.report import misfit_figure
from tswm_runtime.model.contract import load_module
from tswm_runtime.paper import lostmotion
from tswm_runtime.results.plot import figure
from tswm_runtime.simulation.simulate import simulate


def _inside(outer, inner) -> bool:
    """Whether the display box ``inner`` lies within ``outer`` (half a pixel of slack)."""
    return (inner.x0 >= outer.x0 - 0.5 and inner.x1 <= outer.x1 + 0.5
            and inner.y0 >= outer.y0 - 0.5 and inner.y1 <= outer.y1 + 0.5)


def _titles_fit(fig) -> None:
    """The figure's title lies within the figure, each axes' title is no wider than its axes."""
    renderer = fig.canvas.get_renderer()
    if fig._suptitle is not None:
        assert _inside(fig.bbox, fig._suptitle.get_window_extent(renderer)), fig._suptitle.get_text()
    for ax in fig.axes:
        if ax.get_title():
            box = ax.title.get_window_extent(renderer)
            assert box.width <= ax.bbox.width + 0.5 and _inside(fig.bbox, box), ax.get_title()


def _legends_clear_of_data(fig) -> None:
    """No point of an axes' plotted curves (vertical lines included) lies under its legend, and
    the figure's legends lie outside every axes."""
    renderer = fig.canvas.get_renderer()
    for legend in fig.legends:
        box = legend.get_window_extent(renderer)
        assert not any(box.overlaps(ax.bbox) for ax in fig.axes), [t.get_text() for t in legend.get_texts()]
        assert _inside(fig.bbox, box), [t.get_text() for t in legend.get_texts()]              # not cut
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None:
            continue
        box = legend.get_window_extent(renderer)
        for line in ax.get_lines():
            if line.get_marker() not in ("None", "", None, " ") and line.get_linestyle() in ("None", ""):
                continue   # a marker named in the legend itself
            xy = line.get_transform().transform(np.column_stack(line.get_data()))
            covered = (xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)
            assert not covered.any(), (ax.get_ylabel(), line.get_label(), int(covered.sum()))


def test_plural_and_differences():
    assert plural(1, "mode change") == "1 mode change" and plural(0, "event") == "0 events"
    assert plural(2, "event") == "2 events" and plural(1, "degree of freedom") == "1 degree of freedom"
    assert plural(11, "degree of freedom") == "11 degrees of freedom"
    assert difference(0.0) == "agree exactly" and difference(3.21e-7, "N") == "differ by at most 3.2e-07 N"
    assert differences({"S1m": 0.0, "KD1": 0.0}, {"S1m": "N", "KD1": ""}) == "agree exactly in S1m and KD1"
    text = differences({"S1m": 2.3e-9, "KD1": 0.0, "S2m": 0.0}, {"S1m": "N", "KD1": "", "S2m": "N"})
    assert text == "agree exactly in KD1 and S2m and differ by at most 2.3e-09 N in S1m"
    assert "at most 0 " not in text


def test_a_run_with_one_mode_change_says_so():
    """The printed equations switch once, tractive -> inverse-tractive (the paper report's (b))."""
    r = simulate("paper-literal", {"m2": 200.0, "F2": -15000.0})
    assert [ph.regime for ph in r.phases] == ["tractive", "inverse-tractive"] and len(r.events) == 1
    assert r.message.endswith("with 1 mode change"), r.message


def test_backlash_figure_zooms_on_the_impacts_and_keeps_labels_off_the_data():
    r = simulate("backlash")
    assert r.impacts, "the backlash scene strikes the other flank"
    fig = figure(r, load_module("backlash"), event_labels=True)
    fig.canvas.draw()
    zoom = fig.axes[-1]
    lo, hi = zoom.get_xlim()
    assert len(fig.axes) == 5 and "zoomed" in zoom.get_xlabel()           # a1, S1, S2, gap, zoom
    assert all(lo < e.t < hi for e in r.impacts) and hi - lo < 0.2 * r.t_stop
    free = [ph for ph in r.phases if ph.regime == "free flight"]
    assert free and all(lo <= ph.t_start and ph.t_end <= hi for ph in free)
    _titles_fit(fig)
    _legends_clear_of_data(fig)
    top = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in top.texts]
    assert boxes and all(b.y0 >= top.bbox.y1 for b in boxes)              # above the frame, off the curves
    assert all(_inside(fig.bbox, b) for b in boxes)
    assert all(not a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])


def test_long_headings_are_wrapped_to_the_figure():
    """The paper report's heading for reading (d) is longer than a line of the figure."""
    r = simulate(lostmotion.SCENE, {"m2": 200.0, "F2_1": -15000.0, lostmotion.FREE: 0.004})
    heading = f"(d) {lostmotion.SCENE}: {lostmotion.TITLE}\nm2 = 200 kg, F2 = -15000 N; runs"
    fig = figure(r, load_module(lostmotion.SCENE), heading=heading, event_labels=True)
    fig.canvas.draw()
    assert fig._suptitle.get_text().count("\n") >= 2
    assert fig._suptitle.get_text().split() == heading.split()           # wrapped, nothing cut
    _titles_fit(fig)
    _legends_clear_of_data(fig)


def _fit_result(ci: tuple, names=("load_at1",), cost=None, covariance=None) -> SimpleNamespace:
    """What misfit_figure reads of a FitResult, for a cost with its minimum at 0.01."""
    xs = np.linspace(0.0005, 0.05, 199)
    if len(names) == 1:
        axes, grid = [xs.tolist()], (1 + 1e4 * (xs - 0.01) ** 2).tolist() if cost is None else cost
        starts = [Start([0.02], [0.01], 1.0, 1, "", 10, 0)]
    else:
        ys = np.linspace(100.0, 400.0, 9)
        axes = [xs.tolist(), ys.tolist()]
        grid = (1 + 1e4 * (xs[:, None] - 0.01) ** 2 + 1e-4 * (ys[None, :] - 250) ** 2).tolist()
        starts = [Start([0.02, 300.0], [0.01, 250.0], 1.0, 1, "", 10, 0)]
    return SimpleNamespace(
        misfit={"names": list(names), "axes": axes, "cost": grid, "others_at_optimum": []},
        names=list(names), units=["m", "kg"][:len(names)], starts=starts, scene="paper-lostmotion",
        estimate=dict(zip(names, [0.01, 250.0])), ci={names[0]: ci}, confidence=0.95, dof=11,
        covariance=covariance or [[1e-6]])


@pytest.mark.parametrize("ci, narrow", [((0.008, 0.012), False), ((0.0099999, 0.0100001), True)])
def test_misfit_plot_shades_the_confidence_band_and_says_when_it_is_too_narrow_to_see(ci, narrow):
    fig = misfit_figure(_fit_result(ci))
    fig.canvas.draw()
    ax = fig.axes[0]
    entries = [t.get_text() for t in fig.legends[0].get_texts()]
    band = [p for p in ax.patches if "profile interval" in p.get_label()]
    assert len(band) == 1 and 0 < band[0].get_alpha() < 1
    x0, x1 = band[0].get_extents().x0, band[0].get_extents().x1
    assert x1 - x0 >= 0 and ax.transData.inverted().transform((x0, 0))[0] == pytest.approx(ci[0], abs=1e-6)
    label = next(e for e in entries if "profile interval" in e)
    assert ("narrower than the optimum's line" in label) == narrow, label
    assert label.startswith("95% profile interval [0.008, 0.012]" if not narrow else
                            "95% profile interval [0.0099999, 0.0100001]"), label   # the ends differ
    _titles_fit(fig)
    _legends_clear_of_data(fig)


def test_misfit_plot_without_a_finite_interval_says_so():
    fig = misfit_figure(_fit_result((-math.inf, math.inf)))
    entries = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "no finite 95% profile interval" in entries


def test_two_parameter_misfit_plot_shades_the_confidence_region():
    res = _fit_result((0.009, 0.011), names=("load_at1", "m2"), covariance=[[1e-6, 0.0], [0.0, 100.0]])
    fig = misfit_figure(res)
    ax = fig.axes[0]
    region = [p for p in ax.patches if "confidence region" in p.get_label()]
    assert len(region) == 1 and 0 < region[0].get_alpha() < 1
    xy = region[0].get_xy()
    r = math.sqrt(2 * __import__("scipy").stats.f.ppf(0.95, 2, 11))
    assert np.ptp(xy[:, 0]) == pytest.approx(2 * r * 1e-3, rel=1e-3)       # semi-axes r * sigma
    assert np.ptp(xy[:, 1]) == pytest.approx(2 * r * 10.0, rel=1e-3)
    assert any("confidence region" in t.get_text() for t in fig.legends[0].get_texts())
    _titles_fit(fig)


@pytest.mark.heavy
def test_bench_plot_titles_fit_and_its_legend_keeps_off_the_panels():
    from tswm_runtime.bench.cases import CASES
    from tswm_runtime.bench.report import work_precision_figure

    names = list(CASES) + ["a case whose name is much longer than one panel of the figure is wide"]
    rows = [{"case": case, "solver": solver, "rtol": rtol, "t_med": t * (1 + k), "err": rtol * (1 + k)}
            for case in names for k, solver in enumerate(("tswm simulate", "scipy RK45", "scipy LSODA", "CVODE"))
            for rtol, t in ((1e-4, 1e-3), (1e-6, 3e-3), (1e-8, 1e-2))]
    fig = work_precision_figure(rows)
    fig.canvas.draw()
    _titles_fit(fig)
    _legends_clear_of_data(fig)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["tswm simulate", "scipy RK45", "scipy LSODA", "CVODE"]
