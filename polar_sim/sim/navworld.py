"""``navworld``: seeded cluttered indoor worlds for goal-reaching navigation (GPISNav-v0).

A grid of rooms is carved into a square; neighbouring rooms are joined by doors along a random
spanning tree (so every room is reachable) plus a few extra doors (so there are loops). Clutter
(boxes and cylinders, solid from the floor up) is scattered with clearance from doors. The start
and the goal are sampled in free space at least ``min_goal_distance`` apart, and the goal is
checked reachable for the rover on an inflated occupancy grid.
"""

from __future__ import annotations

import mujoco
import numba
import numpy as np
from scipy import ndimage

from polar_sim.sim.robots import GROUP, ROVER_PRESETS, add_rover

__all__ = ["build_navworld"]

_T = 0.075  # wall half thickness, m
_H = 0.6  # wall half height, m


def _box(spec, name, cx, cy, hx, hy, hz, material):
    spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=[cx, cy, hz], size=[hx, hy, hz],
                            material=material, group=GROUP["static"])


#: Limits of the layout options (checked before anything is built): rooms per side, metres per
#: room side, the world's side, and pieces of clutter.
MAX_ROOMS = 16
MAX_ROOM_SIZE = 50.0
MAX_SIDE = 100.0
MAX_CLUTTER = 500
_RES = 0.1  # m, cell of the occupancy grid the start, the goal and the geodesic distance use


def _rasterise(obstacles, bounds, res, inflate):
    """Occupancy (ny, nx) bool of boxes/discs inflated by ``inflate`` metres, and the cell centres
    xs (nx,), ys (ny,).

    Each obstacle is tested only on the cells of its bounding box (plus a cell), in one compiled
    loop, with the same per-cell test (and floating-point operations) as numpy over the whole grid."""
    x0, x1, y0, y1 = bounds
    xs = np.arange(x0 + res / 2, x1, res)
    ys = np.arange(y0 + res / 2, y1, res)
    table = np.zeros((len(obstacles), 9))
    for k, (kind, cx, cy, a, b, yaw) in enumerate(obstacles):
        if kind == "box" and yaw == 0.0:  # the walls: axis-aligned
            rx, ry = a + inflate + res, b + inflate + res
        else:
            rx = ry = (np.hypot(a, b) if kind == "box" else a) + inflate + res
        table[k] = (kind == "box", cx, cy, a, b, np.cos(yaw), np.sin(yaw), rx, ry)
    occ = np.zeros((len(ys), len(xs)), bool)
    _rasterise_kernel(xs, ys, table, float(inflate), occ)
    return occ, xs, ys


@numba.njit(cache=True, nogil=True)
def _rasterise_kernel(xs, ys, table, inflate, occ):
    for k in range(table.shape[0]):
        box, cx, cy, a, b, c, s, rx, ry = table[k]
        j0, j1 = np.searchsorted(xs, cx - rx), np.searchsorted(xs, cx + rx)
        i0, i1 = np.searchsorted(ys, cy - ry), np.searchsorted(ys, cy + ry)
        for i in range(i0, i1):
            Y = ys[i]
            for j in range(j0, j1):
                X = xs[j]
                if box:
                    u = (X - cx) * c + (Y - cy) * s
                    v = -(X - cx) * s + (Y - cy) * c
                    hit = np.hypot(max(abs(u) - a, 0.0), max(abs(v) - b, 0.0)) <= inflate
                else:
                    hit = np.hypot(X - cx, Y - cy) <= a + inflate
                if hit:
                    occ[i, j] = True


