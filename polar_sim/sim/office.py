"""``office2d``: seeded furniture in the hand-written lab floor of ``scenes/office2d.xml``.

Furniture is solid from the floor up (desks as closed cabinets, shelves, round tables, pillars),
so a planar lidar at any height below 0.7 m sees its exact outline and ``World.sdf`` in 2D is
a closed form. Nothing is placed in the corridor or within 1.2 m of a door.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from polar_sim.sim.robots import GROUP, ROVER_PRESETS, add_rover

__all__ = ["build_office", "ROOMS", "DOORS"]

#: Rooms as (x0, x1, y0, y1) interiors, metres.
ROOMS = {
    "office_w": (-14.9, -5.1, 1.6, 14.9),
    "office_c": (-4.9, 4.9, 1.6, 14.9),
    "office_e": (5.1, 14.9, 1.6, 14.9),
    "lab": (-14.9, 4.9, -14.9, -1.6),
    "store": (5.1, 14.9, -14.9, -1.6),
}
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


def build_office(spec: mujoco.MjSpec, seed, *, furniture_per_room=6, camera_height=None):
    """Add furniture and the indoor rover. Options: ``furniture_per_room`` (int, default 6),
    ``camera_height`` (m, default the indoor preset's 0.6)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7002]))
    placed = []  # (x, y, radius) footprints, for spacing
    doors = np.array(DOORS, dtype=float)
    k = 0
    for room, (x0, x1, y0, y1) in ROOMS.items():
        for _ in range(int(furniture_per_room)):
            for _attempt in range(50):
                kind, shape, size = _furniture(rng)
                rad = float(np.hypot(size[0], size[1]) if shape == "box" else size[0])
                along_wall = shape == "box" and rng.random() < 0.6
                yaw = float(rng.choice([0.0, np.pi / 2]) if along_wall else rng.uniform(0, np.pi))
                x = rng.uniform(x0 + rad, x1 - rad)
                y = rng.uniform(y0 + rad, y1 - rad)
                if np.min(np.hypot(doors[:, 0] - x, doors[:, 1] - y)) < rad + 1.2:
                    continue
                # Keep 0.9 m between pieces so the rover can pass between most of them.
                if any(np.hypot(px - x, py - y) < rad + pr + 0.9 for px, py, pr in placed):
                    continue
                placed.append((x, y, rad))
                colour = _COLOURS[rng.integers(len(_COLOURS))]
                if shape == "box":
                    spec.worldbody.add_geom(name=f"furniture_{k}_{kind}", type=mujoco.mjtGeom.mjGEOM_BOX,
                                            size=list(size), pos=[x, y, size[2]], rgba=list(colour),
                                            quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)],
                                            group=GROUP["static"])
                else:
                    spec.worldbody.add_geom(name=f"furniture_{k}_{kind}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                                            size=[size[0], size[1], 0], pos=[x, y, size[1]], rgba=list(colour),
                                            group=GROUP["static"])
                k += 1
                break
    cfg = ROVER_PRESETS["indoor"]
    if camera_height is not None:
        cfg = dataclasses.replace(cfg, camera_height=float(camera_height))
    start = np.array([-13.0, 0.0, 0.0])
    add_rover(spec, cfg, start)
    return {"rover_config": cfg, "start_pose2d": start, "rooms": dict(ROOMS), "doors": doors,
            "bounds": (-15.0, 15.0, -15.0, 15.0)}
