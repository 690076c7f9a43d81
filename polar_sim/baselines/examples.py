"""Small exact data sets for the baselines' contract checks (:class:`polar_sim.params.CheckData`):
scans of the exact room :class:`~polar_sim.baselines.RoomSDF2D` from three poses, the occupancy
grid they build, and a walled box for the 3D discrete SDF. Each class names its function in its
``TAGS``; nothing here is imported until a check runs."""

from __future__ import annotations

import numpy as np

from polar_sim.params import CheckData

__all__ = ["occupancy_grid", "discrete_sdf_2d", "discrete_sdf_3d", "likelihood_field", "particle_filter",
           "icp", "room_2d", "room_3d"]

_ANGLES = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 271)           # 270 deg at 1 deg
_POSES = (np.array([2.0, 1.5, 0.4]), np.array([2.3, 1.6, 0.45]), np.array([2.6, 1.7, 0.5]))
_POINTS_2D = np.array([[3.0, 3.0], [-0.5, 3.0], [6.2, 3.1]])


def _scans():
    from polar_sim.baselines.analytic import RoomSDF2D

    room = RoomSDF2D()
    return tuple((_ANGLES.copy(), room.scan(p, _ANGLES), p.copy()) for p in _POSES)


def _grid():
    from polar_sim.baselines.occupancy import OccupancyGrid2D

    grid = OccupancyGrid2D(cell_size=0.1)
    for a, r, p in _scans():
        grid.update(a, r, p)
    return grid


def occupancy_grid():
    """Three scans of the default room (0.1 m cells); the occupancy at three points."""
    return CheckData(init={"cell_size": 0.1}, frames=_scans(), query=(_POINTS_2D.copy(),))


def discrete_sdf_2d():
    """The occupied cells of the room's grid; the SDF at three points."""
    g = _grid()
    return CheckData(frames=((g.occupied_mask(), g.origin_.copy(), g.cell_size),), query=(_POINTS_2D.copy(),))


def discrete_sdf_3d():
    """The walls of a 2 m box of 0.1 m cells with a block inside; the SDF at three points."""
    occ = np.zeros((20, 20, 20), bool)
    occ[[0, -1]] = occ[:, [0, -1]] = occ[:, :, [0, -1]] = True
    occ[8:12, 8:12, 8:12] = True
    return CheckData(frames=((occ, np.zeros(3), 0.1),),
                     query=(np.array([[0.5, 0.5, 0.5], [1.0, 1.0, 1.0], [1.5, 0.4, 1.2]]),))


def likelihood_field():
    """The room's grid; the log-likelihood of three beam end points."""
    return CheckData(frames=((_grid(),),), query=(_POINTS_2D.copy(),))


def particle_filter():
    """200 particles started near the first pose on the room's field, then the three scans with
    their exact odometry."""
    from polar_sim.baselines.likelihood_field import LikelihoodField

    field = LikelihoodField(sigma_hit=0.2).fit(_grid())
    return CheckData(init={"n_particles": 200}, prepare=(("initialize", (field, _POSES[0] + [0.05, -0.05, 0.02])),),
                     frames=_scans())


def icp():
    """The room's grid as the map; one scan registered from 10 cm and 0.05 rad off."""
    a, r, p = _scans()[1]
    return CheckData(frames=((_grid(),),), query=((a, r), p + [0.1, -0.1, 0.05]))


def room_2d():
    """The exact SDF of the default room at three points (no update: the map is exact)."""
    return CheckData(query=(_POINTS_2D.copy(),))


def room_3d():
    """The exact SDF of the default 3D room at three points."""
    return CheckData(query=(np.array([[1.0, 1.0, 1.0], [2.5, 1.5, 1.0], [-0.2, 1.0, 1.0]]),))
