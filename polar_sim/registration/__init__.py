"""polar_sim.registration: scan-to-map registration shared by the GPIS localiser and the baselines.

- :func:`register_sdf`: Gauss-Newton on a signed distance field, without closest points (ICP-G on
  a GPIS map, ICP-D on a discrete SDF); ``polar_sim.gpis.localize.localize`` is this function.
- :func:`kabsch`: closed-form rigid alignment of paired points (Arun et al. 1987 / Umeyama 1991,
  without scale), and :func:`point_to_point_covariance`.
- :func:`robust_weight`, :func:`robust_cost`: Huber / Tukey IRLS kernels.
- Scan handling: :func:`as_scan2d`, :func:`as_sensor_offset`, :func:`valid_beams`,
  :func:`beam_points`, :func:`transform2d`, :func:`arc_length_subsample`, :func:`scan3d_points`.

numpy only; it imports neither the modules (``gpis``, ``baselines``) nor the simulator.
"""

from polar_sim.registration.kabsch import kabsch, point_to_point_covariance
from polar_sim.registration.robust import ROBUST_KERNELS, robust_cost, robust_weight
from polar_sim.registration.scans import (
    arc_length_subsample,
    as_scan2d,
    as_sensor_offset,
    beam_points,
    scan3d_points,
    transform2d,
    valid_beams,
)
from polar_sim.registration.sdf import register_sdf

__all__ = [
    "register_sdf",
    "kabsch",
    "point_to_point_covariance",
    "ROBUST_KERNELS",
    "robust_weight",
    "robust_cost",
    "arc_length_subsample",
    "as_scan2d",
    "as_sensor_offset",
    "beam_points",
    "scan3d_points",
    "transform2d",
    "valid_beams",
]
