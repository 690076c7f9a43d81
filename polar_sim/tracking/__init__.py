"""Self-supervised object segmentation and 6-DoF tracking under touch occlusion (docs/specs/tracking.md).

``ObjectTracker(model_points, K, initial_pose, **params).process(rgb, depth)`` returns a
:class:`TrackResult` with the pose (T_cam_obj), the target mask, the prediction map, the labels O
and diagnostics. :mod:`polar_sim.tracking.synthetic` renders small RGB-D test scenes.
"""

from polar_sim.tracking.tracker import APPEARANCE_VARIANTS, ObjectTracker, TrackResult

__all__ = ["ObjectTracker", "TrackResult", "APPEARANCE_VARIANTS"]
