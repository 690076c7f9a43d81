"""A ``tracker`` plug-in: run your own object tracker in polar_sim's tracking experiments.

The protocol (``polar_sim.runner.methods``): ``factory(model_points (M, 3), K (3, 3), initial_pose
(4, 4), *, model_normals (M, 3), random_state) -> tr``; ``tr.process(rgb (H, W, 3) uint8, depth (H, W)
float32 m, t) -> r`` with ``r.pose`` (4, 4) T_cam_obj and, optionally, ``r.mask`` (H, W) bool,
``r.prob`` (H, W) in [0, 1], ``r.lost`` (bool), ``r.roi`` (x0, y0, x1, y1).

Two plug-ins here:

- ``HoldTracker``: reports the initial pose for ever and an empty mask: the floor any tracker beats.
- ``ColourTracker``: polar_sim's own tracker with another configuration (the colour Naive Bayes,
  no online calibration), to show that keyword arguments are yours to choose.

Run them beside the built-in trackers, scored the same way::

    PYTHONPATH=examples polar-sim run tracking_variants --quick --set method=[ww,my_tracker:HoldTracker]
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np


class HoldTracker:
    """Keeps the initial pose; no segmentation."""

    def __init__(self, model_points, K, initial_pose, *, model_normals=None, random_state=0):
        self.pose = np.array(initial_pose, dtype=float)

    def process(self, rgb, depth, t=None):
        return SimpleNamespace(pose=self.pose.copy(), mask=np.zeros(depth.shape, bool), lost=False)


def ColourTracker(model_points, K, initial_pose, *, model_normals=None, random_state=0, **kw):
    """polar_sim's ObjectTracker with the colour Naive Bayes and the raw prediction map."""
    from polar_sim.tracking import ObjectTracker

    return ObjectTracker(model_points, K, initial_pose, model_normals=model_normals, random_state=random_state,
                         appearance="h", calibrate=False, **kw)
