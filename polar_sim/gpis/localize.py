"""ICP-G: localisation on the signed distance field of a GPIS map (scan-to-map registration).

``localize(map, scan, initial_pose, ...)`` pulls every beam end point along the map's SDF
gradient by its SDF value, Gauss-Newton on SE(2) or SE(3) with robust weights
``rho(d) / (var + sigma^2)`` that trust the map where its variance is low. The solver is
:func:`polar_sim.registration.register_sdf` (the same one runs ICP-D on a discrete SDF in
:class:`polar_sim.baselines.ICPLocalizer`); see it for every parameter and output.

In 2D the scan's sensor offset follows the map: ``sensor_offset=None`` takes
``map.sensor_offset`` (``GPISMap2D``'s default is (0, 0): the pose is the sensor's), so a map
fed base poses with a mounting offset localises base poses with the same offset.
"""

from polar_sim.registration.sdf import register_sdf as localize

__all__ = ["localize"]
