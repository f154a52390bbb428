"""The report's figures read as a reader would: the paper's unit-less values never on the Nm axis (a panel of
ratios instead, worked out by hand here), one legend outside the data, titles and legends inside the
figure, units on every axis, and no wall-time panel without a spread."""

from __future__ import annotations

import math

import pytest
from scipy import stats
from test_report import CON, SEL, results, write_job

from selpres.report import aggregate, load_jobs
from selpres_studies._table1_plots import PAPER, draw_table1_cost, draw_table1_curves, paper_ratio_rows
from selpres_studies.table1 import ORDER


@pytest.fixture
def sweep(tmp_path):
    """Table 1's grid in part: 6-4-2 complete for three methods, 6-8-2 without conventional results."""
    s = tmp_path / "sweep"
    write_job(s, "selective", "6-4-2", results("selective", "6-4-2", SEL))
    write_job(s, "conventional", "6-4-2", results("conventional", "6-4-2", CON))
    write_job(s, "random_growth", "6-4-2", results("random_growth", "6-4-2", [0.11, 0.11, 0.12, 0.12, 0.10]))
    write_job(s, "selective", "6-8-2", results("selective", "6-8-2", SEL))
    return s


def _grouped(sweep):
    return aggregate(load_jobs(sweep), ORDER)


def _extent(artist, renderer):
    return artist.get_window_extent(renderer)


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_paper_ratio_is_ours_beside_the_papers_by_hand(sweep):
    """6-4-2: selective ÷ conventional per seed (test-10 = held-out here), their geometric mean as the
    fifth root of the product, its interval from scipy's t quantile on the log ratios; the paper's from its
    printed values. 6-8-2 has no conventional results: no row."""
    groups, tops, _ = _grouped(sweep)
    (row,) = paper_ratio_rows(groups, tops)
    ratios = [s / c for s, c in zip(SEL, CON)]
    assert row["topology"] == "6-4-2" and row["n"] == 5
    assert row["ours"] == pytest.approx(math.prod(ratios) ** (1 / 5), rel=1e-12)
    logs = [math.log(r) for r in ratios]
    half = stats.t.ppf(0.975, 4) * stats.tstd(logs) / math.sqrt(5)
    mean = sum(logs) / 5
    assert (row["ours_ci_lo"], row["ours_ci_hi"]) == pytest.approx((math.exp(mean - half), math.exp(mean + half)))
    assert row["paper"] == pytest.approx(0.0581 / 0.0554)


def test_curves_keep_the_papers_values_off_the_nm_axis_and_the_legend_outside(sweep):
    groups, tops, methods = _grouped(sweep)
    fig = draw_table1_curves(groups, tops, methods)
    *panels, ratio = fig.axes
    assert len(panels) == len(tops) == 2
    paper_rms = {v for m in PAPER.values() for v in m["rms"].values()}
    for ax in panels:
        assert ax.get_ylabel() == "held-out curve RMS (Nm)" and "units of t" in ax.get_xlabel()
        for line in ax.get_lines():
            assert not paper_rms & {float(y) for y in line.get_ydata()}, line.get_label()
        assert ax.get_legend() is None
    # the ratio panel: the paper's ratio as its own marker, ours with an interval, no unit claimed
    assert "no unit" in ratio.get_ylabel()
    paper_marker = [ln for ln in ratio.get_lines() if ln.get_label().startswith("paper's Table 1")]
    assert [list(ln.get_ydata()) for ln in paper_marker] == [[pytest.approx(0.0581 / 0.0554)]]
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts()]
    assert len(labels) == len(set(labels)) and sum("paper" in t for t in labels) == 1
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box, page = _extent(legend, renderer), fig.bbox
    assert not any(_overlap(box, _extent(ax, renderer)) for ax in fig.axes)
    for artist in (legend, fig._suptitle):
        e = _extent(artist, renderer)
        assert page.x0 <= e.x0 and e.x1 <= page.x1 and page.y0 <= e.y0 and e.y1 <= page.y1
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_single_topology_curves_fit_their_title_and_legend(sweep):
    """One topology: the narrowest figure, where the title used to run past both edges."""
    groups, tops, methods = _grouped(sweep)
    one = {k: g for k, g in groups.items() if k[0] == "6-4-2"}
    fig = draw_table1_curves(one, ["6-4-2"], methods)
    fig.canvas.draw()
    renderer, page = fig.canvas.get_renderer(), fig.bbox
    for artist in (fig.legends[0], fig._suptitle, *(ax.title for ax in fig.axes)):
        e = _extent(artist, renderer)
        assert page.x0 <= e.x0 and e.x1 <= page.x1 and e.y1 <= page.y1, artist
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_cost_figure_has_no_wall_time_panel_and_its_legend_is_readable(sweep):
    groups, tops, methods = _grouped(sweep)
    fig = draw_table1_cost(groups, tops, methods)
    (ax,) = fig.axes  # presentations only: a job's wall time is one measurement, no spread
    assert "units of t" in ax.get_ylabel()
    (legend,) = fig.legends
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    assert not _overlap(_extent(legend, renderer), _extent(ax, renderer))
    # every legend marker beside its text, not over it
    for handle, text in zip(legend.legend_handles, legend.get_texts()):
        assert _extent(handle, renderer).x1 <= _extent(text, renderer).x0, text.get_text()
    import matplotlib.pyplot as plt

    plt.close(fig)
