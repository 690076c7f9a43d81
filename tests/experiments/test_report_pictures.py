"""The experiment reports' pictures read as a reviewer wants: error charts with plain tick labels and
no label cut off, maps that grey what was never observed, legends and colour bars that cover no
map. Built from stand-in arrays; they check structure (ticks, boxes, artists), not pixels."""

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from polar_sim.experiments import _ground_pictures as G  # noqa: E402
from polar_sim.runner import pictures2d as P  # noqa: E402


def _overlap(a, b):
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _boxes(fig):
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _assert_legends_clear(fig):
    """No legend lies over an axes that shows data (images, lines, scatters, bars)."""
    r = _boxes(fig)
    data = [a for a in fig.axes if a.images or a.lines or a.collections or a.patches]
    legends = [a.get_legend() for a in fig.axes if a.get_legend()]
    assert legends
    for leg in legends:
        for a in data:
            assert not _overlap(leg.get_window_extent(r), a.get_window_extent(r)), a.get_title()


# ground_odometry_errors.png: errors spanning 0.8 % to 170 % on a log axis whose ticks read as plain
# numbers on a 1-2-5 sequence (not "2x10^0"), the target line inside the range, the legend beside
# the bars, and the long y label wrapped inside the figure.
def test_error_chart_ticks_and_labels():
    rng = np.random.default_rng(0)
    table = [{"route": f"test_{k}", "method": m, "t_pct": float(v)} for k in range(12)
             for m, v in zip(("mono", "u2", "w6"), rng.uniform(0.8, 170.0, 3))]
    fig = G.per_route_bars(table, "t_pct", 2.0, "translation error (%), scaled segments: routes under 100 m",
                           "KITTI translation error per route")
    ax = fig.axes[0]
    r = _boxes(fig)
    labels = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
    assert labels and all("$" not in s and "^" not in s for s in labels)
    ticks = [float(s) for s in labels]
    assert all(round(t / 10 ** np.floor(np.log10(t)), 9) in (1, 2, 5) for t in ticks)
    lo, hi = ax.get_ylim()
    vals = [row["t_pct"] for row in table]
    assert lo <= min(vals) and hi >= max(vals) and lo <= 2.0 <= hi
    assert not _overlap(ax.get_legend().get_window_extent(r), ax.get_window_extent(r))
    label, figbox = ax.yaxis.label.get_window_extent(r), fig.bbox
    assert figbox.y0 <= label.y0 and label.y1 <= figbox.y1          # not cut off at the top or the bottom


def _map_arrays():
    xs, ys = np.linspace(-5, 5, 60), np.linspace(-4, 4, 50)
    X, Y = np.meshgrid(xs, ys)
    sdf = 3.0 - np.hypot(X, Y)
    var = np.where(X > 3.0, 1.01, 0.01)                              # the east strip never observed
    return {"xs": xs, "ys": ys, "sdf": sdf, "var": var, "lines": np.array([[3.0, 0.0], [0.0, 3.0], [np.nan, np.nan]]),
            "path": np.array([[0.0, 0.0], [1.0, 0.5]]), "cpu_ms": np.array([3.0, 4.0, 5.0, 40.0])}


# map_panel greys what the map never observed (its variance at the prior): those cells are not drawn
# (NaN over a grey face), the legend names the grey, and legends and colour bars cover no map.
def test_map_figure_greys_the_unobserved():
    z = _map_arrays()
    fig = P.map_figure(z, mapper="gpis", title="stand-in")
    sdf_ax = fig.axes[1]
    shown = np.ma.filled(sdf_ax.images[0].get_array(), np.nan)
    np.testing.assert_array_equal(np.isnan(shown), z["var"] >= 1.0)
    assert matplotlib.colors.to_rgb(sdf_ax.get_facecolor()) == matplotlib.colors.to_rgb(P.UNSEEN_GREY)
    assert any("never observed" in t.get_text() for t in sdf_ax.get_legend().get_texts())
    _assert_legends_clear(fig)
    r = _boxes(fig)
    bars = [a for a in fig.axes if a not in fig.axes[:3]]            # the colour bars' axes
    assert len(bars) == 2
    for b in bars:
        for a in fig.axes[:3]:
            assert not _overlap(b.get_tightbbox(r), a.get_window_extent(r))


# error_figure: the legends under both panels, the colour bar and its label clear of the next panel.
@pytest.mark.parametrize("rows", [1, 3])
def test_error_figure_legends_and_colour_bar(rows):
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(1)
    z = {"hits": rng.uniform(0, 10, (300, 2)), "P": rng.uniform(0, 10, (300, 2)), "err": rng.normal(0, 0.05, 300),
         "path": np.array([[1.0, 1.0], [8.0, 8.0]]), "est": rng.uniform(0, 10, (200, 2)), "dA": rng.uniform(0, 0.2, 200),
         "worst": rng.uniform(0, 10, (6, 2)), "worst_cls": np.array([0, 1, 2, 0, 1, 2])}
    r = {"seed": 10000, "method": "gpis", "near_rmse_m": 0.03, "hausdorff_m": 0.2}
    fig, ax = plt.subplots(rows, 2, figsize=(15, 6.5 * rows), squeeze=False)
    for a in ax:
        P.error_figure(a, z, r, "warehouse2d")
    _assert_legends_clear(fig)
    rr = _boxes(fig)
    cbar = fig.axes[-1]
    assert not _overlap(cbar.get_tightbbox(rr), ax[-1, 1].get_tightbbox(rr))
