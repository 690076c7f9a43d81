"""Self-supervised object segmentation and 6-DoF tracking under touch occlusion (docs/specs/tracking.md).

``ObjectTracker(model_points, K, initial_pose, appearance=..., registration=RegistrationConfig(...),
...).process(rgb, depth)`` returns a :class:`TrackResult` with the pose (T_cam_obj), the target
mask, the prediction map, the labels O and diagnostics. The stage configs are in
:mod:`polar_sim.tracking.config`; :mod:`polar_sim.tracking.synthetic` renders small RGB-D test scenes.
"""

from polar_sim.tracking.config import AttentionConfig, GuardConfig, LearningConfig, MotionConfig, RegistrationConfig
from polar_sim.tracking.result import TrackResult
from polar_sim.tracking.tracker import APPEARANCE_VARIANTS, ObjectTracker

__all__ = ["ObjectTracker", "TrackResult", "APPEARANCE_VARIANTS", "MotionConfig", "AttentionConfig",
           "RegistrationConfig", "GuardConfig", "LearningConfig"]