def check_layout(rooms, room_size, clutter, door_width=1.6, extra_doors=0.5, min_goal_distance=5.0):
    """The layout options, checked against their limits before anything is built: ``rooms``
    (int, 1..:data:`MAX_ROOMS`), ``room_size`` (m, door_width + 0.6 .. :data:`MAX_ROOM_SIZE`, with
    rooms x room_size <= :data:`MAX_SIDE`), ``clutter`` (int, 0..:data:`MAX_CLUTTER`),
    ``door_width`` (m, > 0), ``extra_doors`` (a probability) and ``min_goal_distance`` (m, >= 0).
    Returns them as (int, float, int, float, float, float)."""
    from polar_sim._validation import as_float, as_int

    rooms = as_int(rooms, "rooms", minimum=1, maximum=MAX_ROOMS)
    clutter = as_int(clutter, "clutter", minimum=0, maximum=MAX_CLUTTER)
    door_width = as_float(door_width, "door_width", minimum=0.0, exclusive_minimum=True, maximum=MAX_ROOM_SIZE)
    room_size = as_float(room_size, "room_size", minimum=door_width + 0.6, exclusive_minimum=True,
                         maximum=MAX_ROOM_SIZE)
    if rooms * room_size > MAX_SIDE:
        raise ValueError(f"room_size: rooms x room_size = {rooms * room_size:g} m exceeds the limit of {MAX_SIDE:g} m "
                         "(MAX_SIDE)")
    extra_doors = as_float(extra_doors, "extra_doors", minimum=0.0, maximum=1.0)
    min_goal_distance = as_float(min_goal_distance, "min_goal_distance", minimum=0.0, maximum=MAX_SIDE)
    return rooms, room_size, clutter, door_width, extra_doors, min_goal_distance


def build_navworld(spec: mujoco.MjSpec, seed, *, rooms=3, room_size=4.0, clutter=10, door_width=1.6,
                   extra_doors=0.5, min_goal_distance=5.0, lidar_beams=270):
    """Rooms, doors, clutter, the indoor rover at the start and a goal marker.

    Options: ``rooms`` per side (int), ``room_size`` (m), ``clutter`` pieces (int),
    ``door_width`` (m), ``extra_doors`` (probability that a wall not on the spanning tree has a
    door too: 0 gives a maze, 1 a door in every wall), ``min_goal_distance`` (m, straight line),
    ``lidar_beams`` of the 2D lidar (270 deg field of view); limits in :func:`check_layout`.
    """
    n, L, clutter, door_width, extra_doors, min_goal_distance = check_layout(
        rooms, room_size, clutter, door_width, extra_doors, min_goal_distance)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7003]))
    half = n * L / 2
    bounds = (-half, half, -half, half)
    obstacles = []  # (kind, cx, cy, half_a, half_b, yaw) for rasterising and placing
    for name, (x0, y0, x1, y1) in (("wall_s", (-half, -half, half, -half)), ("wall_n", (-half, half, half, half)),
                                   ("wall_w", (-half, -half, -half, half)), ("wall_e", (half, -half, half, half))):
        _wall(spec, obstacles, name, x0, y0, x1, y1)
    edges, doors = _doors(rng, n, extra_doors)
    door_pts = _inner_walls(spec, obstacles, rng, edges, doors, n, L, door_width)
    _clutter(spec, obstacles, rng, clutter, half, door_pts, door_width)
    cfg = ROVER_PRESETS["indoor"]
    radius = float(np.hypot(cfg.chassis_half[0], cfg.chassis_half[1]))
    occ, start, goal_xy = _start_and_goal(rng, obstacles, bounds, radius, min(min_goal_distance, 0.8 * n * L), seed)
    spec.worldbody.add_site(name="goal", pos=[goal_xy[0], goal_xy[1], 0.01], size=[0.25, 0.01, 0],
                            type=mujoco.mjtGeom.mjGEOM_CYLINDER, material="goal")
    add_rover(spec, cfg, start, lidar_beams=lidar_beams)
    return {"rover_config": cfg, "start_pose2d": start, "goal": goal_xy, "bounds": bounds,
            "occupancy": occ, "occupancy_res": _RES, "robot_radius": radius}


