"""``office2d``: seeded furniture in the hand-written lab floor of ``scenes/office2d.xml``.

Furniture is solid from the floor up (desks as closed cabinets, shelves, round tables, pillars),
so a planar lidar at any height below 0.7 m sees its exact outline and ``World.sdf`` in 2D is
a closed form. Nothing is placed in the corridor or within 1.2 m of a door.

``tiles=n`` (default 1, the floor as it is) builds a large world of n x n copies of the floor,
30 m apart (tile (i, j) is shifted by (30 i, 30 j) m; tile (0, 0) is the original position),
each with its own seeded furniture. Neighbouring tiles share their outer wall, which then has a
1.2 m door: east-west on the corridor axis (y = 30 j), so the corridors form one long corridor
per row, and north-south at x = 30 i + 9.85 between the east office and the store of the tile
above, in line with their corridor doors, through a furniture-free lane 1 m either side of it.
The outer boundary of the whole world is closed.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from polar_sim.sim.actors.robots import GROUP, ROVER_PRESETS, add_rover

__all__ = ["build_office", "ROOMS", "DOORS", "TILE", "LANE_X"]

#: Rooms as (x0, x1, y0, y1) interiors, metres.
ROOMS = {
    "office_w": (-14.9, -5.1, 1.6, 14.9),
    "office_c": (-4.9, 4.9, 1.6, 14.9),
    "office_e": (5.1, 14.9, 1.6, 14.9),
    "lab": (-14.9, 4.9, -14.9, -1.6),
    "store": (5.1, 14.9, -14.9, -1.6),
}
#: Side of one floor tile, metres (the ``tiles`` option repeats the floor at this pitch).
TILE = 30.0
#: x of the tiled north-south passage in each tile: the centre of the east office's and the
#: store's doors onto the corridor (9.475-10.225 m).
LANE_X = 9.85
#: Door centres (x, y), metres.
DOORS = [(-10, 1.5), (0, 1.5), (10, 1.5), (-8, -1.5), (10, -1.5), (5, 7.9), (5, -8.5)]

_COLOURS = [(0.55, 0.35, 0.2, 1), (0.3, 0.3, 0.35, 1), (0.75, 0.75, 0.7, 1), (0.2, 0.35, 0.55, 1),
            (0.6, 0.2, 0.2, 1), (0.25, 0.45, 0.25, 1)]


def _furniture(rng):
    kind = rng.choice(["desk", "cabinet", "shelf", "round_table", "pillar"], p=[0.35, 0.2, 0.2, 0.15, 0.1])
    if kind == "desk":
        return kind, "box", (0.8, 0.4, 0.375)
    if kind == "cabinet":
        return kind, "box", (0.3, 0.25, 0.6)
    if kind == "shelf":
        return kind, "box", (rng.uniform(0.6, 1.0), 0.2, 1.0)
    if kind == "round_table":
        return kind, "cylinder", (rng.uniform(0.4, 0.6), 0.375)
    return kind, "cylinder", (0.2, 1.25)


def _place_furniture(spec, rng, offset, lane, k, per_room):
    """Seeded furniture in the five rooms of one tile shifted by ``offset`` (x, y); ``lane``:
    keep footprints 1 m clear of the line x = offset_x + LANE_X (the tiled north-south passage).
    Returns the next free furniture index."""
    ox, oy = offset
    placed = []  # (x, y, radius) footprints, for spacing
    doors = np.array(DOORS, dtype=float)
    for room, (x0, x1, y0, y1) in ROOMS.items():
        for _ in range(int(per_room)):
            for _attempt in range(50):
                kind, shape, size = _furniture(rng)
                rad = float(np.hypot(size[0], size[1]) if shape == "box" else size[0])
                along_wall = shape == "box" and rng.random() < 0.6
                yaw = float(rng.choice([0.0, np.pi / 2]) if along_wall else rng.uniform(0, np.pi))
                x = rng.uniform(x0 + rad, x1 - rad)
                y = rng.uniform(y0 + rad, y1 - rad)
                if np.min(np.hypot(doors[:, 0] - x, doors[:, 1] - y)) < rad + 1.2:
                    continue
                if lane and abs(x - LANE_X) < rad + 1.0:
                    continue
                # Keep 0.9 m between pieces so the rover can pass between most of them.
                if any(np.hypot(px - x, py - y) < rad + pr + 0.9 for px, py, pr in placed):
                    continue
                placed.append((x, y, rad))
                colour = _COLOURS[rng.integers(len(_COLOURS))]
                if shape == "box":
                    spec.worldbody.add_geom(name=f"furniture_{k}_{kind}", type=mujoco.mjtGeom.mjGEOM_BOX,
                                            size=list(size), pos=[x + ox, y + oy, size[2]], rgba=list(colour),
                                            quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)],
                                            group=GROUP["static"])
                else:
                    spec.worldbody.add_geom(name=f"furniture_{k}_{kind}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                                            size=[size[0], size[1], 0], pos=[x + ox, y + oy, size[1]],
                                            rgba=list(colour), group=GROUP["static"])
                k += 1
                break
    return k


_OUTER = ("wall_north", "wall_south", "wall_west", "wall_east")
_HALF_T = 0.075     # wall half-thickness
_HALF_H = 1.25      # wall half-height
_DOOR_HALF = 0.6    # half-width of a door


def _wall(spec, name, x0, y0, x1, y1):
    """An axis-aligned wall box from (x0, y0) to (x1, y1) along its centre line."""
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    hx = 0.5 * abs(x1 - x0) + _HALF_T
    hy = 0.5 * abs(y1 - y0) + _HALF_T
    spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, _HALF_H],
                            pos=[cx, cy, _HALF_H], material="wall")


def _line_with_doors(spec, name, fixed, lo, hi, doors, vertical):
    """Wall segments along x = fixed (vertical) or y = fixed from lo to hi, open at ``doors``."""
    cuts = [lo]
    for d in sorted(doors):
        cuts += [d - _DOOR_HALF - _HALF_T, d + _DOOR_HALF + _HALF_T]
    cuts.append(hi)
    for s, (a, b) in enumerate(zip(cuts[::2], cuts[1::2])):
        if vertical:
            _wall(spec, f"{name}_{s}", fixed, a + (_HALF_T if s else 0.0), fixed, b - (_HALF_T if b != hi else 0.0))
        else:
            _wall(spec, f"{name}_{s}", a + (_HALF_T if s else 0.0), fixed, b - (_HALF_T if b != hi else 0.0), fixed)


def _tile_walls(spec, n):
    """Copy the inner walls into every tile and rebuild the outer walls with doors between tiles."""
    inner = [g for g in spec.geoms if g.name.startswith("wall_") and g.name not in _OUTER]
    proto = [(g.name, np.array(g.size, float), np.array(g.pos, float)) for g in inner]
    for name in _OUTER:
        spec.delete(spec.geom(name))
    for i in range(n):
        for j in range(n):
            if i == 0 and j == 0:
                continue
            for name, size, pos in proto:
                spec.worldbody.add_geom(name=f"{name}_t{i}_{j}", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(size),
                                        pos=[pos[0] + TILE * i, pos[1] + TILE * j, pos[2]], material="wall")
    h = TILE / 2
    lo, hi = -h, -h + TILE * n
    for i in range(n + 1):  # vertical lines x = -15 + 30 i; doors on each row's corridor axis
        doors = [TILE * j for j in range(n)] if 0 < i < n else []
        _line_with_doors(spec, f"wall_x{i}", -h + TILE * i, lo, hi, doors, vertical=True)
    for j in range(n + 1):  # horizontal lines y = -15 + 30 j; doors at x = 30 i + LANE_X
        doors = [TILE * i + LANE_X for i in range(n)] if 0 < j < n else []
        _line_with_doors(spec, f"wall_y{j}", -h + TILE * j, lo, hi, doors, vertical=False)
    floor = spec.geom("floor")
    floor.size = [TILE * n / 2 + 0.5, TILE * n / 2 + 0.5, 0.5]
    floor.pos = [TILE * (n - 1) / 2, TILE * (n - 1) / 2, 0.0]


def build_office(spec: mujoco.MjSpec, seed, *, furniture_per_room=6, camera_height=None, tiles=1):
    """Add furniture and the indoor rover. Options: ``furniture_per_room`` (int, default 6),
    ``camera_height`` (m, default the indoor preset's 0.6), ``tiles`` (int n >= 1, default 1: an
    n x n tiled world, see the module docstring)."""
    if isinstance(tiles, bool) or not isinstance(tiles, (int, np.integer)) or not 1 <= tiles <= 16:
        raise ValueError(f"tiles: expected an integer in 1..16, got {tiles!r}")
    n = int(tiles)
    k = 0
    if n == 1:
        rng = np.random.default_rng(np.random.SeedSequence([seed, 7002]))
        k = _place_furniture(spec, rng, (0.0, 0.0), False, k, furniture_per_room)
    else:
        _tile_walls(spec, n)
        for i in range(n):
            for j in range(n):
                # Tile (i, j) has its own stream; the stream of tile (0, 0) is the untiled floor's.
                key = [seed, 7002] if i == j == 0 else [seed, 7002, i, j]
                rng = np.random.default_rng(np.random.SeedSequence(key))
                k = _place_furniture(spec, rng, (TILE * i, TILE * j), True, k, furniture_per_room)
    cfg = ROVER_PRESETS["indoor"]
    if camera_height is not None:
        cfg = dataclasses.replace(cfg, camera_height=float(camera_height))
    start = np.array([-13.0, 0.0, 0.0])
    add_rover(spec, cfg, start)
    h = TILE / 2
    meta = {"rover_config": cfg, "start_pose2d": start, "rooms": dict(ROOMS), "doors": np.array(DOORS, dtype=float),
            "bounds": (-h, -h + TILE * n, -h, -h + TILE * n)}
    if n > 1:
        meta["tiles"] = n
    return meta
