"""Sensors: RGB-D cameras with labels, 2D and 3D lidars, and their switchable noise models.

A scene declares a lidar with a ``<custom><text name="sensor:NAME" data="..."/>`` entry, e.g.
``type=lidar2d site=lidar beams=1081 fov_deg=270 min=0.1 max=30`` or
``type=lidar3d site=lidar3d rows=32 cols=1024 vfov_min_deg=-25 vfov_max_deg=15 min=0.3 max=80``;
the beams fan out in the site frame (x forward, y left, z up). Every MJCF camera is a camera.
"""

from __future__ import annotations

import dataclasses
import functools

import mujoco
import numpy as np

from polar_sim._validation import as_float, as_int
from polar_sim.geometry import CV_FROM_GL, make_pose
from polar_sim.sim.render import OffscreenRenderer
from polar_sim.sim.actors.robots import RAY_GROUPS, RENDER_GROUPS, TARGET_ONLY_GROUPS

__all__ = [
    "CameraFrame", "LidarScan", "LidarScan3D", "LidarSpec", "RangeNoise", "DepthNoise",
    "parse_lidars", "Lidar", "bare_multiray", "CameraRig", "MAX_LIDAR_RAYS",
]

#: Most rays one declared lidar may cast per scan (a 3D lidar's rows x cols included).
MAX_LIDAR_RAYS = 1_000_000


@dataclasses.dataclass(frozen=True)
class CameraFrame:
    """One camera image with its exact geometry.

    Attributes
    ----------
    rgb : (H, W, 3) uint8
    depth : (H, W) float32, metres along the optical axis; ``inf`` where nothing was hit
        (and where the noise model drops a pixel)
    labels : (H, W) int32, classes of :data:`polar_sim.sim.truth.LABELS`
    geom_ids : (H, W) int32, MuJoCo geom id per pixel, -1 for background
    K : (3, 3) intrinsics, OpenCV convention (x right, y down, z forward, pixel centres at integers)
    T_world_cam : (4, 4) camera-to-world pose, OpenCV camera axes
    t : float, simulation time in seconds
    """

    rgb: np.ndarray
    depth: np.ndarray
    labels: np.ndarray
    geom_ids: np.ndarray
    K: np.ndarray
    T_world_cam: np.ndarray
    t: float


@dataclasses.dataclass(frozen=True)
class LidarScan:
    """A planar scan. ``angles`` (n,) rad in the sensor frame (counter-clockwise from x);
    ``ranges`` (n,) metres, ``inf`` for no return; ``T_world_sensor`` (4, 4); ``t`` seconds."""

    angles: np.ndarray
    ranges: np.ndarray
    T_world_sensor: np.ndarray
    t: float

    def points(self):
        """Beam end points (m, 2) of the valid returns in the sensor frame."""
        ok = np.isfinite(self.ranges)
        r = self.ranges[ok]
        return np.stack([r * np.cos(self.angles[ok]), r * np.sin(self.angles[ok])], 1)


@dataclasses.dataclass(frozen=True)
class LidarScan3D:
    """A 3D scan. ``directions`` (n, 3) unit vectors in the sensor frame; ``ranges`` (n,) metres,
    ``inf`` for no return; ``T_world_sensor`` (4, 4); ``t`` seconds."""

    directions: np.ndarray
    ranges: np.ndarray
    T_world_sensor: np.ndarray
    t: float

    def points(self):
        """End points (m, 3) of the valid returns in the sensor frame."""
        ok = np.isfinite(self.ranges)
        return self.directions[ok] * self.ranges[ok, None]


@dataclasses.dataclass(frozen=True)
class RangeNoise:
    """Lidar noise: Gaussian range noise ``sigma`` (m) and a dropout probability per beam."""

    sigma: float = 0.0
    dropout: float = 0.0

    def __post_init__(self):
        as_float(self.sigma, "sigma", minimum=0.0)
        if as_float(self.dropout, "dropout", minimum=0.0) >= 1.0:
            raise ValueError(f"dropout: expected a probability in [0, 1), got {self.dropout}")

    def apply(self, ranges, rng):
        out = ranges.copy()
        hit = np.isfinite(out)
        if self.sigma > 0:
            out[hit] += rng.normal(0.0, self.sigma, hit.sum())
            out[hit] = np.maximum(out[hit], 0.0)
        if self.dropout > 0:
            out[rng.random(len(out)) < self.dropout] = np.inf
        return out


