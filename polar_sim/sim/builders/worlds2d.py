"""``warehouse2d``: randomised warehouse worlds for the 2D lidar, with an exact SDF.

Every seed builds a different world; the same seed builds the same world, bit for bit. The hall's
interior is x in [0, Lx], y in [0, Ly] (``size=(Lx, Ly)``, metres); on its east side lies an
unfenced yard, x in [Lx, Lx + ``yard``]. The world holds:

- **outer walls** (20-30 cm thick) around the hall, with one or two 3-5 m doors in the east wall;
- an **open yard** outside those doors with nothing beyond it: from the yard, beams pointing away
  from the hall meet nothing within the lidar's range (an open area wider than the sensor's range);
- a **racking zone** (the west 45-60 % of the hall): long rows of solid shelving or of pallet
  racks (uprights every 2.2-2.8 m, loads in some bays, empty bays the lidar sees through),
  0.5-1.6 m deep, with 1.8-3.0 m aisles between them, aisles along the walls and, in most
  worlds, a cross aisle; the rows run east-west or north-south (seeded);
- a **partition zone** (the rest of the hall, past a 1.8-2.8 m main aisle): thin walls (5-15 cm
  thick, 2-5 m long, half of them with an L-shaped return), one or two **curved walls**
  (5-15 cm thick, radius 1.5-4 m, 60-180 deg), **crates** at random yaw;
- **pillars** (cylinders, 15-30 cm radius) on a structural grid wherever they fit, and bollards in
  the yard;
- **clutter**: ``clutter`` small objects (5-25 cm boxes and cylinders), in the open, beside shelf
  faces and walls, and in the yard.

Everything is solid from the floor up, at least 0.4 m tall, so a planar lidar at the indoor
rover's 0.35 m sees its exact outline and ``World.sdf`` in 2D is a closed form (rectangles and
discs). A curved wall is a chain of short boxes (chords of at most 0.2 m, mitred so that the
outer face is closed): the SDF is exact for that chain, which lies within 2 mm of the ideal arc.
Pieces keep 1 m from each other (clutter beside a face: 2-10 cm from it), so every aisle, door
and gap leaves the rover a 0.9 m wide passage and every region is reachable from the start.

The metadata (``World.meta``) describes the layout: ``regions`` (named rectangles for routes:
``aisle_k``, ``main_aisle``, ``partitions``, ``yard``), ``bounds``, ``hall``, ``corners`` (the
section's corners: convex box vertices on the boundary and the concave corners of the hall and the
L-shaped walls), ``features`` (arrays per kind) and ``layout`` (every box and disc), from which
:func:`layout_sdf` computes the same exact SDF without MuJoCo.
"""

from __future__ import annotations

import dataclasses
import numbers

import mujoco
import numpy as np

from polar_sim.sim.actors.robots import GROUP, ROVER_PRESETS, add_rover

__all__ = ["build_warehouse", "layout_sdf", "ARC_CHORD"]

#: Longest chord of a curved wall's boxes, metres.
ARC_CHORD = 0.2
_GAP = 1.0            # clearance between pieces, m (the rover needs 0.9 m)
_END = (1.8, 2.6)     # aisles along the walls and at the row ends, m
_AISLE = (1.8, 3.0)   # aisles between rows, m


@dataclasses.dataclass
class _Layout:
    """Boxes (cx, cy, hx, hy, yaw, hz, name, material, kind) and discs (cx, cy, r, hz, name, material,
    kind) placed so far; :meth:`sdf` is their exact 2D signed distance."""

    boxes: list = dataclasses.field(default_factory=list)
    discs: list = dataclasses.field(default_factory=list)

    def arrays(self):
        b = np.array([x[:5] for x in self.boxes], float).reshape(-1, 5)
        d = np.array([x[:3] for x in self.discs], float).reshape(-1, 3)
        return b, d

    def sdf(self, P):
        return layout_sdf(*self.arrays(), P)

    def box(self, cx, cy, hx, hy, yaw, hz, name, material, kind):
        self.boxes.append((float(cx), float(cy), float(hx), float(hy), float(yaw), float(hz), name, material, kind))

    def disc(self, cx, cy, r, hz, name, material, kind):
        self.discs.append((float(cx), float(cy), float(r), float(hz), name, material, kind))


