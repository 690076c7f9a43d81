"""Outdoor rover scenes: seeded heightfield terrain, a closed route, ground zones and obstacles.

One builder serves ``rover_terrain`` (hills) and ``rover_flat`` (zero heights). The visible
ground is a set of textured mesh tiles, one material per ground zone; collisions use a hidden
heightfield with the same heights (a mesh collides through its convex hull, which would be wrong
for terrain), and the sensors' rays hit the meshes (about 10x faster than a heightfield).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from polar_sim.sim.builders.appearance_textures import ground_family_texture, sky_cube
from polar_sim.sim.builders.rover_appearance import resolve_appearance
from polar_sim.sim.builders.textures import GROUND_TYPES, OBSTACLE_COLOURS, ground_texture, obstacle_texture

__all__ = ["TerrainGrid", "make_route", "build_rover_scene", "build_rover_terrain", "build_rover_flat"]


@dataclasses.dataclass(frozen=True)
class TerrainGrid:
    """A height map on a regular grid, triangulated exactly as the rendered and ray-cast meshes.

    Vertex (i, j) sits at ``(x0 + j*cell, y0 + i*cell, heights[i, j])``. Each cell is split along
    the diagonal from (i, j) to (i+1, j+1).
    """

    x0: float
    y0: float
    cell: float
    heights: np.ndarray  # (ny, nx) metres

    @property
    def shape(self):
        return self.heights.shape

    @property
    def extent(self):
        ny, nx = self.heights.shape
        return (self.x0, self.x0 + (nx - 1) * self.cell, self.y0, self.y0 + (ny - 1) * self.cell)

    def vertices(self):
        ny, nx = self.heights.shape
        xs = self.x0 + self.cell * np.arange(nx)
        ys = self.y0 + self.cell * np.arange(ny)
        X, Y = np.meshgrid(xs, ys)
        return np.stack([X, Y, self.heights], axis=-1).reshape(-1, 3)

    def faces(self, i0=0, i1=None, j0=0, j1=None):
        """Triangles (k, 3) of the cells in rows [i0, i1) and columns [j0, j1), global vertex ids."""
        ny, nx = self.heights.shape
        i1 = ny - 1 if i1 is None else i1
        j1 = nx - 1 if j1 is None else j1
        I, J = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1), indexing="ij")
        a = (I * nx + J).ravel()
        b, c, d = a + 1, a + nx + 1, a + nx
        return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])

    def height(self, x, y):
        """Exact height (m) of the triangulated surface at points x, y (arrays of equal shape)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        ny, nx = self.heights.shape
        u = np.clip((x - self.x0) / self.cell, 0, nx - 1 - 1e-9)
        v = np.clip((y - self.y0) / self.cell, 0, ny - 1 - 1e-9)
        j = np.floor(u).astype(int)
        i = np.floor(v).astype(int)
        fu, fv = u - j, v - i
        H = self.heights
        h00, h01, h11, h10 = H[i, j], H[i, j + 1], H[i + 1, j + 1], H[i + 1, j]
        # Lower triangle (a, b, c) when fu >= fv, upper (a, c, d) otherwise.
        lower = fu >= fv
        return np.where(lower, h00 + fu * (h01 - h00) + fv * (h11 - h01),
                        h00 + fv * (h10 - h00) + fu * (h11 - h10))

    def normal(self, x, y):
        """Unit up-facing normal (3,) of the triangle under a point."""
        e = 1e-4 * self.cell
        hx = (self.height(x + e, y) - self.height(x - e, y)) / (2 * e)
        hy = (self.height(x, y + e) - self.height(x, y - e)) / (2 * e)
        n = np.array([-hx, -hy, 1.0])
        return n / np.linalg.norm(n)


def _smooth_heights(rng, n, cell, amplitude, max_slope=0.10):
    """Sum of random low-frequency sinusoids: hills 40-120 m long, at most ``amplitude`` high
    and ``max_slope`` steep (rise over run), like a gently rolling rural road."""
    if amplitude == 0:
        return np.zeros((n, n))
    xs = cell * np.arange(n)
    X, Y = np.meshgrid(xs, xs)
    Z = np.zeros((n, n))
    for _ in range(8):
        wavelength = rng.uniform(40.0, 120.0)
        ang = rng.uniform(0, np.pi)
        k = 2 * np.pi / wavelength
        phase = rng.uniform(0, 2 * np.pi)
        Z += rng.uniform(0.4, 1.0) * np.sin(k * (np.cos(ang) * X + np.sin(ang) * Y) + phase)
    Z *= amplitude / (np.abs(Z).max() + 1e-9)
    gy, gx = np.gradient(Z, cell)
    Z *= min(1.0, max_slope / np.hypot(gx, gy).max())
    return Z - Z.mean()


