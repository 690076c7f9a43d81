"""Shared scene for the baseline tests: a 10 m x 6 m room with a pillar, rotated off the grid axes."""

import numpy as np

from polar_sim.baselines import OccupancyGrid2D, RoomSDF2D
from polar_sim.registration import transform2d

# Rotated so that walls cut the grid cells at every offset: an axis-aligned wall at a fixed offset
# inside its cells would bias a grid map by up to half a cell, the same way for every cell.
ROOM_POSE = (0.37, -0.21, 0.35)
ANGLES = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 1081)  # 270 deg at 0.25 deg, a UTM-30LX
MAP_POSES_ROOM = [(2.0, 1.5, 0.4), (8.0, 1.5, 2.2), (8.0, 4.5, -2.4), (2.0, 4.5, -0.6), (4.5, 3.0, 0.0)]


def make_room():
    return RoomSDF2D(size=(10.0, 6.0), pillars=((6.0, 3.0, 0.5),), pose=ROOM_POSE)


def world_pose(room, x, y, th):
    """Robot pose (x, y, theta) given in the room frame -> world."""
    p = transform2d(room.pose, np.array([[x, y]]))[0]
    return np.array([p[0], p[1], th + room.pose[2]])


def build_grid(room, cell_size=0.05, poses=MAP_POSES_ROOM):
    """A grid built from exact scans at room-frame poses."""
    g = OccupancyGrid2D(cell_size=cell_size)
    for p in poses:
        pose = world_pose(room, *p)
        g.update(ANGLES, room.scan(pose, ANGLES), pose)
    return g


def pose_error(est, truth):
    """(position error m, heading error deg) between planar poses."""
    dth = (est[2] - truth[2] + np.pi) % (2 * np.pi) - np.pi
    return float(np.hypot(*(est[:2] - truth[:2]))), float(abs(np.degrees(dth)))