def layout_sdf(boxes, discs, points):
    """Exact signed distance (n,) of a union of rectangles and discs at points (n, 2), metres.

    ``boxes`` (k, 5): centre x, y, half sizes hx, hy, yaw (rad); ``discs`` (m, 3): centre x, y,
    radius. Exact outside the shapes and inside any shape that overlaps no other (as
    ``World.sdf``); ``World.meta.layout`` holds a world's arrays.
    """
    P = np.asarray(points, float).reshape(-1, 2)
    boxes = np.asarray(boxes, float).reshape(-1, 5)
    discs = np.asarray(discs, float).reshape(-1, 3)
    out = np.full(len(P), np.inf)
    c, s = np.cos(boxes[:, 4]), np.sin(boxes[:, 4])
    for i in range(0, len(P), 2048):
        p = P[i : i + 2048]
        if len(boxes):
            rx = p[:, None, 0] - boxes[None, :, 0]
            ry = p[:, None, 1] - boxes[None, :, 1]
            qx = np.abs(rx * c + ry * s) - boxes[:, 2]
            qy = np.abs(-rx * s + ry * c) - boxes[:, 3]
            d = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0)
            out[i : i + 2048] = d.min(1)
        if len(discs):
            d = np.hypot(p[:, None, 0] - discs[:, 0], p[:, None, 1] - discs[:, 1]) - discs[:, 2]
            out[i : i + 2048] = np.minimum(out[i : i + 2048], d.min(1))
    return out


def _outline(boxes, discs, step=0.02):
    """Points every ``step`` m along the outlines of boxes (k, 5) and discs (m, 3)."""
    pts = []
    for cx, cy, hx, hy, yaw in boxes:
        nx, ny = max(2, int(np.ceil(2 * hx / step)) + 1), max(2, int(np.ceil(2 * hy / step)) + 1)
        u, v = np.linspace(-hx, hx, nx), np.linspace(-hy, hy, ny)
        loc = np.vstack([np.c_[u, np.full(nx, hy)], np.c_[u, np.full(nx, -hy)],
                         np.c_[np.full(ny, hx), v], np.c_[np.full(ny, -hx), v]])
        c, s = np.cos(yaw), np.sin(yaw)
        pts.append(loc @ np.array([[c, s], [-s, c]]) + (cx, cy))
    for cx, cy, r in discs:
        a = np.linspace(0, 2 * np.pi, max(12, int(np.ceil(2 * np.pi * r / step))), endpoint=False)
        pts.append(np.c_[cx + r * np.cos(a), cy + r * np.sin(a)])
    return np.vstack(pts) if pts else np.zeros((0, 2))


def _clearance(lay, boxes, discs, exclude=None):
    """Smallest distance (m) between candidate shapes and the layout (without its box number
    ``exclude``); -1 when they overlap."""
    boxes, discs = np.asarray(boxes, float).reshape(-1, 5), np.asarray(discs, float).reshape(-1, 3)
    b, c = lay.arrays()
    if exclude is not None:
        b = np.delete(b, exclude, axis=0)
    if not len(b) and not len(c):
        return np.inf
    d = float(layout_sdf(b, c, _outline(boxes, discs)).min())
    centres = np.vstack([b[:, :2], c[:, :2]])
    if d <= 0 or (layout_sdf(boxes, discs, centres) < 0).any():
        return -1.0
    return d


