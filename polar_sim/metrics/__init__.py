"""Plain metric functions over numpy arrays (no file I/O, no MuJoCo).

- :mod:`~polar_sim.metrics.calibration`: expected calibration error, reliability diagrams.
- :mod:`~polar_sim.metrics.odometry`: KITTI segment errors, ATE, RPE, trajectory file formats.
- :mod:`~polar_sim.metrics.maps`: distance-field maps against an exact SDF: the observed area of a
  drive, SDF and surface scores, where the worst errors lie, per-class calibration, 3D objects.
- :mod:`~polar_sim.metrics.localisation`: position and heading errors of planar poses, pooled
  over steps.
- :mod:`~polar_sim.metrics.relations`: the SLAM-benchmark relation metric (Kümmerle et al. 2009),
  over all, local and loop relations.
- :mod:`~polar_sim.metrics.ground`: RANSAC ground success ps, its exponential fit, the Laplace
  scale of the speed error, classifier IoU and AUC.
- :mod:`~polar_sim.metrics.pose`: ADD, ADD-S, 5 cm / 5 deg, AUC, BOP VSD / MSSD / MSPD.
- :mod:`~polar_sim.metrics.segmentation`: IoU, ROC AUC of probability maps.
- :mod:`~polar_sim.metrics.surface`: Hausdorff, Chamfer, RMSE, SDF error.
"""

from polar_sim.metrics.calibration import *  # noqa: F401,F403
from polar_sim.metrics.ground import *  # noqa: F401,F403
from polar_sim.metrics.localisation import *  # noqa: F401,F403
from polar_sim.metrics.maps import *  # noqa: F401,F403
from polar_sim.metrics.odometry import *  # noqa: F401,F403
from polar_sim.metrics.relations import *  # noqa: F401,F403
from polar_sim.metrics.pose import *  # noqa: F401,F403
from polar_sim.metrics.segmentation import *  # noqa: F401,F403
from polar_sim.metrics.surface import *  # noqa: F401,F403