def make_route(rng, radius=75.0, spacing=1.0):
    """A closed, smooth loop around the origin, resampled every ``spacing`` metres of arc.

    Returns (n, 2) waypoints in metres; consecutive points are ``spacing`` apart and the last point
    connects back to the first.
    """
    a2, a3 = rng.uniform(0.04, 0.12, 2)
    p2, p3 = rng.uniform(0, 2 * np.pi, 2)
    phi = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    r = radius * (1 + a2 * np.sin(2 * phi + p2) + a3 * np.sin(3 * phi + p3))
    pts = np.stack([r * np.cos(phi), r * np.sin(phi)], 1)
    seg = np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    closed = np.vstack([pts, pts[:1]])
    n = int(s[-1] // spacing)
    t = np.linspace(0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], 1)


def _add_texture(spec, name, img):
    tex = spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D,
                           width=img.shape[1], height=img.shape[0], nchannel=3)
    tex.data = np.ascontiguousarray(img).tobytes()
    return tex


def build_rover_scene(spec: mujoco.MjSpec, seed: int, *, flat: bool, rover: str = "car",
                      camera_height=None, camera_fovy=None, appearance=None):
    """Fill a base rover spec with seeded terrain, route, zones, obstacles and the rover.

    Returns the scene metadata: ``route`` (n, 2), ``zones`` (the ground type or family of each zone,
    in route order), ``zone_of_route`` (n,) zone index per waypoint, ``terrain``
    (:class:`TerrainGrid`), ``start_pose2d``, ``appearance`` (the resolved spec, None by default;
    see :mod:`polar_sim.sim.builders.rover_appearance`).
    """
    from polar_sim.sim.actors.robots import ROVER_PRESETS

    look = resolve_appearance(appearance, seed)  # validated before anything is built
    if rover not in ROVER_PRESETS:
        raise ValueError(f"rover: unknown preset {rover!r}; expected one of {sorted(ROVER_PRESETS)}")
    # One generator drives the terrain, the route, the zones' textures and the obstacles, in this order.
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7001]))
    cell, n = 2.0, 111  # 220 m x 220 m terrain
    half = cell * (n - 1) / 2
    heights = _smooth_heights(rng, n, cell, 0.0 if flat else 3.0)
    grid = TerrainGrid(-half, -half, cell, heights)
    route = make_route(rng)
    zones, materials, repeat = _ground_materials(spec, rng, look)
    zone_of_route = (np.arange(len(route)) * len(zones) // len(route)).astype(int)
    if look is not None:
        _apply_sky_and_light(spec, look)
    _ground_tiles(spec, grid, route, zone_of_route, materials, repeat)
    _collision_ground(spec, grid, flat)
    _obstacles(spec, rng, grid, route)
    cfg, start = _rover_at_start(spec, grid, route, ROVER_PRESETS[rover], camera_height, camera_fovy)
    return {
        "route": route,
        "zones": zones,
        "zone_of_route": zone_of_route,
        "terrain": grid,
        "start_pose2d": np.array(start),
        "rover_config": cfg,
        "appearance": look,
    }


def _ground_materials(spec, rng, look):
    """The ground zones' textures and materials: at least 3 appearances, order seeded, or the
    appearance's families. Returns (zones, material names, texture repeat in m per zone).

    The default textures are drawn even under another appearance, so that the obstacles (drawn
    next from the same stream) do not depend on the appearance."""
    zones = list(rng.permutation(GROUND_TYPES))
    textures = [ground_texture(kind, rng) for kind in zones]
    materials, repeat = [f"ground_{kind}" for kind in zones], [4.0] * len(zones)
    if look is not None and "ground" in look:
        zones = [z["family"] for z in look["ground"]]
        opts = [{k: v for k, v in z.items() if k not in ("family", "scale_m")} for z in look["ground"]]
        textures = [ground_family_texture(z, np.random.default_rng(np.random.SeedSequence([look["texture_seed"], k])), **o)
                    for k, (z, o) in enumerate(zip(zones, opts))]
        materials = [f"ground_zone{k}" for k in range(len(zones))]
        repeat = [z["scale_m"] for z in look["ground"]]
    for name, img in zip(materials, textures):
        _add_texture(spec, name, img)
        mat = spec.add_material(name=name, specular=0.05, shininess=0.05)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
    return zones, materials, repeat


def _ground_tiles(spec, grid, route, zone_of_route, materials, repeat, tile=10):
    """The visible ground: meshes of ``tile`` x ``tile`` cells, each in the zone of its nearest
    route point (a contiguous arc of the route)."""
    from polar_sim.sim.actors.robots import GROUP

    verts = grid.vertices()
    n = grid.heights.shape[0]
    for i0 in range(0, n - 1, tile):
        for j0 in range(0, n - 1, tile):
            i1, j1 = min(i0 + tile, n - 1), min(j0 + tile, n - 1)
            F = grid.faces(i0, i1, j0, j1)
            used = np.unique(F)
            remap = np.full(len(verts), -1)
            remap[used] = np.arange(len(used))
            V = verts[used]
            k = zone_of_route[np.argmin(np.linalg.norm(route - V[:, :2].mean(0), axis=1))]
            name = f"ground_tile_{i0}_{j0}"
            mesh = spec.add_mesh(name=name)
            # Static visual mesh: its inertia is unused, and a flat tile has no volume.
            mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
            mesh.uservert = V.ravel().tolist()
            mesh.userface = remap[F].ravel().tolist()
            # 4 m texture repeat by default: gravel stones of 2-6 texels come out 1.5-5 cm large.
            mesh.usertexcoord = (V[:, :2] / repeat[k]).ravel().tolist()
            spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name,
                                    material=materials[k], contype=0, conaffinity=0,
                                    group=GROUP["ground"])