@dataclasses.dataclass(frozen=True)
class DepthNoise:
    """Kinect-v1-like depth noise.

    Axial Gaussian noise ``sigma(z) = sigma0 + sigma2 * (z - 0.4)^2`` (metres; Nguyen et al. 2012),
    quantisation in disparity (``baseline`` m, ``disparity_step`` px: depth steps grow as z^2),
    dropout of pixels within ``edge_px`` of a depth discontinuity larger than ``edge_jump`` m,
    and random ``dropout``. Dropped pixels become ``inf``. RGB gets Gaussian noise ``rgb_sigma``
    (grey levels).
    """

    sigma0: float = 0.0012
    sigma2: float = 0.0019
    baseline: float = 0.075
    disparity_step: float = 0.125
    edge_px: int = 1
    edge_jump: float = 0.05
    dropout: float = 0.01
    rgb_sigma: float = 2.0

    def __post_init__(self):
        for name in ("sigma0", "sigma2", "disparity_step", "edge_jump", "rgb_sigma"):
            as_float(getattr(self, name), name, minimum=0.0)
        as_float(self.baseline, "baseline", minimum=0.0, exclusive_minimum=True)
        as_int(self.edge_px, "edge_px", minimum=0, maximum=64)
        if as_float(self.dropout, "dropout", minimum=0.0) >= 1.0:
            raise ValueError(f"dropout: expected a probability in [0, 1), got {self.dropout}")

    def apply(self, rgb, depth, fx, rng):
        z = depth.astype(np.float64)
        hit = np.isfinite(z)
        zn = z.copy()
        zn[hit] += rng.normal(0.0, 1.0, hit.sum()) * (self.sigma0 + self.sigma2 * (z[hit] - 0.4) ** 2)
        if self.disparity_step > 0:
            disp = fx * self.baseline / np.maximum(zn[hit], 1e-6)
            disp = np.maximum(np.round(disp / self.disparity_step), 1) * self.disparity_step
            zn[hit] = fx * self.baseline / disp
        drop = rng.random(z.shape) < self.dropout
        if self.edge_px > 0:
            import cv2

            zz = np.where(hit, z, 1e6).astype(np.float32)
            k = np.ones((2 * self.edge_px + 1,) * 2, np.uint8)
            jump = cv2.dilate(zz, k) - cv2.erode(zz, k)
            drop |= jump > self.edge_jump
        zn[drop] = np.inf
        out_rgb = rgb
        if self.rgb_sigma > 0:
            out_rgb = np.clip(rgb + rng.normal(0.0, self.rgb_sigma, rgb.shape), 0, 255).astype(np.uint8)
        return out_rgb, zn.astype(np.float32)



@dataclasses.dataclass(frozen=True)
class LidarSpec:
    name: str
    kind: str  # "lidar2d" | "lidar3d"
    site: str
    min_range: float
    max_range: float
    directions: np.ndarray  # (n, 3) unit vectors in the site frame
    angles: np.ndarray | None  # (n,) for 2D


def _parse_kv(text, where):
    out = {}
    for tok in text.split():
        if "=" not in tok:
            raise ValueError(f"{where}: expected key=value tokens, got {tok[:80]!r}")
        k, v = tok.split("=", 1)
        out[k] = v
    return out


_LIDAR_KEYS = {"lidar2d": ("type", "site", "beams", "fov_deg", "min", "max"),
               "lidar3d": ("type", "site", "rows", "cols", "vfov_min_deg", "vfov_max_deg", "min", "max")}


def _num(kv, key, default, where, *, integer=False, lo=None, hi=None, lo_open=False):
    """Value ``key`` of a sensor declaration as a checked int or float."""
    text = kv.get(key)
    if text is None:
        return default
    try:
        v = int(text) if integer else float(text)
    except ValueError:
        kind = "an integer" if integer else "a number"
        raise ValueError(f"{where}: {key}={text[:40]!r} is not {kind}") from None
    bad = (not np.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo))
           or (hi is not None and v > hi))
    if bad:
        rng = f"{'(' if lo_open else '['}{lo}, {hi}]"
        raise ValueError(f"{where}: {key}={text[:40]!r} is out of range; expected a value in {rng}")
    return v


