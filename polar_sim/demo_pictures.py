"""The figures of ``polar-sim demo``, built from plain arrays (no simulator), so that their layout
can be checked on stand-in data: every legend lies outside the images and maps it describes,
extrapolated map regions are grey, and the tracking figure zooms on the object and draws the
estimated pose."""

from __future__ import annotations

import numpy as np

__all__ = ["gpis_figure", "ground_figure", "tracking_figure", "env_figure", "outlined", "zoom_box", "project"]

#: Colours of the ground picture's agreement panel (RGB 0..255).
GROUND_COLOURS = {"ground, found": (60, 170, 60), "not ground, called ground": (220, 60, 50),
                  "ground, missed": (240, 200, 40)}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def outlined():
    """Path effects that draw a thin dark outline round a white line (so it shows on a white legend)."""
    from matplotlib import patheffects

    return [patheffects.Stroke(linewidth=3, foreground="0.3"), patheffects.Normal()]


def gpis_figure(X, Y, d, true, unseen, path):
    """The GPIS map (grey where ``unseen``) beside the exact SDF, both clipped to -0.5..2.5 m,
    on the grid ``X``, ``Y`` (h, w) m, with the robot ``path`` (n, 2) m."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from polar_sim.plotting import colorbar_beside

    plt = _plt()
    extent = [X[0, 0], X[0, -1], Y[0, 0], Y[-1, 0]]
    fig, ax = plt.subplots(1, 2, figsize=(12, 5.2), gridspec_kw={"wspace": 0.3})
    for a, field, title in ((ax[0], d, "online GPIS map: its signed distance"), (ax[1], true, "exact SDF of the scene")):
        im = a.imshow(field, origin="lower", extent=extent, cmap="viridis", vmin=-0.5, vmax=2.5)
        if a is ax[0]:
            a.imshow(np.where(unseen, 1.0, np.nan), origin="lower", extent=extent, cmap="Greys", vmin=0.0, vmax=2.0,
                     interpolation="nearest")
        a.contour(X, Y, np.where(unseen, np.nan, field) if a is ax[0] else field, levels=[0.0], colors="w",
                  linewidths=0.8)
        a.plot(path[:, 0], path[:, 1], color="orange", lw=1.5)
        a.plot(*path[0], "o", color="orange", ms=6)
        a.set(title=title, xlabel="x [m]", ylabel="y [m]", aspect="equal")
        colorbar_beside(fig, a, im, "signed distance [m] (clipped to -0.5..2.5)")
    fig.legend(handles=[Line2D([], [], color="orange", lw=1.5, marker="o", markevery=[0],
                               label=f"robot path (dot: start), {len(path)} scans"),
                        Line2D([], [], color="w", lw=1.5, path_effects=outlined(), label="zero level: the surface"),
                        Patch(color="0.6", label="never observed (map variance at its prior): not scored")],
               loc="lower center", ncol=3, fontsize=9, frameon=False, bbox_to_anchor=(0.5, -0.06))
    fig.suptitle("office2d, simulated 2D lidar (1 cm noise): the GPIS map built online beside the exact SDF")
    return fig


def ground_figure(rgb, prob, truth, index, mean_iou):
    """Camera image, learned P(ground) and its agreement with the true ground mask (legend below)."""
    from matplotlib.patches import Patch

    from polar_sim.plotting import colorbar_beside, legend_under

    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(17, 2.4), gridspec_kw={"wspace": 0.42})
    ax[0].imshow(rgb)
    ax[0].set_title(f"camera, frame {index}")
    im = ax[1].imshow(prob, cmap="viridis", vmin=0, vmax=1)
    ax[1].set_title("learned P(ground | colour)")
    colorbar_beside(fig, ax[1], im, "probability")
    pred = prob > 0.5
    agree = np.zeros(rgb.shape, np.uint8)
    for (label, colour), sel in zip(GROUND_COLOURS.items(), (pred & truth, pred & ~truth, ~pred & truth)):
        agree[sel] = colour
    ax[2].imshow(agree)
    ax[2].set_title("P > 0.5 against the true ground mask")
    for a in ax:
        a.set(xlabel="u [px]", ylabel="v [px]")
    legend_under(ax[2], [Patch(color=np.array(c) / 255, label=t) for t, c in GROUND_COLOURS.items()]
                 + [Patch(color="k", label="neither")], ncol=2)
    fig.suptitle(f"rover on route flat_00 (simulated): GroundVO's ground classifier, learned online from its own "
                 f"RANSAC labels, after {index + 1} frames (mean IoU {mean_iou:.2f} after frame 10)")
    return fig


def project(K, T, points):
    """Pixels (n, 2) of points (n, 3) in the object frame under pose ``T`` (4, 4, object to camera)."""
    X = points @ T[:3, :3].T + T[:3, 3]
    return np.column_stack([K[0, 0] * X[:, 0] / X[:, 2] + K[0, 2], K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]])


def zoom_box(shape, uv, *, pad=0.35, min_side=48):
    """A square window (u0, u1, v0, v1), pixels, round the pixels ``uv`` (n, 2), ``pad`` of their
    extent added on each side, at least ``min_side`` wide and inside an image of ``shape`` (H, W)."""
    H, W = shape[:2]
    lo, hi = uv.min(0), uv.max(0)
    c = (lo + hi) / 2
    half = max(float((hi - lo).max()) * (0.5 + pad), min_side / 2)
    half = min(half, H / 2, W / 2)
    cu, cv = np.clip(c[0], half, W - half), np.clip(c[1], half, H - half)
    return cu - half, cu + half, cv - half, cv + half


def _silhouette(shape, uv):
    """(H, W) float mask of the pixels the projected points ``uv`` (n, 2) cover, their gaps closed."""
    import cv2

    H, W = shape
    m = np.zeros((H, W), np.uint8)
    ij = np.rint(uv).astype(int)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
    m[ij[ok, 1], ij[ok, 0]] = 1
    return cv2.morphologyEx(m, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8)).astype(float)


def _axes_pixels(K, T, length):
    """Pixels of the origin and the tips of the x, y, z axes (length m) of pose T."""
    return project(K, T, np.vstack([np.zeros(3), length * np.eye(3)]))


def tracking_figure(frame, mask, K, model_points, T_est, T_gt, *, index, start, add_m, iou, diameter):
    """One tracked frame: the whole image with the zoom window; the zoom with the model points and
    axes projected at the estimated pose (the true pose's axes dashed); the zoom with the tracker's
    mask and the true visible outline. ``frame`` holds ``rgb`` (H, W, 3), ``mask_visible`` and
    ``mask_full`` (H, W) bool; ``add_m`` (m) and ``iou`` are this frame's scores."""
    import cv2
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Rectangle

    from polar_sim.plotting import legend_under

    plt = _plt()
    rgb = frame["rgb"]
    uv = project(K, T_est, model_points)
    ys, xs = np.nonzero(frame["mask_full"])
    box = zoom_box(rgb.shape, np.vstack([uv, np.column_stack([xs, ys])]) if len(xs) else uv)
    u0, u1, v0, v1 = box
    fig, ax = plt.subplots(1, 3, figsize=(16, 5.0), gridspec_kw={"wspace": 0.25})
    ax[0].imshow(rgb)
    ax[0].add_patch(Rectangle((u0, v0), u1 - u0, v1 - v0, fill=False, ec="w", lw=1.5))
    ax[0].set_title(f"camera, frame {index} (the hand touches the mug)")
    ax[1].imshow(rgb)
    ax[1].scatter(uv[:, 0], uv[:, 1], s=2, color="c", alpha=0.5, lw=0)
    ax[1].contour(_silhouette(rgb.shape[:2], uv), levels=[0.5], colors="c", linewidths=1.5)
    L = 0.5 * diameter
    for T, ls in ((T_gt, "--"), (T_est, "-")):
        o, *tips = _axes_pixels(K, T, L)
        for tip, c in zip(tips, ("r", "lime", "b")):
            ax[1].plot([o[0], tip[0]], [o[1], tip[1]], ls, color=c, lw=2)
    ax[1].set_title(f"estimated pose: ADD {1000 * add_m:.1f} mm ({add_m / diameter:.2f} d)")
    tint = rgb.copy()
    tint[mask] = (0.45 * tint[mask] + [0, 0, 140]).astype(np.uint8)
    edge = cv2.morphologyEx(frame["mask_visible"].astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    tint[edge] = (255, 255, 0)
    ax[2].imshow(tint)
    ax[2].set_title(f"segmentation: IoU {iou:.2f} with the true visible mask")
    for a in ax[1:]:
        a.set_xlim(u0, u1)
        a.set_ylim(v1, v0)
    for a in ax:
        a.set(xlabel="u [px]", ylabel="v [px]")
    legend_under(ax[0], [Patch(fill=False, ec="k", label="zoom of the other panels")], ncol=1)
    legend_under(ax[1], [Line2D([], [], color="c", marker="s", ms=3, label="model points and outline at the estimate"),
                         Line2D([], [], color="k", label=f"axes x y z ({100 * L:.0f} cm): estimate"),
                         Line2D([], [], color="k", ls="--", label="axes: true pose")], ncol=1)
    legend_under(ax[2], [Patch(color=(0.2, 0.2, 0.7), label="tracker mask"),
                         Patch(color=(1, 1, 0), label="true visible outline")], ncol=1)
    fig.suptitle(f"tabletop mug_touch (simulated RGB-D, {rgb.shape[1]}x{rgb.shape[0]}): ObjectTracker from the true "
                 f"pose at frame {start}, learning the mug's appearance online")
    return fig


def env_figure(frame, X, Y, sdf, track, est_track, info, n, title, *, size_m):
    """A GPISNav episode in three panels: the env's top-down render of the world (``size_m``: its
    width and height, m); the exact SDF on the grid ``X``, ``Y`` (the whole world) with the true
    path ``track`` (k, 2) and the estimated one ``est_track`` (k, 2) m; the env's render of the
    online map around the robot at the end (``frame`` (h, 2w, 3): render | map)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from polar_sim.envs.gpis_nav import RENDER_SDF_RANGE, RENDER_SPAN, RENDER_UNSEEN_GREY, RENDER_ZERO_BAND
    from polar_sim.envs.lidar_nav import GOAL_RADIUS
    from polar_sim.plotting import colorbar_beside

    plt = _plt()
    w = frame.shape[1] // 2
    norm = Normalize(*RENDER_SDF_RANGE)
    lo, hi = RENDER_SDF_RANGE
    goal, pose = info["goal"], info["robot_pose2d"]
    fig, ax = plt.subplots(1, 3, figsize=(18, 5.8), gridspec_kw={"wspace": 0.32})
    ax[0].imshow(frame[:, :w])
    ax[0].set(title="the scene from above\n(render; walls white)", xticks=[], yticks=[])
    ax[0].set_xlabel(f"{size_m[0]:.0f} x {size_m[1]:.0f} m: rooms, doors, clutter; the robot is the small box")
    im = ax[1].imshow(sdf, origin="lower", extent=[X[0, 0], X[0, -1], Y[0, 0], Y[-1, 0]], cmap="viridis", norm=norm)
    ax[1].contour(X, Y, sdf, levels=[0.0], colors="w", linewidths=0.8)
    ax[1].plot(track[:, 0], track[:, 1], color="orange", lw=1.5)
    ax[1].plot(est_track[:, 0], est_track[:, 1], color="m", lw=1.0, ls="--")
    ax[1].plot(*track[0], "s", color="orange", ms=7)
    ax[1].add_patch(plt.Circle(goal[:2], GOAL_RADIUS, fill=False, color=(0.24, 0.86, 0.24), lw=2))
    ax[1].plot(*pose[:2], "o", color=(1, 0.31, 0.31), ms=7)
    ax[1].set_title(f"exact SDF of the world and the path driven\n({n} steps, {info['path_length']:.1f} m)")
    colorbar_beside(fig, ax[1], im, f"exact signed distance [m] (clipped to {lo:g}..{hi:g})")
    ext = [pose[0] - RENDER_SPAN, pose[0] + RENDER_SPAN, pose[1] - RENDER_SPAN, pose[1] + RENDER_SPAN]
    ax[2].imshow(frame[:, w:], extent=ext, origin="upper")
    ax[2].set_title("the online GPIS map around the robot at the end\n(the env's render, world axes)")
    colorbar_beside(fig, ax[2], ScalarMappable(norm, "viridis"),
                    f"map signed distance [m] (clipped to {lo:g}..{hi:g};\nwhite: |d| < {100 * RENDER_ZERO_BAND:g} cm, "
                    "the mapped surface)")
    for a in ax[1:]:
        a.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    fig.legend(handles=[Line2D([], [], color="orange", lw=1.5, marker="s", markevery=[0],
                               label="true path (square: start)"),
                        Line2D([], [], color="m", lw=1.0, ls="--", label="estimated path (ICP-G on the map)"),
                        Line2D([], [], ls="", marker="o", color=(1, 0.31, 0.31), ms=8, label="robot at the end"),
                        Line2D([], [], ls="", marker="o", mfc="none", mec=(0.24, 0.86, 0.24), mew=2, ms=10,
                               label=f"goal (success within {GOAL_RADIUS:g} m)"),
                        Line2D([], [], color="w", lw=1.5, path_effects=outlined(), label="zero level: the surface"),
                        Patch(color=np.array(RENDER_UNSEEN_GREY) / 255, label="map never observed (variance at its "
                                                                              "prior): extrapolation, not drawn")],
               loc="lower center", ncol=3, fontsize=9, frameon=False, bbox_to_anchor=(0.5, 0.0))
    fig.suptitle(title)
    return fig