def _wall(spec, obstacles, name, x0, y0, x1, y1):
    """A wall from (x0, y0) to (x1, y1) (axis-aligned), 2 * _T thick, extended by _T at both ends."""
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    hx = abs(x1 - x0) / 2 + _T
    hy = abs(y1 - y0) / 2 + _T
    if y0 == y1:
        hy = _T
    else:
        hx = _T
    _box(spec, name, cx, cy, hx, hy, _H, "wall")
    obstacles.append(("box", cx, cy, hx, hy, 0.0))


def _doors(rng, n, extra_doors):
    """The walls between neighbouring rooms (edges of the room grid) and the set with a door: a
    random spanning tree (every room reachable), plus each other wall with probability
    ``extra_doors`` (loops)."""
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
    return edges, doors


def _inner_walls(spec, obstacles, rng, edges, doors, n, L, door_width):
    """The walls between rooms, each split around its door if it has one; the door centres (k, 2)."""
    half = n * L / 2
    door_pts = []
    for idx, (a, b) in enumerate(edges):
        (i, j), (i2, j2) = a, b
        if i2 == i + 1:  # wall between columns i and i+1 (vertical, at x = ...)
            x = -half + (i + 1) * L
            y0, y1 = -half + j * L, -half + (j + 1) * L
            if (a, b) in doors:
                c = rng.uniform(y0 + door_width / 2 + 0.3, y1 - door_width / 2 - 0.3)
                door_pts.append((x, c))
                _wall(spec, obstacles, f"wall_v{idx}_a", x, y0, x, c - door_width / 2)
                _wall(spec, obstacles, f"wall_v{idx}_b", x, c + door_width / 2, x, y1)
            else:
                _wall(spec, obstacles, f"wall_v{idx}", x, y0, x, y1)
        else:  # wall between rows j and j+1 (horizontal)
            y = -half + (j + 1) * L
            x0, x1 = -half + i * L, -half + (i + 1) * L
            if (a, b) in doors:
                c = rng.uniform(x0 + door_width / 2 + 0.3, x1 - door_width / 2 - 0.3)
                door_pts.append((c, y))
                _wall(spec, obstacles, f"wall_h{idx}_a", x0, y, c - door_width / 2, y)
                _wall(spec, obstacles, f"wall_h{idx}_b", c + door_width / 2, y, x1, y)
            else:
                _wall(spec, obstacles, f"wall_h{idx}", x0, y, x1, y)
    return np.array(door_pts).reshape(-1, 2)


def _clutter(spec, obstacles, rng, count, half, door_pts, door_width):
    """Up to ``count`` boxes and cylinders, away from doors and from each other (100 tries each)."""
    placed = []
    for k in range(count):
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


def _start_and_goal(rng, obstacles, bounds, radius, min_distance, seed):
    """Occupancy (the obstacles inflated by the rover's radius plus 0.1 m, on :data:`_RES` cells),
    the start pose (x, y, theta) and the goal (x, y): free cells at least ``min_distance`` m apart
    and connected on that grid (500 draws)."""
    occ, xs, ys = _rasterise(obstacles, bounds, _RES, radius + 0.1)
    free = np.argwhere(~occ)
    region, _ = ndimage.label(~occ)  # 4-connected free regions
    for _ in range(500):
        si, gi = free[rng.integers(len(free))], free[rng.integers(len(free))]
        start_xy = np.array([xs[si[1]], ys[si[0]]])
        goal_xy = np.array([xs[gi[1]], ys[gi[0]]])
        if np.linalg.norm(goal_xy - start_xy) < min_distance:
            continue
        if region[tuple(si)] == region[tuple(gi)]:
            break
    else:
        raise ValueError(f"navworld: seed {seed} produced no reachable start/goal pair; change the options")
    return occ, np.array([start_xy[0], start_xy[1], rng.uniform(-np.pi, np.pi)]), goal_xy
