"""Pictures of scenes and sensor frames: colourised depth and labels, and labelled figures."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from polar_sim.plotting import colorbar_beside, legend_under, nice_ceil
from polar_sim.sim.truth import LABELS

__all__ = ["colourise_depth", "colourise_labels", "LABEL_COLOURS", "render_scene_pictures", "save_png", "save_figure",
           "image_figure", "camera_figure", "lidar_map_figure"]

#: RGB colour per label (none, ground, obstacle, target, occluder, robot).
LABEL_COLOURS = np.array([[0, 0, 0], [90, 160, 60], [200, 60, 50], [250, 200, 30], [230, 140, 180],
                          [80, 110, 230]], dtype=np.uint8)


def colourise_depth(depth, max_depth=None):
    """(H, W, 3) uint8 RGB: near is bright, no return is black."""
    ok = np.isfinite(depth)
    if not ok.any():
        return np.zeros(depth.shape + (3,), np.uint8)
    hi = max_depth or float(np.percentile(depth[ok], 98))
    v = np.zeros(depth.shape, np.uint8)
    v[ok] = (255 * (1 - np.clip(depth[ok] / hi, 0, 1))).astype(np.uint8)
    out = cv2.applyColorMap(v, cv2.COLORMAP_INFERNO)[..., ::-1]
    out[~ok] = 0
    return out


def colourise_labels(labels):
    """(H, W, 3) uint8 RGB with :data:`LABEL_COLOURS`."""
    return LABEL_COLOURS[np.clip(labels, 0, len(LABEL_COLOURS) - 1)]


def save_png(path, rgb):
    """Write an RGB uint8 image as PNG."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1])):
        raise OSError(f"could not write {path}")
    return path


def save_figure(fig, path):
    """Save a matplotlib figure as PNG (and close it); returns the path."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def image_figure(rgb, title, *, caption=None):
    """A titled figure of one RGB image (no axes ticks), for renders a user looks at."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h, w = rgb.shape[:2]
    fig, ax = plt.subplots(figsize=(min(12.0, 2.0 + w / 80), 1.0 + h / 80))
    ax.imshow(rgb)
    ax.set_title(title)
    ax.set_xticks([])
    ax.set_yticks([])
    if caption:
        ax.set_xlabel(caption, fontsize=8)
    return fig