def _inside(boxes, discs, rect, margin=0.0):
    """True when every candidate shape lies inside ``rect`` (x0, x1, y0, y1) shrunk by ``margin``."""
    P = _outline(np.asarray(boxes, float).reshape(-1, 5), np.asarray(discs, float).reshape(-1, 3), step=0.1)
    x0, x1, y0, y1 = rect
    return bool(np.all((P[:, 0] >= x0 + margin) & (P[:, 0] <= x1 - margin)
                       & (P[:, 1] >= y0 + margin) & (P[:, 1] <= y1 - margin)))


def _arc_boxes(cx, cy, radius, a0, sweep, half_t):
    """Mitred chord boxes (n, 5) of a curved wall along the arc from angle a0 over ``sweep``."""
    n = max(2, int(np.ceil(sweep * radius / ARC_CHORD)))
    da = sweep / n
    ext = half_t * np.tan(da / 2)  # lengthen each chord so the outer faces meet at the mitre
    a = a0 + (np.arange(n) + 0.5) * da
    # Vertices just outside the arc and chord midpoints just inside, by half the sagitta each.
    rv = 2 * radius / (1 + np.cos(da / 2))
    half_len = rv * np.sin(da / 2) + ext
    mid = rv * np.cos(da / 2)
    return np.column_stack([cx + mid * np.cos(a), cy + mid * np.sin(a), np.full(n, half_len),
                            np.full(n, half_t), a + np.pi / 2])


