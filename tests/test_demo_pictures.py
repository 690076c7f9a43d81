"""The pictures `polar-sim demo` and `polar-sim render` write say what they show: colour bars with
units that do not run into a title, legends that cover no image or map, overviews of the whole
world in a colour scale that is not one saturated colour, map regions never observed in grey, and
a tracking picture that zooms on the object and draws the estimated pose with its scores.
Built from stand-in frames and worlds (no simulator, but for the env render), so they run in
seconds. They check structure (extents, artists, boxes), not pixels."""

import types

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from polar_sim import demo_pictures as D  # noqa: E402
from polar_sim.sim.pictures import camera_figure, lidar_map_figure  # noqa: E402


def _overlap(a, b):
    """True when two display-space bounding boxes intersect."""
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _legends_clear_of_axes(fig):
    """Every legend of ``fig`` (axes' and figure's) lies outside every axes that shows data (images,
    lines, collections): nothing is covered. Returns the number of legends checked."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    legends = [a.get_legend() for a in fig.axes if a.get_legend()] + list(fig.legends)
    data_axes = [a for a in fig.axes if a.images or a.lines or a.collections or a.patches]
    for leg in legends:
        box = leg.get_window_extent(r)
        for a in data_axes:
            assert not _overlap(box, a.get_window_extent(r)), (leg.get_texts()[0].get_text(), a.get_title())
    return len(legends)


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
    assert _legends_clear_of_axes(fig) == 1                        # ... under the image, not over the ground


class _World:
    """A stand-in for World: one 2D lidar at the origin facing +x, and the SDF of one disc; with
    ``bounds`` (x0, x1, y0, y1) m, a scene that declares its extent (as office2d does)."""

    def __init__(self, ranges, bounds=None):
        self.angles = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, len(ranges))
        self.ranges = np.asarray(ranges, float)
        self.meta = types.SimpleNamespace() if bounds is None else types.SimpleNamespace(bounds=bounds)

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


# A scene that declares its bounds is drawn whole (office2d: 30 x 30 m, where the scan sees only a
# corridor), with the scan and the robot in it.
def test_overview_shows_the_whole_world():
    fig = lidar_map_figure(_World(np.full(1081, 2.0), bounds=(-15.0, 15.0, -15.0, 15.0)), "lidar", "office")
    ax = fig.axes[0]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 <= -15 and x1 >= 15 and y0 <= -15 and y1 >= 15
    assert x1 - x0 < 36 and y1 - y0 < 36                            # and not much more
    assert _legends_clear_of_axes(fig) == 1


# Open ground far from anything (distances up to about 50 m) is not one saturated colour: at most
# 5 % of the map lies at or beyond the colour scale's end, where the old fixed 3 m end saturated
# nearly all of it; the scale's end is a round number.
def test_overview_colour_scale_is_not_saturated():
    ranges = np.full(1081, np.inf)
    ranges[530:533] = 19.0
    fig = lidar_map_figure(_World(ranges), "lidar", "open ground")
    im = fig.axes[0].images[0]
    field, vmax = np.asarray(im.get_array()), im.norm.vmax
    assert np.mean(field >= vmax) <= 0.05
    assert np.mean(field >= 3.0) > 0.9                              # (what the old scale clipped)
    assert vmax in {m * 10.0 ** e for m in (1, 2, 2.5, 5) for e in range(0, 3)}


def _mug_frame(H=240, W=320):
    """A stand-in tabletop frame: a 20 x 24 px 'mug' (its full and visible masks) at the image centre."""
    full = np.zeros((H, W), bool)
    full[110:134, 150:170] = True
    vis = full.copy()
    vis[110:118] = False                                          # the hand covers its top
    return {"rgb": np.full((H, W, 3), 120, np.uint8), "mask_visible": vis, "mask_full": full}


# The tracking picture zooms on the object (the zoom holds its projection and is a small part of
# the image), draws the model points and the axes of the estimated pose (and dashed, the true
# pose's), and puts ADD and IoU on the figure; legends sit under the images.
def test_tracking_figure_zooms_and_draws_the_pose():
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.6)
    cube = np.random.default_rng(0).uniform(-0.04, 0.04, (500, 3))
    frame = _mug_frame()
    fig = D.tracking_figure(frame, frame["mask_visible"], K, cube, T, T, index=124, start=80, add_m=0.0023, iou=0.87,
                            diameter=0.12)
    full, zoom, seg = fig.axes
    uv = D.project(K, T, cube)
    for a in (zoom, seg):
        (u0, u1), (v1, v0) = a.get_xlim(), a.get_ylim()
        assert u0 <= uv[:, 0].min() and uv[:, 0].max() <= u1 and v0 <= uv[:, 1].min() and uv[:, 1].max() <= v1
        assert u1 - u0 < 0.4 * 320                                    # zoomed: the mug is not 30 px in 320
    points = [c for c in zoom.collections if len(c.get_offsets()) == len(cube)]
    outline = [c for c in zoom.collections if hasattr(c, "levels")]
    assert len(points) == 1 and len(outline) == 1                     # the model points and their outline
    solid = [ln for ln in zoom.lines if ln.get_linestyle() == "-"]
    dashed = [ln for ln in zoom.lines if ln.get_linestyle() == "--"]
    assert len(solid) == 3 and len(dashed) == 3                       # x, y, z axes: estimate and truth
    text = " ".join(a.get_title() for a in fig.axes)
    assert "ADD 2.3 mm" in text and "IoU 0.87" in text
    assert _legends_clear_of_axes(fig) == 3


# The zoom window is square, holds the pixels it is given plus padding, stays inside the image, and
# is never smaller than its minimum side.
def test_zoom_box():
    u0, u1, v0, v1 = D.zoom_box((240, 320), np.array([[100.0, 100.0], [120.0, 130.0]]))
    assert u1 - u0 == pytest.approx(v1 - v0)
    assert u0 < 100 and u1 > 120 and v0 < 100 and v1 > 130
    u0, u1, v0, v1 = D.zoom_box((240, 320), np.array([[2.0, 2.0], [3.0, 3.0]]))
    assert (u0, v0) == (0.0, 0.0) and u1 - u0 == pytest.approx(48.0)


# The GPIS picture greys what the map never observed (a second image layer over the map only) and
# its legend says so, under the panels.
def test_gpis_figure_greys_the_unobserved():
    X, Y = np.meshgrid(np.linspace(-2, 2, 41), np.linspace(-1, 1, 21))
    d = np.hypot(X, Y) - 0.5
    unseen = X > 1.0
    fig = D.gpis_figure(X, Y, d, d, unseen, np.array([[0.0, 0.0], [0.5, 0.2]]))
    maps = [a for a in fig.axes if a.images]
    assert len(maps[0].images) == 2 and len(maps[1].images) == 1
    grey = np.ma.getdata(maps[0].images[1].get_array())
    np.testing.assert_array_equal(np.isfinite(grey), unseen)
    assert any("never observed" in t.get_text() for t in fig.legends[0].get_texts())
    assert _legends_clear_of_axes(fig) == 1


# The ground picture's colour key lies under the images.
def test_ground_figure_legend_is_clear():
    rgb = np.zeros((60, 200, 3), np.uint8)
    truth = np.zeros((60, 200), bool)
    truth[30:] = True
    fig = D.ground_figure(rgb, truth * 0.9, truth, 79, 0.97)
    assert _legends_clear_of_axes(fig) == 1


# The episode picture draws the exact SDF of the whole world (bounds) with the true and estimated
# paths, and names the grey of the map never observed.
def test_env_figure_shows_the_world_and_both_paths():
    X, Y = np.meshgrid(np.linspace(-6.5, 6.5, 50), np.linspace(-6.5, 6.5, 50))
    track = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]])
    info = {"goal": np.array([2.0, 1.0]), "robot_pose2d": np.array([2.0, 1.0, 0.0]), "path_length": 2.2}
    fig = D.env_figure(np.zeros((48, 96, 3), np.uint8), X, Y, np.hypot(X, Y) - 5.0, track, track + 0.01, info, 3,
                       "GPISNav-v1", size_m=(12.0, 12.0))
    world = fig.axes[1]
    assert world.get_xlim() == pytest.approx((-6.5, 6.5)) and world.get_ylim() == pytest.approx((-6.5, 6.5))
    assert len([ln for ln in world.lines if len(ln.get_xdata()) == 3]) == 2      # the true and estimated paths
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("estimated path" in t for t in labels) and any("never observed" in t for t in labels)
    assert "12 x 12 m" in fig.axes[0].get_xlabel()
    assert _legends_clear_of_axes(fig) == 1


class _Known:
    """A map source that answers distance 1 m everywhere with variance ``var`` (0: seen; 2: never)."""

    def __init__(self, var):
        self.var = var

    def reset(self):
        pass

    def update(self, angles, ranges, pose2d):
        pass

    def query(self, points):
        n = len(points)
        return np.ones(n), np.zeros((n, 2)), np.full(n, self.var)


# The environment's render (the map half of GPISNav's picture) greys what its map has never observed
# and colours the rest: a map that knows nothing is grey but for the robot and goal marks; one
# that knows everything has no grey at all.
@pytest.mark.parametrize("var, grey_share", [(2.0, (0.9, 1.0)), (0.0, (0.0, 0.0))])
def test_env_render_greys_the_unobserved(var, grey_share):
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401
    from polar_sim.envs.gpis_nav import RENDER_UNSEEN_GREY

    env = gym.make("polar_sim/GPISNav-v1", sdf_source=_Known(var), pose_source="truth", render_mode="rgb_array",
                   render_size=(96, 96), tier="room")
    env.reset(seed=0)
    frame = env.render()
    env.close()
    heat = frame[:, frame.shape[1] // 2:]
    share = float(np.mean(np.all(heat == RENDER_UNSEEN_GREY, axis=-1)))
    assert grey_share[0] <= share <= grey_share[1]
