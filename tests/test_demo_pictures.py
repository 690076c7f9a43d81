"""The pictures `polar-sim demo` and `polar-sim render` write say what they show: colour bars with
units that do not run into a title, and a lidar overview that explains a scan with few returns.
Built from stand-in frames and worlds (no simulator), so they run in a second."""

import types

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from polar_sim.sim.pictures import camera_figure, lidar_map_figure  # noqa: E402


def _overlap(a, b):
    """True when two display-space bounding boxes intersect."""
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


# The depth panel's colour bar is exactly as tall as the image, labelled in metres, and clear of
# every title and of the next panel's axis label.
def test_camera_figure_colour_bar_is_clear_of_titles():
    depth = np.linspace(0.5, 80.0, 360 * 480).reshape(360, 480)
    depth[:100] = np.inf                                  # sky: no surface
    labels = np.zeros((360, 480), np.int32)
    labels[200:] = 1
    frame = types.SimpleNamespace(rgb=np.zeros((360, 480, 3), np.uint8), depth=depth, labels=labels)
    fig = camera_figure(frame, "scene: camera 'front'")
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    image_axes, bars = fig.axes[:3], fig.axes[3:]
    (bar,) = bars
    assert "[m]" in bar.get_ylabel() and "depth" in bar.get_ylabel()
    depth_ax = image_axes[1]
    assert bar.get_window_extent(r).height == pytest.approx(depth_ax.get_window_extent(r).height, rel=0.01)
    bar_box = bar.get_tightbbox(r)
    for ax in image_axes:
        assert not _overlap(bar_box, ax.title.get_window_extent(r)), ax.get_title()
    assert not _overlap(bar_box, image_axes[2].yaxis.label.get_window_extent(r))
    assert all(ax.get_title() for ax in image_axes) and fig._suptitle is not None
    assert image_axes[2].get_legend() is not None                  # the label colours are named


class _World:
    """A stand-in for World: one 2D lidar at the origin facing +x, and the SDF of one disc."""

    def __init__(self, ranges):
        self.angles = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, len(ranges))
        self.ranges = np.asarray(ranges, float)

    def lidar(self, name):
        ok = np.isfinite(self.ranges)
        pts = np.c_[self.ranges[ok] * np.cos(self.angles[ok]), self.ranges[ok] * np.sin(self.angles[ok]),
                    np.zeros(ok.sum())]
        return types.SimpleNamespace(angles=self.angles, ranges=self.ranges, T_world_sensor=np.eye(4),
                                     points=lambda: pts)

    def lidar_spec(self, name):
        return types.SimpleNamespace(max_range=30.0)

    def sdf(self, P):
        return np.linalg.norm(P - [20.0, 0.0], axis=1) - 1.0


def _legend_text(fig):
    return [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]


# A scan where most beams return nothing (open ground) says so and draws the field of view; a dense
# scan does not. Every legend entry and the colour bar (metres) are there.
def test_lidar_overview_explains_a_sparse_scan():
    ranges = np.full(1081, np.inf)
    ranges[530:533] = 19.0
    fig = lidar_map_figure(_World(ranges), "lidar", "open ground")
    text = " ".join(_legend_text(fig))
    assert "3 of 1081 beams returned" in text and "field of view (270 deg, 30 m)" in text
    assert "other\n1078 beams met nothing" in text
    assert "[m]" in fig.axes[-1].get_ylabel()
    # the window holds the whole range circle, not a strip around three points
    x0, x1 = fig.axes[0].get_xlim()
    assert x0 <= -30 and x1 >= 30
    dense = lidar_map_figure(_World(np.full(1081, 5.0)), "lidar", "indoors")
    assert "1081 of 1081 beams returned" in " ".join(_legend_text(dense))
    assert not any("field of view" in t for t in _legend_text(dense))
