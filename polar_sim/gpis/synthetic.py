"""Small exact scans for the GPIS maps: a 2D lidar inside a circular wall and a depth image of a
tilted plane (numpy only). They feed the contract checks (:func:`check_data_2d`,
:func:`check_data_3d`) and short examples."""

from __future__ import annotations

import numpy as np

__all__ = ["scan_circle", "depth_plane", "check_data_2d", "check_data_3d"]


def scan_circle(n=180, radius=3.0, centre=(0.4, -0.2), pose=(0.0, 0.0, 0.0)):
    """Beam angles (n,) in rad and exact ranges (n,) in m of a 2D lidar at ``pose`` = (x, y, yaw)
    inside a circular wall of ``radius`` m around ``centre``."""
    ang = np.linspace(-np.pi, np.pi, n, endpoint=False)
    x, y, th = pose
    d = np.stack([np.cos(ang + th), np.sin(ang + th)], 1)
    o = np.array([x, y]) - np.asarray(centre)
    b = d @ o
    r = -b + np.sqrt(b * b - (o @ o - radius**2))
    return ang, r


def depth_plane(h=24, w=32, z=1.0):
    """Depth image (h, w) in m of a plane tilted about the camera's x axis (depth ``z`` at the
    centre row, growing towards the bottom rows), and its intrinsics K (3, 3), px."""
    K = np.array([[30.0, 0, (w - 1) / 2], [0, 30.0, (h - 1) / 2], [0, 0, 1.0]])
    v, u = np.mgrid[0:h, 0:w]
    depth = z / (1.0 - 0.3 * (v - K[1, 2]) / K[1, 1])
    return depth.astype(np.float64), K


def check_data_2d():
    """:class:`polar_sim.params.CheckData` of :class:`polar_sim.gpis.GPISMap2D`: three scans along
    a short arc, and two query points (inside and outside the wall)."""
    from polar_sim.params import CheckData

    frames = []
    for k in range(3):
        pose = np.array([0.1 * k, 0.05 * k, 0.1 * k])
        frames.append((*scan_circle(pose=pose), pose))
    return CheckData(frames=tuple(frames), query=(np.array([[0.5, 0.5], [2.0, -1.0]]),))


def check_data_3d():
    """:class:`polar_sim.params.CheckData` of :class:`polar_sim.gpis.GPISMap3D`: two 32x24 depth
    images of a plane, 1 cm apart, and two query points."""
    from polar_sim.params import CheckData

    frames = []
    for k in range(2):
        depth, K = depth_plane(z=1.0 + 0.05 * k)
        T = np.eye(4)
        T[:3, 3] = [0.01 * k, 0.0, 0.0]
        frames.append((depth, K, T))
    return CheckData(frames=tuple(frames), query=(np.array([[0.0, 0.0, 0.9], [0.05, 0.0, 1.0]]),))