def _segment_box(p0, p1, half_t, ext0=0.0, ext1=0.0):
    """Box (5,) of a wall along p0 -> p1, lengthened by ext0 / ext1 at the ends."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    a, b = p0 - ext0 * d, p1 + ext1 * d
    c = 0.5 * (a + b)
    return np.array([c[0], c[1], 0.5 * np.linalg.norm(b - a), half_t, np.arctan2(d[1], d[0])])


def _rows(lay, rng, zone, along):
    """Shelf rows and racks in ``zone`` (x0, x1, y0, y1), whose east side opens onto the main
    aisle; rows run along ``along`` ("x" or "y"). Returns the aisle rectangles and the row
    footprints (x0, x1, y0, y1)."""
    x0, x1, y0, y1 = zone
    (u0, u1), (v0, v1) = ((x0, x1), (y0, y1)) if along == "x" else ((y0, y1), (x0, x1))

    def world(u, v):  # local (u along, v across) -> world (x, y)
        return (u, v) if along == "x" else (v, u)

    def rect(ua, ub, va, vb):  # local rectangle -> world (x0, x1, y0, y1)
        return (ua, ub, va, vb) if along == "x" else (va, vb, ua, ub)

    lo_u = u0 + rng.uniform(*_END)
    hi_u = u1 if (along == "x") else u1 - rng.uniform(*_END)
    cross = None
    if rng.random() < 0.7:
        w = rng.uniform(1.8, 2.4)
        c = rng.uniform(lo_u + 0.35 * (hi_u - lo_u), lo_u + 0.65 * (hi_u - lo_u))
        cross = (c - w / 2, c + w / 2)
    segs = [(lo_u, hi_u)] if cross is None else [(lo_u, cross[0]), (cross[1], hi_u)]
    aisles, rows = [], []
    v = v0 + rng.uniform(*_END)
    v_prev = v0
    k = 0
    while True:
        depth = rng.uniform(0.5, 0.9) if rng.random() < 0.5 else rng.uniform(1.0, 1.6)
        margin = _END[0] if along == "x" else 0.0  # rows along y end at the open east side
        if v + depth > v1 - margin:
            break
        aisles.append(rect(lo_u if along == "y" else u0 + 0.3, hi_u, v_prev, v))
        rack = rng.random() < 0.35
        for j, (ua, ub) in enumerate(segs):
            if ub - ua < 2.0:
                continue
            if not rack:
                cx, cy = world(0.5 * (ua + ub), v + depth / 2)
                hx, hy = (0.5 * (ub - ua), depth / 2) if along == "x" else (depth / 2, 0.5 * (ub - ua))
                lay.box(cx, cy, hx, hy, 0.0, 1.1, f"shelf_{k}_{j}", "shelf", "shelf")
                continue
            s = rng.uniform(0.08, 0.12)
            n_bays = max(1, int(round((ub - ua) / rng.uniform(2.2, 2.8))))
            us = np.linspace(ua + s / 2, ub - s / 2, n_bays + 1)
            for i, u in enumerate(us):
                for side, vv in (("a", v + s / 2), ("b", v + depth - s / 2)):
                    cx, cy = world(u, vv)
                    lay.box(cx, cy, s / 2, s / 2, 0.0, 1.1, f"rack_{k}_{j}_{i}{side}", "rack", "upright")
            for i in range(n_bays):
                if rng.random() < 0.55:
                    g = rng.uniform(0.05, 0.15)
                    la, lb = us[i] + s / 2 + g, us[i + 1] - s / 2 - g
                    cx, cy = world(0.5 * (la + lb), v + depth / 2)
                    h = (0.5 * (lb - la), depth / 2 - 0.05)
                    hx, hy = h if along == "x" else h[::-1]
                    lay.box(cx, cy, hx, hy, 0.0, rng.uniform(0.3, 0.7), f"load_{k}_{j}_{i}", "load", "load")
        rows.append(rect(lo_u, hi_u, v, v + depth))
        v_prev = v + depth
        v = v_prev + rng.uniform(*_AISLE)
        k += 1
    if v1 - v_prev >= _AISLE[0]:  # rows along y may end next to the main aisle
        aisles.append(rect(lo_u if along == "y" else u0 + 0.3, hi_u, v_prev, v1))
    if cross is not None:
        aisles.append(rect(cross[0], cross[1], v0 + 0.3, v1 - 0.3))
    return aisles, rows


def _place(lay, rng, sample, rect, *, tries=200, gap=_GAP):
    """Draw candidates ``sample() -> (boxes, discs)`` until one lies inside ``rect`` with at least
    ``gap`` metres to the layout; returns it or None."""
    for _ in range(tries):
        boxes, discs = sample()
        if _inside(boxes, discs, rect) and _clearance(lay, boxes, discs) >= gap:
            return boxes, discs
    return None


def _check_options(size, yard, clutter, lidar_beams, lidar_range, camera_height):
    if isinstance(size, (str, bytes)) or not hasattr(size, "__len__") or len(size) != 2:
        raise ValueError(f"size: expected (Lx, Ly) in metres, each in [16, 80], got {size!r}")
    for v in size:
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not 16 <= float(v) <= 80:
            raise ValueError(f"size: expected (Lx, Ly) in metres, each in [16, 80], got {size!r}")
    if isinstance(yard, bool) or not isinstance(yard, numbers.Real) or not 4 <= float(yard) <= 40:
        raise ValueError(f"yard: expected a depth in metres in [4, 40], got {yard!r}")
    for name, v, lo, hi in (("clutter", clutter, 0, 200), ("lidar_beams", lidar_beams, 16, 4000)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
            raise ValueError(f"{name}: expected an integer in {lo}..{hi}, got {v!r}")
    if isinstance(lidar_range, bool) or not isinstance(lidar_range, numbers.Real) or not 1 <= lidar_range <= 100:
        raise ValueError(f"lidar_range: expected a maximum range in metres in [1, 100], got {lidar_range!r}")
    if camera_height is not None and (isinstance(camera_height, bool) or not isinstance(camera_height, numbers.Real)
                                      or not 0.2 <= camera_height <= 2.0):
        raise ValueError(f"camera_height: expected metres in [0.2, 2.0] or None, got {camera_height!r}")


def build_warehouse(spec: mujoco.MjSpec, seed, *, size=(24.0, 18.0), yard=8.0, clutter=15, lidar_beams=1081,
                    lidar_range=30.0, camera_height=None):
    """Add a seeded warehouse and the indoor rover (see the module docstring).

    Options: ``size`` (Lx, Ly) of the hall's interior (m, each in [16, 80]; default (24, 18)),
    ``yard`` depth of the open yard the routes use (m, [4, 40]; default 8), ``clutter`` small
    objects (0..200; default 15), ``lidar_beams`` of the 2D lidar (270 deg; default 1081),
    ``lidar_range`` its maximum range (m; default 30, as office2d), ``camera_height`` (m; default
    the indoor preset's 0.6).
    """
    _check_options(size, yard, clutter, lidar_beams, lidar_range, camera_height)
    # One generator drives every step below, in this order: the order is the layout's identity.
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7004]))
    Lx, Ly, yard = float(size[0]), float(size[1]), float(yard)
    lay = _Layout()
    t = _outer_walls(lay, rng, Lx, Ly)
    # Zones: racking in the west, a main aisle, partitions in the east.
    xr = rng.uniform(0.45, 0.6) * Lx
    xp = xr + rng.uniform(1.8, 2.8)
    along = "x" if rng.random() < 0.5 else "y"
    aisles, rows = _rows(lay, rng, (0.0, xr, 0.0, Ly), along)
    hall, part = (0.0, Lx, 0.0, Ly), (xp, Lx, 0.0, Ly)
    yard_rect = (Lx + 2 * t, Lx + 2 * t + yard, 0.0, Ly)
    feats = {"arcs": _arc_walls(lay, rng, part)}
    feats["thin_walls"], inner_corners = _thin_walls(lay, rng, part)
    feats["crates"] = _crates(lay, rng, part, yard_rect)
    feats["pillars"] = _pillars(lay, rng, hall, part)
    feats["bollards"] = _bollards(lay, rng, yard_rect)
    feats["clutter"] = _clutter(lay, rng, int(clutter), hall, part, yard_rect)
    start = _start_pose(lay, rng, part, seed)
    _add_geoms(spec, lay)
    cfg = _add_floor_and_rover(spec, start, Lx + yard, Ly, lidar_beams, lidar_range, camera_height)
    boxes, discs = lay.arrays()
    regions = {f"aisle_{k}": a for k, a in enumerate(aisles)}
    regions.update(main_aisle=(xr + 0.2, xp - 0.2, 0.3, Ly - 0.3), partitions=part,
                   yard=(yard_rect[0] + 0.5, yard_rect[1] - 0.5, 0.5, Ly - 0.5))
    concave = [(0.0, 0.0), (0.0, Ly), (Lx, 0.0), (Lx, Ly)] + inner_corners  # the hall's and the L returns'
    return {"rover_config": cfg, "start_pose2d": start, "regions": regions,
            "bounds": (-2 * t - 0.5, yard_rect[1] + 0.5, -2 * t - 0.5, Ly + 2 * t + 0.5),
            "hall": hall, "yard": yard_rect, "rows_along": along,
            "corners": _corners(lay, np.array(concave)),
            "layout": {"boxes": boxes, "discs": discs, "names": [b[6] for b in lay.boxes] + [d[4] for d in lay.discs]},
            "features": _features(lay, rows, feats)}


def _outer_walls(lay, rng, Lx, Ly):
    """The outer walls, outside the interior [0, Lx] x [0, Ly], with one or two doors in the east
    wall onto the yard. Returns the walls' half thickness (m)."""
    t = rng.uniform(0.1, 0.15)
    lay.box(Lx / 2, -t, Lx / 2 + 2 * t, t, 0.0, 1.25, "wall_south", "wall", "wall")
    lay.box(Lx / 2, Ly + t, Lx / 2 + 2 * t, t, 0.0, 1.25, "wall_north", "wall", "wall")
    lay.box(-t, Ly / 2, t, Ly / 2, 0.0, 1.25, "wall_west", "wall", "wall")
    n_doors = 1 + int(rng.random() < 0.5)
    widths = rng.uniform(3.0, 5.0, n_doors)
    slots = np.linspace(0, Ly, n_doors + 1)
    cuts = [0.0]
    for k in range(n_doors):
        c = rng.uniform(slots[k] + widths[k] / 2 + 1.0, slots[k + 1] - widths[k] / 2 - 1.0)
        cuts += [c - widths[k] / 2, c + widths[k] / 2]
    cuts.append(Ly)
    for k, (a, b) in enumerate(zip(cuts[::2], cuts[1::2])):
        lay.box(Lx + t, (a + b) / 2, t, (b - a) / 2, 0.0, 1.25, f"wall_east_{k}", "wall", "wall")
    return t


def _arc_walls(lay, rng, part):
    """One or two curved thin walls in the partition zone; returns their (cx, cy, r, a0, a1, thickness)."""
    out = []
    for k in range(int(rng.integers(1, 3))):
        def arc():
            r, sweep, ht = rng.uniform(1.5, 4.0), np.radians(rng.uniform(60, 180)), rng.uniform(0.025, 0.075)
            cx, cy, a0 = rng.uniform(part[0], part[1]), rng.uniform(part[2], part[3]), rng.uniform(0, 2 * np.pi)
            arc.params = (cx, cy, r, a0, a0 + sweep, 2 * ht)
            return _arc_boxes(cx, cy, r, a0, sweep, ht), np.zeros((0, 3))
        got = _place(lay, rng, arc, part)
        if got is not None:
            for i, b in enumerate(got[0]):
                lay.box(*b, 1.25, f"arc_{k}_{i}", "thin_wall", "arc")
            out.append(arc.params)
    return out


def _thin_walls(lay, rng, part):
    """Two to four straight thin walls in the partition zone, half of them with an L return.
    Returns their segments (x0, y0, x1, y1, thickness) and the L returns' inner corners."""
    segments, inner = [], []
    for k in range(int(rng.integers(2, 5))):
        def thin():
            ht, L = rng.uniform(0.025, 0.075), rng.uniform(2.0, 5.0)
            a = rng.choice([0.0, np.pi / 2]) if rng.random() < 0.6 else rng.uniform(0, np.pi)
            p0 = np.array([rng.uniform(part[0], part[1]), rng.uniform(part[2], part[3])])
            d = np.array([np.cos(a), np.sin(a)])
            p1 = p0 + L * d
            if rng.random() < 0.5:
                n = np.array([-d[1], d[0]]) * rng.choice([-1.0, 1.0])
                p2 = p1 + rng.uniform(1.0, 2.5) * n
                thin.segs = [(p0, p1, ht), (p1, p2, ht)]
                thin.inner = p1 - ht * d + ht * n
                return np.array([_segment_box(p0, p1, ht, 0, ht), _segment_box(p1, p2, ht, ht, 0)]), np.zeros((0, 3))
            thin.segs, thin.inner = [(p0, p1, ht)], None
            return _segment_box(p0, p1, ht)[None], np.zeros((0, 3))
        got = _place(lay, rng, thin, part)
        if got is not None:
            for i, b in enumerate(got[0]):
                lay.box(*b, 1.25, f"thin_wall_{k}_{i}", "thin_wall", "thin_wall")
            segments += [(*p, *q, 2 * h) for p, q, h in thin.segs]
            if thin.inner is not None:
                inner.append(tuple(thin.inner))
    return segments, inner


def _crates(lay, rng, part, yard_rect):
    """Crates at random yaw, in the partition zone and in the yard; returns their (x, y, hx, hy, yaw)."""
    out = []
    for where, n in ((part, int(rng.integers(4, 9))), (yard_rect, int(rng.integers(1, 4)))):
        for _ in range(n):
            def crate():
                b = np.array([rng.uniform(where[0], where[1]), rng.uniform(where[2], where[3]),
                              rng.uniform(0.2, 0.6), rng.uniform(0.2, 0.6), rng.uniform(0, np.pi)])
                return b[None], np.zeros((0, 3))
            got = _place(lay, rng, crate, where)
            if got is not None:
                lay.box(*got[0][0], rng.uniform(0.3, 0.6), f"crate_{len(out)}", "crate", "crate")
                out.append(tuple(got[0][0]))
    return out


def _pillars(lay, rng, hall, part):
    """Pillars on a structural grid wherever they fit, and at least two; returns their (x, y, r)."""
    out = []
    pitch, pr = rng.uniform(6.0, 9.0), rng.uniform(0.15, 0.3)
    ox, oy = rng.uniform(0, pitch, 2)
    for x in np.arange(ox, hall[1], pitch):
        for y in np.arange(oy, hall[3], pitch):
            disc = np.array([[x, y, pr]])
            if _inside(np.zeros((0, 5)), disc, hall, 1.0) and _clearance(lay, np.zeros((0, 5)), disc) >= _GAP:
                lay.disc(x, y, pr, 1.5, f"pillar_{len(out)}", "pillar", "pillar")
                out.append((x, y, pr))
    while len(out) < 2:  # a grid that found no room: free-standing pillars
        got = _place(lay, rng, lambda: (np.zeros((0, 5)), np.array([[rng.uniform(part[0], part[1]),
                     rng.uniform(part[2], part[3]), pr]])), part, tries=500)
        if got is None:  # pragma: no cover - the partition zone always has room
            break
        lay.disc(*got[1][0], 1.5, f"pillar_{len(out)}", "pillar", "pillar")
        out.append(tuple(got[1][0]))
    return out


def _bollards(lay, rng, yard_rect):
    """Two to four bollards in the yard; returns their (x, y, r)."""
    out = []
    for _ in range(int(rng.integers(2, 5))):
        got = _place(lay, rng, lambda: (np.zeros((0, 5)), np.array([[rng.uniform(*yard_rect[:2]),
                     rng.uniform(*yard_rect[2:]), rng.uniform(0.08, 0.15)]])), yard_rect)
        if got is not None:
            lay.disc(*got[1][0], 0.45, f"bollard_{len(out)}", "pillar", "bollard")
            out.append(tuple(got[1][0]))
    return out


def _clutter(lay, rng, n, hall, part, yard_rect):
    """``n`` small objects, each beside a shelf face or wall (2-10 cm from it), in the open, or in
    the yard (200 tries each). Returns how many were placed."""
    faces = [b for b in lay.boxes if b[8] in ("shelf", "wall", "thin_wall")]
    placed = 0
    for _ in range(n):
        mode = rng.choice(3, p=[0.3, 0.5, 0.2])
        for _attempt in range(200):
            cyl = rng.random() < 0.5
            h = rng.uniform(0.025, 0.125, 2)
            if mode == 0:
                f = faces[rng.integers(len(faces))]
                side = rng.choice([-1.0, 1.0])
                u = rng.uniform(-f[2], f[2])
                off = f[3] + rng.uniform(0.02, 0.1) + (h[0] if cyl else h[1])
                c, s = np.cos(f[4]), np.sin(f[4])
                x, y = f[0] + u * c - side * off * s, f[1] + u * s + side * off * c
                yaw = f[4]
            else:
                r = part if mode == 1 else yard_rect
                x, y, yaw = rng.uniform(r[0], r[1]), rng.uniform(r[2], r[3]), rng.uniform(0, np.pi)
            boxes = np.zeros((0, 5)) if cyl else np.array([[x, y, h[0], h[1], yaw]])
            discs = np.array([[x, y, h[0]]]) if cyl else np.zeros((0, 3))
            rect = hall if mode == 0 else (part if mode == 1 else yard_rect)
            if not _inside(boxes, discs, rect, 0.0 if mode == 0 else 0.5):
                continue
            host = lay.boxes.index(f) if mode == 0 else None
            if mode == 0:  # 2-10 cm from its host face, 1 m from everything else
                dh = layout_sdf(np.array(f[:5])[None], np.zeros((0, 3)), _outline(boxes, discs)).min()
                if not 0.015 <= dh <= 0.12:
                    continue
            if _clearance(lay, boxes, discs, exclude=host) < _GAP:
                continue
            hz = rng.uniform(0.2, 0.5)
            if cyl:
                lay.disc(x, y, h[0], hz, f"clutter_{placed}", "clutter", "clutter")
            else:
                lay.box(x, y, h[0], h[1], yaw, hz, f"clutter_{placed}", "clutter", "clutter")
            placed += 1
            break
    return placed


def _start_pose(lay, rng, part, seed):
    """The start (x, y, yaw): a free spot in the partition zone, 1 m inside it."""
    for _ in range(2000):
        xy = np.array([rng.uniform(part[0] + 1, part[1] - 1), rng.uniform(part[2] + 1, part[3] - 1)])
        if lay.sdf(xy[None])[0] >= _GAP:
            break
    else:  # pragma: no cover - the partition zone always has room
        raise ValueError(f"warehouse2d: seed {seed} left no free start; change the options")
    return np.array([xy[0], xy[1], rng.uniform(-np.pi, np.pi)])


def _add_floor_and_rover(spec, start, extent_x, extent_y, lidar_beams, lidar_range, camera_height):
    """Size the floor to the hall and yard (``extent_x`` x ``extent_y``, m, from the origin), add
    the indoor rover at ``start`` with its lidar's beams and range; returns the rover's configuration."""
    floor = spec.geom("floor")
    floor.size = [extent_x / 2 + 40.0, extent_y / 2 + 40.0, 0.5]
    floor.pos = [extent_x / 2, extent_y / 2, 0.0]
    cfg = ROVER_PRESETS["indoor"]
    if camera_height is not None:
        cfg = dataclasses.replace(cfg, camera_height=float(camera_height))
    add_rover(spec, cfg, start, lidar_beams=int(lidar_beams))
    for txt in spec.texts:
        if txt.name == "sensor:lidar":
            txt.data = txt.data.replace("max=30", f"max={float(lidar_range):g}")
    return cfg


def _features(lay, rows, feats):
    """The ``features`` meta entry: each kind of feature as a float array (k, columns)."""
    def rows_of(key, cols):
        return np.array(feats[key], float).reshape(-1, cols)
    return {"shelf_rows": np.array(rows, float).reshape(-1, 4),
            "racks": sum(1 for b in lay.boxes if b[8] == "upright"),
            "thin_walls": rows_of("thin_walls", 5), "arcs": rows_of("arcs", 6), "crates": rows_of("crates", 5),
            "pillars": rows_of("pillars", 3), "bollards": rows_of("bollards", 3), "clutter": feats["clutter"]}


def _corners(lay, concave):
    """Corners (k, 2) of the section: box vertices outside every other shape (so not the joints
    of a curved wall nor a vertex buried in an L), plus the given concave corners."""
    boxes, discs = lay.arrays()
    out = [concave]
    for i, (cx, cy, hx, hy, yaw) in enumerate(boxes):
        c, s = np.cos(yaw), np.sin(yaw)
        v = np.array([[hx, hy], [hx, -hy], [-hx, hy], [-hx, -hy]]) @ np.array([[c, s], [-s, c]]) + (cx, cy)
        others = np.delete(boxes, i, axis=0)
        keep = layout_sdf(others, discs, v) > 1e-6
        out.append(v[keep])
    return np.vstack(out)


def _add_geoms(spec, lay):
    for cx, cy, hx, hy, yaw, hz, name, material, _ in lay.boxes:
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, hz], pos=[cx, cy, hz],
                                quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], material=material,
                                group=GROUP["static"])
    for cx, cy, r, hz, name, material, _ in lay.discs:
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[r, hz, 0], pos=[cx, cy, hz],
                                material=material, group=GROUP["static"])
