"""README pictures of the rover scenes: camera RGB, depth, labels and an overview per scene, and one
picture of every appearance family and sky kind (``World(..., appearance=...)``).

Usage: python benchmarks/plot_scenes_rover.py  (writes docs/img/scene_<name>.png and
docs/img/rover_appearance.png)
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from polar_sim.sim import World  # noqa: E402
from polar_sim.sim.pictures import colourise_depth, colourise_labels, save_png  # noqa: E402


def sheet(scene, steps, action, out, **view):
    with World(scene, seed=0) as w:
        for _ in range(steps):
            w.step(action)
        f = w.camera("front", width=480, height=360)
        top = w.render_view(width=480, height=360, **view)
        tiles = [f.rgb, colourise_depth(f.depth), colourise_labels(f.labels), top]
    img = np.vstack([np.hstack(tiles[:2]), np.hstack(tiles[2:])])
    save_png(out, cv2.resize(img, (800, 600), interpolation=cv2.INTER_AREA))


def appearance_sheet(out, seed=10_003):
    """The front camera (KITTI-like, 621x188) of rover_terrain under every ground family, the default
    look and "random"; then the three sky kinds over the default ground."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from polar_sim.sim.builders.rover_appearance import FAMILIES, SKIES
    from polar_sim.sim.recorders.rover_sequences import KITTI_FOVY_DEG

    looks = [("default (appearance=None)", None)] + [(f, f) for f in FAMILIES] + [("random", "random")]
    looks += [(f"sky: {k}", {"sky": {"kind": k}}) for k in SKIES]
    fig, axes = plt.subplots((len(looks) + 1) // 2, 2, figsize=(12, 1.9 * ((len(looks) + 1) // 2)))
    for ax, (title, look) in zip(axes.ravel(), looks):
        with World("rover_terrain", seed=seed, camera_fovy=KITTI_FOVY_DEG, appearance=look) as w:
            for _ in range(20):
                w.step((6.0, 0.02))
            ax.imshow(cv2.pyrDown(w.camera("front", width=1242, height=376).rgb))
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes.ravel()[len(looks):]:
        ax.axis("off")
    fig.suptitle(f"rover_terrain (seed {seed}), front camera, simulated: the appearance option", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    appearance_sheet("docs/img/rover_appearance.png")
    sheet("rover_terrain", 45, (8.0, 0.08), "docs/img/scene_rover_terrain.png", distance=60, elevation=-35)
    sheet("rover_flat", 45, (8.0, 0.08), "docs/img/scene_rover_flat.png", distance=60, elevation=-35)
    sheet("office2d", 25, (1.0, 0.0), "docs/img/scene_office2d.png", lookat=[0, 0, 0], distance=38,
          elevation=-89.9)