def parse_lidars(model):
    """Lidar declarations of a compiled model, as ``{name: LidarSpec}``.

    Every value is checked: ``beams`` (1 .. :data:`MAX_LIDAR_RAYS`), ``fov_deg`` (0, 360],
    ``rows``/``cols`` (rows x cols <= :data:`MAX_LIDAR_RAYS`), ``vfov_min_deg`` <= ``vfov_max_deg``
    in [-90, 90], and 0 <= ``min`` < ``max``; a malformed one raises ``ValueError`` naming the
    declaration and the key.
    """
    out = {}
    for i in range(model.ntext):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TEXT, i) or ""
        if not name.startswith("sensor:"):
            continue
        where = f"<text name={name!r}>"
        adr, size = model.text_adr[i], model.text_size[i]
        try:
            text = bytes(model.text_data[adr : adr + size]).rstrip(b"\0").decode()
        except UnicodeDecodeError:
            raise ValueError(f"{where}: the declaration is not UTF-8 text") from None
        spec = _parse_lidar(name, text)
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, spec.site) < 0:
            raise ValueError(f"{where}: site {spec.site!r} does not exist")
        out[spec.name] = spec
    return out


@functools.lru_cache(maxsize=64)
def _parse_lidar(name, text):
    """The :class:`LidarSpec` of declaration ``text`` of ``<text name=name>`` (cached: every
    procedural world declares the same lidars, and a 32 x 1024 3D lidar's directions take
    milliseconds to build; the arrays are shared read-only)."""
    sname = name.split(":", 1)[1]
    where = f"<text name={name!r}>"
    kv = _parse_kv(text, where)
    kind = kv.get("type")
    if kind not in _LIDAR_KEYS:
        raise ValueError(f"{where}: unknown sensor type {kind!r}; expected lidar2d or lidar3d")
    unknown = sorted(set(kv) - set(_LIDAR_KEYS[kind]))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; {kind} takes {list(_LIDAR_KEYS[kind])}")
    if "site" not in kv:
        raise ValueError(f"{where}: site None does not exist")
    site = kv["site"]
    lo = _num(kv, "min", 0.0, where, lo=0.0, hi=1e6)
    hi = _num(kv, "max", 30.0, where, lo=0.0, hi=1e6, lo_open=True)
    if not lo < hi:
        raise ValueError(f"{where}: min={lo} must be smaller than max={hi}")
    if kind == "lidar2d":
        n = _num(kv, "beams", 1081, where, integer=True, lo=1, hi=MAX_LIDAR_RAYS)
        fov = np.radians(_num(kv, "fov_deg", 270.0, where, lo=0.0, hi=360.0, lo_open=True))
        # A full circle must not repeat its first beam at +180 deg.
        ang = np.linspace(-fov / 2, fov / 2, n, endpoint=fov < 2 * np.pi - 1e-9)
        dirs = np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], 1)
    else:
        rows = _num(kv, "rows", 32, where, integer=True, lo=1, hi=MAX_LIDAR_RAYS)
        cols = _num(kv, "cols", 1024, where, integer=True, lo=1, hi=MAX_LIDAR_RAYS)
        if rows * cols > MAX_LIDAR_RAYS:
            raise ValueError(f"{where}: rows x cols = {rows * cols} rays exceeds {MAX_LIDAR_RAYS} (MAX_LIDAR_RAYS)")
        e0 = _num(kv, "vfov_min_deg", -25.0, where, lo=-90.0, hi=90.0)
        e1 = _num(kv, "vfov_max_deg", 15.0, where, lo=-90.0, hi=90.0)
        if e0 > e1:
            raise ValueError(f"{where}: vfov_min_deg={e0} must not exceed vfov_max_deg={e1}")
        el = np.radians(np.linspace(e0, e1, rows))
        az = np.linspace(-np.pi, np.pi, cols, endpoint=False)
        E, A = np.meshgrid(el, az, indexing="ij")
        dirs = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
        ang = None
    for a in (dirs, ang):
        if a is not None:
            a.flags.writeable = False
    return LidarSpec(sname, kind, site, lo, hi, dirs, ang)


