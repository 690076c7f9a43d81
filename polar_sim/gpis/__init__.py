"""polar_sim.gpis: online Gaussian Process Implicit Surface mapping (GPisMap), 2D and 3D.

``GPISMap2D`` fuses planar laser scans (quadtree), ``GPISMap3D`` depth images and 3D lidar
(octree). Both answer ``query(points) -> (sdf, grad, var)``; see ``docs/specs/gpis.md`` for the
algorithm and ``docs/guide/gpis.md`` for usage.
"""

from polar_sim.gpis.map2d import GPISMap2D
from polar_sim.gpis.map3d import GPISMap3D

__all__ = ["GPISMap2D", "GPISMap3D"]
