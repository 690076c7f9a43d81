"""README pictures of the rover scenes: camera RGB, depth, labels and an overview per scene.

Usage: python benchmarks/plot_scenes_rover.py  (writes docs/img/scene_<name>.png)
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


if __name__ == "__main__":
    sheet("rover_terrain", 45, (8.0, 0.08), "docs/img/scene_rover_terrain.png", distance=60, elevation=-35)
    sheet("rover_flat", 45, (8.0, 0.08), "docs/img/scene_rover_flat.png", distance=60, elevation=-35)
    sheet("office2d", 25, (1.0, 0.0), "docs/img/scene_office2d.png", lookat=[0, 0, 0], distance=38,
          elevation=-89.9)
