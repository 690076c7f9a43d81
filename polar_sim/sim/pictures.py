"""Pictures of scenes and sensor frames: colourised depth and labels, and scene sheets."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from polar_sim.sim.truth import LABELS

__all__ = ["colourise_depth", "colourise_labels", "LABEL_COLOURS", "render_scene_pictures", "save_png"]

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


def render_scene_pictures(world, out_dir, *, width=640, height=480):
    """Write, for every camera, ``<cam>_rgb/_depth/_labels.png``, an overview and a sheet that
    puts them side by side. Returns the written paths."""
    out_dir = Path(out_dir)
    paths = []
    tiles = []
    for cam in world.cameras:
        f = world.camera(cam, width=width, height=height)
        for kind, img in (("rgb", f.rgb), ("depth", colourise_depth(f.depth)), ("labels", colourise_labels(f.labels))):
            paths.append(save_png(out_dir / f"{world.scene}_{cam}_{kind}.png", img))
            tiles.append(img)
    overview = world.render_view(width=width, height=height)
    paths.append(save_png(out_dir / f"{world.scene}_overview.png", overview))
    tiles.append(overview)
    small = [cv2.resize(t, (width // 2, height // 2), interpolation=cv2.INTER_AREA) for t in tiles]
    while len(small) % 2:
        small.append(np.zeros_like(small[0]))
    rows = [np.hstack(small[i : i + 2]) for i in range(0, len(small), 2)]
    paths.append(save_png(out_dir / f"{world.scene}_sheet.png", np.vstack(rows)))
    return paths
