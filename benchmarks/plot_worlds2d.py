"""README picture of the randomised ``warehouse2d`` worlds: a top-down render of seed 0 and the
exact SDF in the lidar plane of three seeds, with the zero level, the corners and one lidar scan.

Usage: python benchmarks/plot_worlds2d.py  (writes docs/img/scene_warehouse2d.png)
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from polar_sim.sim import World  # noqa: E402


def sdf_panel(ax, w, title):
    x0, x1, y0, y1 = w.meta.bounds
    xs, ys = np.arange(x0, x1, 0.04), np.arange(y0, y1, 0.04)
    X, Y = np.meshgrid(xs, ys)
    D = w.sdf(np.c_[X.ravel(), Y.ravel()]).reshape(X.shape)
    im = ax.imshow(np.clip(D, -0.2, 3.0), origin="lower", extent=(x0, x1, y0, y1), cmap="viridis", vmin=-0.2, vmax=3.0)
    ax.contour(X, Y, D, [0.0], colors="k", linewidths=0.6)
    c = w.meta.corners
    ax.plot(c[:, 0], c[:, 1], "r.", ms=2.5, label="corners")
    s = w.lidar("lidar")
    T = s.T_world_sensor
    P = s.points() @ T[:2, :2].T + T[:2, 3]
    ax.plot(P[:, 0], P[:, 1], ".", color="magenta", ms=1.0, label="one lidar scan (end points)")
    ax.plot(*w.meta.start_pose2d[:2], "w^", ms=7, mec="k", label="rover start")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return im


if __name__ == "__main__":
    fig, axs = plt.subplots(2, 2, figsize=(15, 9.5), constrained_layout=True)
    with World("warehouse2d", seed=0) as w:
        x0, x1, y0, y1 = w.meta.bounds
        top = w.render_view(width=960, height=600, lookat=[(x0 + x1) / 2, (y0 + y1) / 2, 0], distance=30,
                            elevation=-89.9)
        axs[0, 0].imshow(top)
        axs[0, 0].set_title("warehouse2d seed 0: MuJoCo top-down render (hall, unfenced yard on the right)", fontsize=10)
        axs[0, 0].axis("off")
        im = sdf_panel(axs[0, 1], w, f"seed 0: exact SDF in the lidar plane (rows along {w.meta.rows_along})")
    for ax, seed in zip(axs[1], (1, 10_000)):
        with World("warehouse2d", seed=seed) as w:
            sdf_panel(ax, w, f"seed {seed}: exact SDF (rows along {w.meta.rows_along})")
    axs[0, 1].legend(loc="upper right", fontsize=8, framealpha=0.8)
    fig.colorbar(im, ax=axs[:, 1], shrink=0.6, label="signed distance [m] (clipped to -0.2..3; black: zero level)")
    fig.suptitle("Randomised 2D worlds (warehouse2d): shelf rows and racks with aisles, thin and curved walls, "
                 "pillars, crates at random yaw, clutter, an open yard (simulated)")
    os.makedirs("docs/img", exist_ok=True)
    fig.savefig("docs/img/scene_warehouse2d.png", dpi=80)