def camera_figure(frame, title):
    """RGB, metric depth (colour bar in metres) and per-pixel labels (legend) of one camera frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    fig, ax = plt.subplots(1, 3, figsize=(16, 4.2), gridspec_kw={"wspace": 0.42})
    ax[0].imshow(frame.rgb)
    ax[0].set_title("RGB")
    d = np.where(np.isfinite(frame.depth), frame.depth, np.nan)
    ok = np.isfinite(d)
    hi = float(np.percentile(d[ok], 98)) if ok.any() else 1.0
    im = ax[1].imshow(d, cmap="inferno_r", vmin=0.0, vmax=hi)
    ax[1].set_title("metric depth (white: no surface)")
    colorbar_beside(fig, ax[1], im, f"depth along the optical axis [m]\n(farther than {hi:.3g} m: darkest)")
    ax[2].imshow(colourise_labels(frame.labels))
    ax[2].set_title("per-pixel truth labels")
    present = sorted(set(np.unique(frame.labels).tolist()) & set(LABELS.values()))
    names = {v: k for k, v in LABELS.items()}
    names[LABELS["none"]] = "none (sky, nothing hit)"
    for a in ax:
        a.set_xlabel("u [px]")
        a.set_ylabel("v [px]")
    legend_under(ax[2], [Patch(color=LABEL_COLOURS[v] / 255.0, label=names[v]) for v in present])
    fig.suptitle(title)
    return fig


def lidar_map_figure(world, lidar, title, *, margin=3.0, max_half=30.0, n_cells=400):
    """Top-down map of the world: the exact SDF of the static scene in the lidar plane (colour bar in
    metres, zero level in black), the scan's end points and the sensor pose.

    The window covers the whole world when the scene declares its ``bounds`` (``world.meta``), with
    the robot and the scan; otherwise the scan's end points plus ``margin`` (at most ``max_half`` m
    each way). When fewer than half the beams return (open ground), it also covers the lidar's
    range circle, drawn dashed, and the legend says how many beams met nothing within range. The
    colour scale runs from -1 m to a round number above the 95th percentile of the distances in the
    window, so that open ground is not one saturated colour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter

    scan = world.lidar(lidar)
    rmax = float(world.lidar_spec(lidar).max_range)
    T = scan.T_world_sensor
    cx, cy = T[0, 3], T[1, 3]
    P = scan.points()
    W = P[:, :2] @ T[:2, :2].T + T[:2, 3] if len(P) else np.zeros((0, 2))
    n_beams, n_ret = len(scan.ranges), len(W)
    sparse = n_ret < n_beams / 2
    span = np.vstack([W, [[cx, cy]]] + ([[[cx - rmax, cy - rmax], [cx + rmax, cy + rmax]]] if sparse else []))
    bounds = getattr(getattr(world, "meta", None), "bounds", None)
    if bounds is not None:   # the whole world, and whatever of the scan lies beyond it
        x0, x1, y0, y1 = (float(b) for b in bounds)
        lo, hi = np.minimum(span.min(0), [x0, y0]) - 1.0, np.maximum(span.max(0), [x1, y1]) + 1.0
    else:
        lo = np.maximum(span.min(0) - margin, [cx - max_half - margin, cy - max_half - margin])
        hi = np.minimum(span.max(0) + margin, [cx + max_half + margin, cy + max_half + margin])
    grow = np.maximum(0.6 * float(max(hi - lo)) - (hi - lo), 0.0)   # no thin strips: short side >= 0.6 long
    lo, hi = lo - grow / 2, hi + grow / 2
    res = float(max(hi - lo)) / n_cells
    xs, ys = np.arange(lo[0], hi[0], res), np.arange(lo[1], hi[1], res)
    X, Y = np.meshgrid(xs, ys)
    sdf = world.sdf(np.stack([X.ravel(), Y.ravel()], 1)).reshape(X.shape)
    vmax = nice_ceil(max(float(np.percentile(sdf, 95)), 1.0))
    fig, ax = plt.subplots(figsize=(8.0, 7.0))
    im = ax.imshow(np.clip(sdf, -1.0, vmax), origin="lower", extent=[xs[0], xs[-1], ys[0], ys[-1]], cmap="RdBu",
                   norm=TwoSlopeNorm(vmin=-1.0, vcenter=0.0, vmax=vmax))
    ax.contour(X, Y, sdf, levels=[0.0], colors="k", linewidths=0.8)
    handles = [Line2D([], [], color="k", lw=0.8, label="scene surface (zero level)")]
    if len(W):
        ax.scatter(W[:, 0], W[:, 1], s=2 if not sparse else 25, c="orange", zorder=3)
    handles.append(Line2D([], [], ls="", marker="o", color="orange",
                          label=f"lidar end points: {n_ret} of {n_beams} beams returned"))
    yaw = np.arctan2(T[1, 0], T[0, 0])
    if sparse:   # the field of view: what the beams that did not return swept
        a0, a1 = float(np.min(scan.angles)), float(np.max(scan.angles))
        t = yaw + np.linspace(a0, a1, 361)
        fov = np.c_[np.r_[cx, cx + rmax * np.cos(t), cx], np.r_[cy, cy + rmax * np.sin(t), cy]]
        ax.plot(fov[:, 0], fov[:, 1], "k--", lw=0.8)
        handles.append(Line2D([], [], color="k", ls="--", lw=0.8,
                              label=f"lidar field of view ({np.degrees(a1 - a0):.0f} deg, {rmax:g} m): the other\n"
                                    f"{n_beams - n_ret} beams met nothing within it (open ground)"))
    L = 0.06 * float(max(hi - lo))
    ax.arrow(cx, cy, L * np.cos(yaw), L * np.sin(yaw), width=0.15 * L, color="k", zorder=4)
    handles.append(Line2D([], [], ls="", marker=r"$\rightarrow$", markersize=12, color="k",
                          label="lidar position and heading"))
    cb = colorbar_beside(fig, ax, im, f"exact signed distance in the lidar plane [m]\n(clipped to -1..{vmax:g}; < 0 "
                                      "inside objects)", size="3%")
    cb.set_ticks(np.r_[-1.0, -0.5, np.linspace(0.0, vmax, 6)])   # the two halves of the bar differ in scale
    cb.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    legend_under(ax, handles)
    ax.set_aspect("equal")
    return fig


def render_scene_pictures(world, out_dir, *, width=640, height=480, progress=None):
    """Write a labelled picture of every camera (``<scene>_<cam>.png``: RGB, depth with its colour
    bar, labels with their legend) and an overview (``<scene>_overview.png``: a top-down exact-SDF
    map of the world with the lidar scan where the scene has a 2D lidar, else a third-person
    render). ``progress``, if given, is called with no argument after each picture. Returns the
    written paths."""
    out_dir = Path(out_dir)
    tick = progress or (lambda: None)
    paths = []
    for cam in world.cameras:
        f = world.camera(cam, width=width, height=height)
        paths.append(save_figure(camera_figure(f, f"{world.scene}: camera {cam!r} at t = {f.t:.2f} s, "
                                                  f"{width}x{height}"), out_dir / f"{world.scene}_{cam}.png"))
        tick()
    lidars2d = [n for n in world.lidars if getattr(world.lidar(n), "angles", None) is not None]
    if lidars2d:
        fig = lidar_map_figure(world, lidars2d[0], f"{world.scene} from above at t = {world.time:.2f} s: exact SDF "
                                                   f"and one scan of lidar {lidars2d[0]!r}")
    else:
        fig = image_figure(world.render_view(width=width, height=height), f"{world.scene}: third-person view")
    paths.append(save_figure(fig, out_dir / f"{world.scene}_overview.png"))
    tick()
    return paths
