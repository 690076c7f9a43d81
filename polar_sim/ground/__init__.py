"""Self-supervised ground segmentation and monocular visual odometry with scale from the ground.

Reimplements B. Lee, K. Daniilidis, D. D. Lee, *Online Self-Supervised Monocular Visual Odometry for
Ground Vehicles* (ICRA 2015) from the spec ``docs/specs/ground.md``; numpy/OpenCV/numba only.

>>> from polar_sim.ground import GroundVO, TrackingConfig
>>> vo = GroundVO(K, camera_height, model="6param", sampling="weighted")   # doctest: +SKIP
>>> e = vo.process(rgb, t)                                                  # doctest: +SKIP
"""

from polar_sim.ground.config import (CalibrationConfig, ClassifierConfig, FilterConfig, GroundModelConfig,
                                     MotionConfig, TrackingConfig)
from polar_sim.ground.models import GROUND_MODELS, GroundFit, fit_ground, ransac_iterations
from polar_sim.ground.vo import STATUSES, GroundEstimate, GroundVO

__all__ = ["GroundVO", "GroundEstimate", "STATUSES", "GROUND_MODELS", "GroundFit", "fit_ground", "ransac_iterations",
           "TrackingConfig", "MotionConfig", "GroundModelConfig", "FilterConfig", "ClassifierConfig",
           "CalibrationConfig"]
