"""``navworld``: seeded cluttered indoor worlds for goal-reaching navigation (GPISNav-v0).

A grid of rooms is carved into a square; neighbouring rooms are joined by doors along a random
spanning tree (so every room is reachable) plus a few extra doors (so there are loops). Clutter
(boxes and cylinders, solid from the floor up) is scattered with clearance from doors. The start
and the goal are sampled in free space at least ``min_goal_distance`` apart, and the goal is
checked reachable for the rover on an inflated occupancy grid.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy import ndimage

from polar_sim.sim.robots import GROUP, ROVER_PRESETS, add_rover

__all__ = ["build_navworld"]

_T = 0.075  # wall half thickness, m
_H = 0.6  # wall half height, m


def _box(spec, name, cx, cy, hx, hy, hz, material):
    spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=[cx, cy, hz], size=[hx, hy, hz],
                            material=material, group=GROUP["static"])


def _rasterise(obstacles, bounds, res, inflate):
    """Occupancy (ny, nx) bool of boxes/discs inflated by ``inflate`` metres."""
    x0, x1, y0, y1 = bounds
    xs = np.arange(x0 + res / 2, x1, res)
    ys = np.arange(y0 + res / 2, y1, res)
    X, Y = np.meshgrid(xs, ys)
    occ = np.zeros(X.shape, bool)
    for kind, cx, cy, a, b, yaw in obstacles:
        if kind == "box":
            c, s = np.cos(yaw), np.sin(yaw)
            u = (X - cx) * c + (Y - cy) * s
            v = -(X - cx) * s + (Y - cy) * c
            dx, dy = np.maximum(np.abs(u) - a, 0), np.maximum(np.abs(v) - b, 0)
            occ |= np.hypot(dx, dy) <= inflate
        else:
            occ |= np.hypot(X - cx, Y - cy) <= a + inflate
    return occ, xs, ys


def build_navworld(spec: mujoco.MjSpec, seed, *, rooms=3, room_size=4.0, clutter=10, door_width=1.6,
                   extra_doors=0.5, min_goal_distance=5.0, lidar_beams=270):
    """Rooms, doors, clutter, the indoor rover at the start and a goal marker.

    Options: ``rooms`` per side (int), ``room_size`` (m), ``clutter`` pieces (int),
    ``door_width`` (m), ``extra_doors`` (probability that a wall not on the spanning tree has a
    door too: 0 gives a maze, 1 a door in every wall), ``min_goal_distance`` (m, straight line),
    ``lidar_beams`` of the 2D lidar (270 deg field of view).
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7003]))
    n, L = int(rooms), float(room_size)
    half = n * L / 2
    bounds = (-half, half, -half, half)
    obstacles = []  # (kind, cx, cy, half_a, half_b, yaw) for rasterising and placing

    def wall(name, x0, y0, x1, y1):
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        hx = abs(x1 - x0) / 2 + _T
        hy = abs(y1 - y0) / 2 + _T
        if y0 == y1:
            hy = _T
        else:
            hx = _T
        _box(spec, name, cx, cy, hx, hy, _H, "wall")
        obstacles.append(("box", cx, cy, hx, hy, 0.0))

    # Outer walls.
    wall("wall_s", -half, -half, half, -half)
    wall("wall_n", -half, half, half, half)
    wall("wall_w", -half, -half, -half, half)
    wall("wall_e", half, -half, half, half)
    # Doors: a random spanning tree over the room grid, plus extra doors for loops.
    edges = [((i, j), (i + 1, j)) for i in range(n - 1) for j in range(n)] + \
            [((i, j), (i, j + 1)) for i in range(n) for j in range(n - 1)]
    order = rng.permutation(len(edges))
    parent = {(i, j): (i, j) for i in range(n) for j in range(n)}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    doors = set()
    for k in order:
        a, b = edges[k]
        if find(a) != find(b):
            parent[find(a)] = find(b)
            doors.add(edges[k])
    for k in order:
        if rng.random() < extra_doors:
            doors.add(edges[k])
    door_pts = []
    for idx, (a, b) in enumerate(edges):
        (i, j), (i2, j2) = a, b
        if i2 == i + 1:  # wall between columns i and i+1 (vertical, at x = ...)
            x = -half + (i + 1) * L
            y0, y1 = -half + j * L, -half + (j + 1) * L
            if (a, b) in doors:
                c = rng.uniform(y0 + door_width / 2 + 0.3, y1 - door_width / 2 - 0.3)
                door_pts.append((x, c))
                wall(f"wall_v{idx}_a", x, y0, x, c - door_width / 2)
                wall(f"wall_v{idx}_b", x, c + door_width / 2, x, y1)
            else:
                wall(f"wall_v{idx}", x, y0, x, y1)
        else:  # wall between rows j and j+1 (horizontal)
            y = -half + (j + 1) * L
            x0, x1 = -half + i * L, -half + (i + 1) * L
            if (a, b) in doors:
                c = rng.uniform(x0 + door_width / 2 + 0.3, x1 - door_width / 2 - 0.3)
                door_pts.append((c, y))
                wall(f"wall_h{idx}_a", x0, y, c - door_width / 2, y)
                wall(f"wall_h{idx}_b", c + door_width / 2, y, x1, y)
            else:
                wall(f"wall_h{idx}", x0, y, x1, y)
    door_pts = np.array(door_pts).reshape(-1, 2)
    # Clutter, away from doors and from each other.
    placed = []
    for k in range(int(clutter)):
        for _ in range(100):
            cyl = rng.random() < 0.4
            a = rng.uniform(0.15, 0.35) if cyl else rng.uniform(0.15, 0.5)
            b = a if cyl else rng.uniform(0.15, 0.5)
            r = np.hypot(a, b) if not cyl else a
            x, y = rng.uniform(-half + r + 0.2, half - r - 0.2, 2)
            if len(door_pts) and np.min(np.hypot(*(door_pts - [x, y]).T)) < r + door_width:
                continue
            if any(np.hypot(px - x, py - y) < r + pr + 0.8 for px, py, pr in placed):
                continue
            placed.append((x, y, r))
            yaw = rng.uniform(0, np.pi)
            hz = rng.uniform(0.3, 0.6)
            if cyl:
                spec.worldbody.add_geom(name=f"clutter_{k}", type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=[x, y, hz],
                                        size=[a, hz, 0], material="clutter", group=GROUP["static"])
                obstacles.append(("disc", x, y, a, a, 0.0))
            else:
                spec.worldbody.add_geom(name=f"clutter_{k}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[x, y, hz],
                                        size=[a, b, hz], quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)],
                                        material="clutter", group=GROUP["static"])
                obstacles.append(("box", x, y, a, b, yaw))
            break
    # Start and goal: free for the rover (inflated by its radius plus a margin), far apart,
    # and connected on the inflated grid.
    cfg = ROVER_PRESETS["indoor"]
    radius = float(np.hypot(cfg.chassis_half[0], cfg.chassis_half[1]))
    res = 0.1
    occ, xs, ys = _rasterise(obstacles, bounds, res, radius + 0.1)
    free = np.argwhere(~occ)
    region, _ = ndimage.label(~occ)  # 4-connected free regions
    for _ in range(500):
        si, gi = free[rng.integers(len(free))], free[rng.integers(len(free))]
        start_xy = np.array([xs[si[1]], ys[si[0]]])
        goal_xy = np.array([xs[gi[1]], ys[gi[0]]])
        if np.linalg.norm(goal_xy - start_xy) < min(min_goal_distance, 0.8 * n * L):
            continue
        if region[tuple(si)] == region[tuple(gi)]:
            break
    else:
        raise ValueError(f"navworld: seed {seed} produced no reachable start/goal pair; change the options")
    start = np.array([start_xy[0], start_xy[1], rng.uniform(-np.pi, np.pi)])
    spec.worldbody.add_site(name="goal", pos=[goal_xy[0], goal_xy[1], 0.01], size=[0.25, 0.01, 0],
                            type=mujoco.mjtGeom.mjGEOM_CYLINDER, material="goal")
    add_rover(spec, cfg, start, lidar_beams=lidar_beams)
    return {"rover_config": cfg, "start_pose2d": start, "goal": goal_xy, "bounds": bounds,
            "occupancy": occ, "occupancy_res": res, "robot_radius": radius}