class Lidar:
    """Casts one scan of a :class:`LidarSpec` with ``mj_multiRay`` (robot geoms excluded by group)."""

    def __init__(self, model, spec: LidarSpec):
        self.spec = spec
        self._site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, spec.site)
        n = len(spec.directions)
        self._geomid = np.zeros(n, np.int32)
        self._dist = np.zeros(n, np.float64)

    def scan(self, model, data, noise=None, rng=None):
        R = data.site_xmat[self._site].reshape(3, 3)
        origin = data.site_xpos[self._site].copy()
        vec = self.spec.directions @ R.T
        n = len(vec)
        mujoco.mj_multiRay(model, data, origin, vec.ravel(), RAY_GROUPS, 1, -1, self._geomid, self._dist,
                           None, n, self.spec.max_range)
        r = self._dist.copy()
        r[(r < self.spec.min_range) | (r > self.spec.max_range)] = np.inf  # -1 (no hit) included
        if noise is not None:
            r = noise.apply(r, rng)
        T = make_pose(R, origin)
        if self.spec.kind == "lidar2d":
            return LidarScan(self.spec.angles.copy(), r, T, float(data.time))
        return LidarScan3D(self.spec.directions.copy(), r, T, float(data.time))


def bare_multiray(model, data, spec: LidarSpec):
    """A zero-argument callable that makes only the ``mj_multiRay`` call one scan of ``spec`` needs,
    from the sensor's pose at the time of this call (directions rotated to world axes once, here).

    The floor a :meth:`Lidar.scan` is measured against (``benchmarks/bench_sim.py``): no range
    clipping, noise or result objects; the distances are discarded.
    """
    sid = model.site(spec.site).id
    R = data.site_xmat[sid].reshape(3, 3)
    vec = (spec.directions @ R.T).ravel()
    org = data.site_xpos[sid].copy()
    n = len(spec.directions)
    gid, dist = np.zeros(n, np.int32), np.zeros(n)

    def cast():
        mujoco.mj_multiRay(model, data, org, vec, RAY_GROUPS, 1, -1, gid, dist, None, n, spec.max_range)

    return cast


class CameraRig:
    """Renders every camera of a model: one :class:`OffscreenRenderer` per image size, made lazily."""

    def __init__(self, model):
        self._renderers = {}
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[:] = RENDER_GROUPS
        self._opt.sitegroup[:] = 0
        self._target_opt = mujoco.MjvOption()
        self._target_opt.geomgroup[:] = TARGET_ONLY_GROUPS
        self._target_opt.sitegroup[:] = 0

    def renderer(self, model, height, width):
        key = (height, width)
        if key not in self._renderers:
            self._renderers[key] = OffscreenRenderer(model, height, width)
        return self._renderers[key]

    def render(self, model, data, cam_id, width, height, label_lut, *, rgb=True, depth=True, seg=True):
        """``(rgb, depth, labels, geom_ids)`` of a fixed camera; unrequested parts are None."""
        img, d, g = self.renderer(model, height, width).render(data, cam_id, self._opt, rgb=rgb,
                                                                 depth=depth, ids=seg or depth)
        labels = None
        if g is not None:
            labels = np.where(g >= 0, label_lut[np.maximum(g, 0)], 0).astype(np.int32)
        return img, d, labels, g

    def render_free(self, model, data, width, height, lookat, distance, azimuth, elevation):
        """RGB (H, W, 3) from a free camera orbiting ``lookat`` (m) at ``distance`` (m),
        ``azimuth`` and ``elevation`` in degrees (MuJoCo's viewer convention)."""
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = lookat
        cam.distance = distance
        cam.azimuth = azimuth
        cam.elevation = elevation
        img, _, _ = self.renderer(model, height, width).render(data, cam, self._opt, depth=False, ids=False)
        return img

    def render_target_mask(self, model, data, cam_id, width, height):
        """Full (amodal) silhouette (H, W) bool of the geoms in the target group, ignoring
        everything that would occlude them."""
        _, _, g = self.renderer(model, height, width).render(data, cam_id, self._target_opt, rgb=False,
                                                              depth=False, ids=True)
        return g >= 0

    def close(self):
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()


def camera_pose(data, cam_id):
    """Camera-to-world pose (4, 4) in OpenCV camera axes."""
    return make_pose(data.cam_xmat[cam_id].reshape(3, 3) @ CV_FROM_GL, data.cam_xpos[cam_id])
