"""``navworld``: seeded cluttered indoor worlds for goal-reaching navigation (GPISNav-v0).

A grid of rooms is carved into a square; neighbouring rooms are joined by doors along a random
spanning tree (so every room is reachable) plus a few extra doors (so there are loops). Clutter
(boxes and cylinders, solid from the floor up) is scattered with clearance from doors. The start
and the goal are sampled in free space at least ``min_goal_distance`` apart, and the goal is
checked reachable for the rover on an inflated occupancy grid.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numba
import numpy as np
from scipy import ndimage

from polar_sim.sim.actors.robots import GROUP, ROVER_PRESETS, add_rover

__all__ = ["build_navworld", "navworld_layout", "NavLayout", "check_layout"]

_T = 0.075  # wall half thickness, m
_H = 0.6  # wall half height, m


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


@dataclasses.dataclass(frozen=True)
class NavLayout:
    """One navworld layout, drawn from its seed (no MuJoCo): what :func:`build_navworld` adds to a
    scene and what a pooled world writes into its compiled model.

    Attributes
    ----------
    walls : tuple of (name, cx, cy, hx, hy)
        Boxes from the floor to 2 * _H m, centre and half sizes, m.
    clutter : tuple of (name, cylinder, x, y, a, b, hz, yaw)
        Boxes (half sizes a, b, turned by yaw about z) and cylinders (radius a), 2 * hz high.
    start_pose2d : (3,) the rover's start (x, y, theta), m and rad.
    goal : (2,) m.
    bounds : (x0, x1, y0, y1), m.
    occupancy : (ny, nx) bool, obstacles inflated by the rover's radius plus 0.1 m, :data:`_RES` cells.
    robot_radius : float, m.
    """

    walls: tuple
    clutter: tuple
    start_pose2d: np.ndarray
    goal: np.ndarray
    bounds: tuple
    occupancy: np.ndarray
    robot_radius: float

    def meta(self):
        """The scene metadata the environments read."""
        return {"rover_config": ROVER_PRESETS["indoor"], "start_pose2d": self.start_pose2d, "goal": self.goal,
                "bounds": self.bounds, "occupancy": self.occupancy, "occupancy_res": _RES,
                "robot_radius": self.robot_radius}


def navworld_layout(seed, *, rooms=3, room_size=4.0, clutter=10, door_width=1.6, extra_doors=0.5,
                    min_goal_distance=5.0):
    """The :class:`NavLayout` of ``seed`` (options as :func:`build_navworld`'s; limits in
    :func:`check_layout`). Raises ``ValueError`` if the draw has no reachable start/goal pair."""
    n, L, clutter, door_width, extra_doors, min_goal_distance = check_layout(
        rooms, room_size, clutter, door_width, extra_doors, min_goal_distance)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7003]))
    half = n * L / 2
    bounds = (-half, half, -half, half)
    walls = [_wall(name, x0, y0, x1, y1)
             for name, (x0, y0, x1, y1) in (("wall_s", (-half, -half, half, -half)), ("wall_n", (-half, half, half, half)),
                                            ("wall_w", (-half, -half, -half, half)), ("wall_e", (half, -half, half, half)))]
    edges, doors = _doors(rng, n, extra_doors)
    door_pts = _inner_walls(walls, rng, edges, doors, n, L, door_width)
    pieces = _clutter(rng, clutter, half, door_pts, door_width)
    obstacles = [("box", cx, cy, hx, hy, 0.0) for _, cx, cy, hx, hy in walls] + \
                [("disc", x, y, a, a, 0.0) if cyl else ("box", x, y, a, b, yaw) for _, cyl, x, y, a, b, _, yaw in pieces]
    cfg = ROVER_PRESETS["indoor"]
    radius = float(np.hypot(cfg.chassis_half[0], cfg.chassis_half[1]))
    occ, start, goal_xy = _start_and_goal(rng, obstacles, bounds, radius, min(min_goal_distance, 0.8 * n * L), seed)
    return NavLayout(tuple(walls), tuple(pieces), start, goal_xy, bounds, occ, radius)


def build_navworld(spec: mujoco.MjSpec, seed, *, rooms=3, room_size=4.0, clutter=10, door_width=1.6,
                   extra_doors=0.5, min_goal_distance=5.0, lidar_beams=270, pooled=False):
    """Rooms, doors, clutter, the indoor rover at the start and a goal marker.

    Options: ``rooms`` per side (int), ``room_size`` (m), ``clutter`` pieces (int),
    ``door_width`` (m), ``extra_doors`` (probability that a wall not on the spanning tree has a
    door too: 0 gives a maze, 1 a door in every wall), ``min_goal_distance`` (m, straight line),
    ``lidar_beams`` of the 2D lidar (270 deg field of view); limits in :func:`check_layout`.

    ``pooled=True`` builds a world whose layout can be replaced in place (``World.relayout``)
    instead of recompiled: one box or cylinder slot for every wall and piece of clutter the
    options allow, filled from the layout after compilation (:func:`relayout_navworld`), the
    unused ones hidden (no contact, no ray, not drawn); MuJoCo's mid-phase, whose bounding
    volumes are built at compile time, is off, so contacts are found on the current geometry.
    """
    if not isinstance(pooled, (bool, np.bool_)):
        raise TypeError(f"pooled: expected a bool, got {pooled!r}")
    lay = navworld_layout(seed, rooms=rooms, room_size=room_size, clutter=clutter, door_width=door_width,
                          extra_doors=extra_doors, min_goal_distance=min_goal_distance)
    if pooled:
        return _build_pooled(spec, lay, rooms, clutter, lidar_beams)
    for name, cx, cy, hx, hy in lay.walls:
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=[cx, cy, _H], size=[hx, hy, _H],
                                material="wall", group=GROUP["static"])
    for name, cyl, x, y, a, b, hz, yaw in lay.clutter:
        if cyl:
            spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=[x, y, hz],
                                    size=[a, hz, 0], material="clutter", group=GROUP["static"])
        else:
            spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=[x, y, hz], size=[a, b, hz],
                                    quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], material="clutter",
                                    group=GROUP["static"])
    goal = lay.goal
    spec.worldbody.add_site(name="goal", pos=[goal[0], goal[1], 0.01], size=[0.25, 0.01, 0],
                            type=mujoco.mjtGeom.mjGEOM_CYLINDER, material="goal")
    add_rover(spec, ROVER_PRESETS["indoor"], lay.start_pose2d, lidar_beams=lidar_beams)
    return lay.meta()


def _build_pooled(spec, lay, rooms, clutter, lidar_beams):
    """The pooled scene: hidden slots, the goal marker, the rover; the layout is written after
    compilation (``World`` calls :func:`relayout_navworld`)."""
    n_walls, n_clutter = _slot_counts(rooms, clutter)
    for k in range(n_walls + n_clutter):
        name = f"wall_{k}" if k < n_walls else f"clutter_{k - n_walls}"
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0, -10.0], size=[0.01] * 3,
                                material="wall" if k < n_walls else "clutter", group=GROUP["collision"],
                                contype=0, conaffinity=0)
    spec.worldbody.add_site(name="goal", pos=[0, 0, 0.01], size=[0.25, 0.01, 0], type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                            material="goal")
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
    add_rover(spec, ROVER_PRESETS["indoor"], lay.start_pose2d, lidar_beams=lidar_beams)
    # Clutter cylinders come and go with the layout: draw them as finely as the widest one needs.
    return {**lay.meta(), "pooled": True, "max_round_radius": 0.35}


def _slot_counts(rooms, clutter):
    """(wall slots, clutter slots): 4 outer walls and at most 2 pieces per wall between rooms."""
    n = int(rooms)
    return 4 + 4 * n * (n - 1), int(clutter)


def relayout_navworld(model, seed, *, rooms=3, room_size=4.0, clutter=10, door_width=1.6, extra_doors=0.5,
                      min_goal_distance=5.0, lidar_beams=270, pooled=True):
    """Write the layout of ``seed`` into a pooled navworld ``model`` (its slots and the goal
    marker; the caller resets the data) and return the scene metadata. The layout is drawn
    first: a seed without a reachable start/goal pair raises ``ValueError`` and changes nothing."""
    lay = navworld_layout(seed, rooms=rooms, room_size=room_size, clutter=clutter, door_width=door_width,
                          extra_doors=extra_doors, min_goal_distance=min_goal_distance)
    n_walls, n_clutter = _slot_counts(rooms, clutter)
    obj = mujoco.mjtObj
    first = mujoco.mj_name2id(model, obj.mjOBJ_GEOM, "wall_0")
    if first < 0 or mujoco.mj_name2id(model, obj.mjOBJ_GEOM, f"clutter_{n_clutter - 1}" if n_clutter else "wall_0") < 0:
        raise ValueError("model: not a pooled navworld of these options (build it with pooled=True)")
    # Every slot's shape as (type, size (3,), pos (3,), yaw); the unused ones hidden below the floor.
    G = mujoco.mjtGeom
    shapes = [(G.mjGEOM_BOX, (hx, hy, _H), (cx, cy, _H), 0.0) for _, cx, cy, hx, hy in lay.walls]
    shapes += [(G.mjGEOM_BOX, (0.01,) * 3, (0.0, 0.0, -10.0), 0.0)] * (n_walls - len(lay.walls))
    shapes += [(G.mjGEOM_CYLINDER, (a, hz, 0.0), (x, y, hz), 0.0) if cyl else (G.mjGEOM_BOX, (a, b, hz), (x, y, hz), yaw)
               for _, cyl, x, y, a, b, hz, yaw in lay.clutter]
    shapes += [(G.mjGEOM_BOX, (0.01,) * 3, (0.0, 0.0, -10.0), 0.0)] * (n_clutter - len(lay.clutter))
    used = np.array([True] * len(lay.walls) + [False] * (n_walls - len(lay.walls))
                    + [True] * len(lay.clutter) + [False] * (n_clutter - len(lay.clutter)))
    ids = first + np.arange(n_walls + n_clutter)
    kind = np.array([t for t, _, _, _ in shapes])
    size = np.array([z for _, z, _, _ in shapes], dtype=np.float64)
    yaw = np.array([w for _, _, _, w in shapes])
    model.geom_type[ids] = kind
    model.geom_size[ids] = size
    model.geom_pos[ids] = np.array([p for _, _, p, _ in shapes], dtype=np.float64)
    model.geom_quat[ids] = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], 1)
    # The compiler marks geoms that share their body's frame (or rotation), and the kinematics
    # then copy the body's: a slot's frame is its own.
    model.geom_sameframe[ids] = mujoco.mjtSameFrame.mjSAMEFRAME_NONE
    # The bounding sphere and box the collision and ray code prune with (as the compiler sets them).
    cyl = kind == G.mjGEOM_CYLINDER
    half = np.where(cyl[:, None], np.stack([size[:, 0], size[:, 0], size[:, 1]], 1), size)
    sq = size * size
    model.geom_rbound[ids] = np.sqrt(np.where(cyl, sq[:, 0] + sq[:, 1], sq[:, 0] + sq[:, 1] + sq[:, 2]))
    model.geom_aabb[ids] = np.concatenate([np.zeros((len(ids), 3)), half], 1)
    model.geom_group[ids] = np.where(used, GROUP["static"], GROUP["collision"])
    model.geom_contype[ids] = used
    model.geom_conaffinity[ids] = used
    model.site_pos[mujoco.mj_name2id(model, obj.mjOBJ_SITE, "goal")] = [lay.goal[0], lay.goal[1], 0.01]
    return {**lay.meta(), "pooled": True, "max_round_radius": 0.35}


def _wall(name, x0, y0, x1, y1):
    """A wall from (x0, y0) to (x1, y1) (axis-aligned), 2 * _T thick, extended by _T at both ends:
    (name, cx, cy, hx, hy)."""
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    hx = abs(x1 - x0) / 2 + _T
    hy = abs(y1 - y0) / 2 + _T
    if y0 == y1:
        hy = _T
    else:
        hx = _T
    return name, cx, cy, hx, hy


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


def _inner_walls(walls, rng, edges, doors, n, L, door_width):
    """The walls between rooms, each split around its door if it has one, appended to ``walls``;
    the door centres (k, 2)."""
    half = n * L / 2
    door_pts = []
    for idx, (a, b) in enumerate(edges):
        (i, j), (i2, _) = a, b
        if i2 == i + 1:  # wall between columns i and i+1 (vertical, at x = ...)
            x = -half + (i + 1) * L
            y0, y1 = -half + j * L, -half + (j + 1) * L
            if (a, b) in doors:
                c = rng.uniform(y0 + door_width / 2 + 0.3, y1 - door_width / 2 - 0.3)
                door_pts.append((x, c))
                walls.append(_wall(f"wall_v{idx}_a", x, y0, x, c - door_width / 2))
                walls.append(_wall(f"wall_v{idx}_b", x, c + door_width / 2, x, y1))
            else:
                walls.append(_wall(f"wall_v{idx}", x, y0, x, y1))
        else:  # wall between rows j and j+1 (horizontal)
            y = -half + (j + 1) * L
            x0, x1 = -half + i * L, -half + (i + 1) * L
            if (a, b) in doors:
                c = rng.uniform(x0 + door_width / 2 + 0.3, x1 - door_width / 2 - 0.3)
                door_pts.append((c, y))
                walls.append(_wall(f"wall_h{idx}_a", x0, y, c - door_width / 2, y))
                walls.append(_wall(f"wall_h{idx}_b", c + door_width / 2, y, x1, y))
            else:
                walls.append(_wall(f"wall_h{idx}", x0, y, x1, y))
    return np.array(door_pts).reshape(-1, 2)


def _clutter(rng, count, half, door_pts, door_width):
    """Up to ``count`` boxes and cylinders, away from doors and from each other (100 tries each):
    (name, cylinder, x, y, a, b, hz, yaw) each."""
    placed, pieces = [], []
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
            pieces.append((f"clutter_{k}", bool(cyl), x, y, a, b, hz, yaw))
            break
    return pieces


def _start_and_goal(rng, obstacles, bounds, radius, min_distance, seed):
    """Occupancy (the obstacles inflated by the rover's radius plus 0.1 m, on :data:`_RES` cells),
    the start pose (x, y, theta) and the goal (x, y): free cells at least ``min_distance`` m apart
    and connected on that grid (500 draws)."""
    occ, xs, ys = _rasterise(obstacles, bounds, _RES, radius + 0.1)
    free = np.argwhere(~occ)
    region, _ = ndimage.label(~occ)  # 4-connected free regions
    n_free = len(free)
    for _ in range(500):
        si, gi = free[rng.integers(n_free)], free[rng.integers(n_free)]
        dx, dy = xs[gi[1]] - xs[si[1]], ys[gi[0]] - ys[si[0]]
        # The distance test of np.linalg.norm, whose decision this repeats exactly (within 1e-9 of
        # the bound, where round-off could differ, norm itself decides).
        d = math.sqrt(dx * dx + dy * dy)
        if abs(d - min_distance) < 1e-9:
            d = float(np.linalg.norm(np.array([xs[gi[1]], ys[gi[0]]]) - np.array([xs[si[1]], ys[si[0]]])))
        if d < min_distance:
            continue
        if region[si[0], si[1]] == region[gi[0], gi[1]]:
            start_xy = np.array([xs[si[1]], ys[si[0]]])
            goal_xy = np.array([xs[gi[1]], ys[gi[0]]])
            break
    else:
        raise ValueError(f"navworld: seed {seed} produced no reachable start/goal pair; change the options")
    return occ, np.array([start_xy[0], start_xy[1], rng.uniform(-np.pi, np.pi)]), goal_xy