def _collision_ground(spec, grid, flat):
    """The collision ground: a hidden plane when flat, else a heightfield, under the visible meshes."""
    from polar_sim.sim.actors.robots import GROUP

    heights = grid.heights
    n = heights.shape[0]
    half = grid.cell * (n - 1) / 2
    if flat:
        spec.worldbody.add_geom(name="ground_collision", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                size=[half, half, 1.0], group=GROUP["collision"], rgba=[0, 0, 0, 0],
                                friction=[1.0, 0.01, 0.001])
        return
    zmin, zmax = float(heights.min()), float(heights.max())
    hf = spec.add_hfield(name="terrain", nrow=n, ncol=n, size=[half, half, zmax - zmin, 1.0])
    hf.userdata = ((heights - zmin) / (zmax - zmin)).ravel().tolist()
    spec.worldbody.add_geom(name="ground_collision", type=mujoco.mjtGeom.mjGEOM_HFIELD,
                            hfieldname="terrain", pos=[0, 0, zmin], group=GROUP["collision"],
                            rgba=[0, 0, 0, 0], friction=[1.0, 0.01, 0.001])


def _obstacles(spec, rng, grid, route, n_obst=60):
    """``n_obst`` obstacles 5.5-10 m beside the route: boxes, walls and poles, in colours unlike
    the ground, their bases sunk 0.3 m so that no gap shows on slopes."""
    from polar_sim.sim.actors.robots import GROUP

    colours = list(OBSTACLE_COLOURS)
    for c in colours:
        _add_texture(spec, f"obst_{c}", obstacle_texture(OBSTACLE_COLOURS[c], rng))
        mat = spec.add_material(name=f"obst_{c}", specular=0.2)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"obst_{c}"
    tangents = np.roll(route, -1, axis=0) - np.roll(route, 1, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    normals = np.stack([-tangents[:, 1], tangents[:, 0]], 1)
    idx = np.sort(rng.choice(np.arange(20, len(route) - 5), n_obst, replace=False))
    for k, i in enumerate(idx):
        side = rng.choice([-1.0, 1.0])
        kind = rng.choice(["box", "wall", "pole"], p=[0.45, 0.25, 0.3])
        off = rng.uniform(5.5, 10.0)
        px, py = route[i] + side * off * normals[i]
        yaw = np.arctan2(tangents[i, 1], tangents[i, 0])
        colour = colours[rng.integers(len(colours))]
        if kind == "box":
            sx, sy, sz = rng.uniform(0.5, 1.2, 3)
            yaw += rng.uniform(-0.5, 0.5)
            size, gtype = [sx, sy, sz + 0.3], mujoco.mjtGeom.mjGEOM_BOX
        elif kind == "wall":
            sx, sy, sz = rng.uniform(2.0, 4.0), 0.15, rng.uniform(0.8, 1.3)
            size, gtype = [sx, sy, sz + 0.3], mujoco.mjtGeom.mjGEOM_BOX
        else:
            sz = rng.uniform(1.2, 2.0)
            size, gtype = [0.15, sz + 0.3, 0], mujoco.mjtGeom.mjGEOM_CYLINDER
        zc = float(grid.height(px, py)) + size[2 if gtype == mujoco.mjtGeom.mjGEOM_BOX else 1] - 0.3
        spec.worldbody.add_geom(name=f"obstacle_{k}_{kind}", type=gtype, size=size,
                                pos=[px, py, zc], quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)],
                                material=f"obst_{colour}", group=GROUP["static"])


