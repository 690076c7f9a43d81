"""What the GPIS papers compare against, plus exact reference maps.

- :class:`OccupancyGrid2D`: log-odds occupancy grid with exact ray traversal.
- :class:`LikelihoodField`: Thrun's likelihood field of a grid.
- :class:`ParticleFilterLocalizer`: MCL on the likelihood field ("PF").
- :class:`DiscreteSDF2D`, :class:`DiscreteSDF3D`: signed EDT of a grid, interpolated ("ICP-D" map).
- :class:`ICPLocalizer`: ICP-D (Gauss-Newton on a discrete SDF) and point-to-point ICP.
- :class:`RoomSDF2D`, :class:`RoomSDF3D`: exact SDF and ray casting of a box room with pillars.
"""

from polar_sim.baselines.analytic import RoomSDF2D, RoomSDF3D
from polar_sim.baselines.discrete_sdf import DiscreteSDF2D, DiscreteSDF3D
from polar_sim.baselines.icp import ICPLocalizer
from polar_sim.baselines.likelihood_field import LikelihoodField
from polar_sim.baselines.occupancy import OccupancyGrid2D
from polar_sim.baselines.particle_filter import (
    ParticleFilterLocalizer,
    low_variance_resample,
    sample_motion_model_odometry,
)

__all__ = [
    "OccupancyGrid2D",
    "LikelihoodField",
    "ParticleFilterLocalizer",
    "sample_motion_model_odometry",
    "low_variance_resample",
    "DiscreteSDF2D",
    "DiscreteSDF3D",
    "ICPLocalizer",
    "RoomSDF2D",
    "RoomSDF3D",
]