def _rover_at_start(spec, grid, route, cfg, camera_height, camera_fovy):
    """Add the rover (preset ``cfg``, camera overrides applied) at the route's start, facing
    along it. Returns (the rover's configuration, the start (x, y, yaw))."""
    from polar_sim.sim.actors.robots import add_rover

    if camera_height is not None:
        cfg = dataclasses.replace(cfg, camera_height=float(camera_height))
    if camera_fovy is not None:
        cfg = dataclasses.replace(cfg, camera_fovy_deg=float(camera_fovy))
    t0 = route[1] - route[-1]
    start = (route[0, 0], route[0, 1], float(np.arctan2(t0[1], t0[0])))
    add_rover(spec, cfg, start, z0=float(grid.height(start[0], start[1])))
    return cfg, start


def _apply_sky_and_light(spec, look):
    """Replace the base MJCF's sky texture, sun and headlight by an appearance's (those it gives)."""
    sky = look.get("sky")
    if sky is not None:
        tex = next(t for t in spec.textures if t.name == "sky")
        if sky["kind"] == "clutter":
            rng = np.random.default_rng(np.random.SeedSequence([look["texture_seed"], 99]))
            img = sky_cube(rng, colour=sky["colour"], colour2=sky["colour2"], clutter_colour=sky["clutter_colour"],
                           clutter_deg=sky["clutter_deg"])
            tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_NONE
            tex.width, tex.height = img.shape[1], img.shape[0]
            tex.data = np.ascontiguousarray(img).tobytes()
        else:
            top = np.asarray(sky["colour"]) / 255.0
            hor = np.asarray(sky.get("colour2", sky["colour"])) / 255.0
            tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_GRADIENT if sky["kind"] == "gradient" else mujoco.mjtBuiltin.mjBUILTIN_FLAT
            tex.rgb1, tex.rgb2 = top, (hor if sky["kind"] == "gradient" else top)
    light = look.get("light")
    if light is not None:
        sun = next(li for li in spec.worldbody.lights if li.name == "sun")
        az, el = np.radians(light["azimuth_deg"]), np.radians(light["elevation_deg"])
        sun.dir = -np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        sun.diffuse = np.clip(0.65 * light["intensity"] * np.asarray(light["colour"]), 0.0, 1.0)
        spec.visual.headlight.ambient = [light["ambient"]] * 3


def build_rover_terrain(spec, seed, *, camera_height=None, camera_fovy=None, rover="car", appearance=None):
    """``rover_terrain``: rolling hills (up to 10% slopes). Options: ``camera_height`` (m above
    the ground, default the preset's 1.65), ``camera_fovy`` (vertical field of view, degrees,
    default 45; 29.31 gives KITTI's f = 718.9 px at 376 rows), ``rover`` preset ("car" or
    "indoor"), ``appearance`` (None: the default look; "random", a ground family name or an
    explicit spec: :mod:`polar_sim.sim.builders.rover_appearance`)."""
    return build_rover_scene(spec, seed, flat=False, rover=rover, camera_height=camera_height,
                             camera_fovy=camera_fovy, appearance=appearance)


def build_rover_flat(spec, seed, *, camera_height=None, camera_fovy=None, rover="car", appearance=None):
    """``rover_flat``: the same route, zones and obstacles on flat ground (same options)."""
    return build_rover_scene(spec, seed, flat=True, rover=rover, camera_height=camera_height,
                             camera_fovy=camera_fovy, appearance=appearance)
