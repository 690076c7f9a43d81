"""Small numpy pinhole renderer of a textured ground and corridor walls, for tests, benchmarks and docs.

The world frame is the first camera's frame (OpenCV axes: x right, y down, z forward). The ground is
the plane y = h; two textured walls run along the path at lateral distance ``half_width`` (planes for a
straight path, coaxial cylinders around the turning centre for a constant yaw rate), from the ground
up to ``wall_height``; above them is a featureless sky. The camera follows an exact unicycle path
with constant speed and yaw rate, so the true poses, speed, yaw rate, ground mask and depth are exact.
Textures are periodic multi-octave noise sampled bilinearly from a mip pyramid (level picked from the
pixel footprint) so that far texture does not alias.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from polar_sim._validation import as_rng
from polar_sim.geometry import pinhole_intrinsics

__all__ = ["CorridorScene", "unicycle_poses", "arc_lengths", "make_sequence", "GROUND_KINDS"]


def _periodic_noise(rng, size, sigmas, weights):
    """Sum of Gaussian-filtered white noise fields (periodic, zero mean, unit std), (size, size)."""
    f = np.fft.fftfreq(size)
    r2 = f[:, None] ** 2 + f[None, :] ** 2
    out = np.zeros((size, size))
    for s, w in zip(sigmas, weights):
        n = np.fft.fft2(rng.standard_normal((size, size)))
        field = np.real(np.fft.ifft2(n * np.exp(-2.0 * (np.pi * s) ** 2 * r2)))
        out += w * field / field.std()
    return out / out.std()


def _texture(rng, size, base, amp, tint):
    lum = _periodic_noise(rng, size, (0.7, 2.0, 6.0, 20.0), (1.0, 0.8, 0.6, 0.5))
    chroma = _periodic_noise(rng, size, (8.0, 30.0), (1.0, 1.0))
    tex = (np.asarray(base, np.float64)[None, None, :] + amp * lum[..., None]
           + np.asarray(tint)[None, None, :] * chroma[..., None])
    tex = np.clip(tex, 0, 255).astype(np.float32)
    pyr = [tex]
    while pyr[-1].shape[0] > 8:
        pyr.append(cv2.pyrDown(pyr[-1], borderType=cv2.BORDER_REFLECT101))  # (no wrap border in pyrDown)
    return pyr


#: Ground textures of :class:`CorridorScene`: multi-octave noise, a faint grain on one colour (few
#: corners), square tiles with grout lines, painted stripes across the path on a grainy grey, and wide
#: painted bands on a dark, almost untextured asphalt; the last three repeat along the path (``tile``
#: and ``stripe_period`` texels).
GROUND_KINDS = ("noise", "faint", "checker", "stripes", "painted")


def _ground_texture(kind, rng, size, base, *, tile=32, stripe_period=128, stripe_width=3):
    """The ground texture pyramid of ``kind`` (:data:`GROUND_KINDS`); ``rng`` draws the noise texture in
    every case, so the walls drawn after it are the same whatever the ground."""
    noise = _texture(rng, size, base, 38.0, (10.0, 6.0, 2.0))
    if kind == "noise":
        return noise
    grain = (noise[0] - np.asarray(base, np.float32)) / 38.0  # about unit-variance fine detail
    ii, jj = np.mgrid[0:size, 0:size]
    if kind == "faint":
        tex = np.asarray(base, np.float32) + 2.5 * grain  # +-2.5 grey levels (std), one colour
    elif kind == "checker":
        light = ((ii // tile + jj // tile) % 2 == 0)[..., None]
        grout = ((ii % tile < 2) | (jj % tile < 2))[..., None]
        tex = np.where(light, np.float32([170, 165, 155]), np.float32([95, 95, 100]))
        tex = np.where(grout, np.float32([45, 45, 48]), tex) + 4.0 * grain
    elif kind == "stripes":  # stripes across the path: texture rows are the forward coordinate
        line = ((ii % stripe_period) < stripe_width)[..., None]
        tex = np.where(line, np.float32([230, 228, 215]), np.float32([70, 70, 72])) + 12.0 * grain
    else:  # painted: 0.16 m bands every 1.28 m on dark asphalt whose only texture is +-1 grey level of grain
        line = ((ii % (stripe_period // 2)) < 8)[..., None]
        tex = np.where(line, np.float32([225, 222, 210]), np.float32([52, 52, 55])) + 1.0 * grain
    tex = np.clip(tex, 0, 255).astype(np.float32)
    pyr = [tex]
    while pyr[-1].shape[0] > 8:
        pyr.append(cv2.pyrDown(pyr[-1], borderType=cv2.BORDER_REFLECT101))
    return pyr


def _sample(pyr, a, b, level):
    """Bilinear, wrapping lookup of texel coordinates (a: column, b: row) at mip ``level`` (ints)."""
    out = np.empty((len(a), 3), dtype=np.float32)
    for lv in np.unique(level):
        m = level == lv
        tex = pyr[lv]
        n = tex.shape[0]
        # pyrDown keeps texel 2j of the finer level as texel j, so texel j of level lv is centred at
        # j 2^lv in level-0 units at every level (blending levels then shifts nothing).
        x = a[m] / (2.0**lv)
        y = b[m] / (2.0**lv)
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx = (x - x0)[:, None].astype(np.float32)
        fy = (y - y0)[:, None].astype(np.float32)
        i0 = x0.astype(np.int64) % n
        j0 = y0.astype(np.int64) % n
        i1 = (i0 + 1) % n
        j1 = (j0 + 1) % n
        out[m] = ((tex[j0, i0] * (1 - fx) + tex[j0, i1] * fx) * (1 - fy)
                  + (tex[j1, i0] * (1 - fx) + tex[j1, i1] * fx) * fy)
    return out



def unicycle_poses(n, dt, speed, yaw_rate, accel=None):
    """Exact camera poses (n, 4, 4) of a unicycle at constant speed (m/s) and yaw rate (rad/s).

    Pose k is camera k in camera 0's frame (OpenCV axes, KITTI convention); yaw about +y, ω > 0 turns
    right (toward +x). With ``accel`` (m/s²) the unicycle starts from rest and speeds up at ``accel``
    to ``speed`` along the same circle (curvature ω / speed), as a vehicle pulling away.
    """
    t = np.arange(n) * dt
    dist = arc_lengths(t, speed, accel)
    curv = yaw_rate / speed if speed > 0 else 0.0
    psi = curv * dist
    if abs(curv) < 1e-12:
        x, z = np.zeros(n), dist
    else:
        x = (1.0 - np.cos(psi)) / curv
        z = np.sin(psi) / curv
    T = np.tile(np.eye(4), (n, 1, 1))
    c, s = np.cos(psi), np.sin(psi)
    T[:, 0, 0], T[:, 0, 2], T[:, 2, 0], T[:, 2, 2] = c, s, -s, c
    T[:, 0, 3], T[:, 2, 3] = x, z
    return T


def arc_lengths(t, speed, accel=None):
    """Distance (m) driven at times ``t`` (s): at constant ``speed``, or from rest at ``accel`` (m/s²)
    up to ``speed``."""
    t = np.asarray(t, dtype=np.float64)
    if accel is None:
        return speed * t
    t1 = speed / accel  # end of the acceleration
    return np.where(t < t1, 0.5 * accel * t * t, 0.5 * accel * t1 * t1 + speed * (t - t1))


@dataclass
class CorridorScene:
    """Textured ground plane and corridor walls along a constant-curvature path.

    Parameters
    ----------
    camera_height : float
        Height of the camera above the ground, m (ground plane y = camera_height).
    half_width : float
        Lateral distance from the path to each wall, m.
    wall_height : float
        Wall height above the ground, m.
    curvature : float
        Path curvature ω/V, 1/m (0: straight corridor).
    texel : float
        Size of one texel of the finest texture level, m.
    seed : int
        Texture randomness.
    ground : {"noise", "faint", "checker", "stripes", "painted"}
        Ground texture (:data:`GROUND_KINDS`): the default noise; a faint grain on one colour (almost no
        corners, as a plain concrete floor); 0.64 m tiles with grout lines; painted stripes every
        2.56 m across the path; 0.16 m bands every 1.28 m on dark, almost untextured asphalt (the last
        three repeat along the path).
    """

    camera_height: float = 1.0
    half_width: float = 4.0
    wall_height: float = 3.0
    curvature: float = 0.0
    texel: float = 0.02
    seed: int = 0
    tex_size: int = 512
    ground_rgb: tuple = (120, 108, 92)
    wall_rgb: tuple = (70, 105, 150)
    sky_rgb: tuple = (185, 210, 240)
    ground: str = "noise"

    def __post_init__(self):
        if self.ground not in GROUND_KINDS:
            raise ValueError(f"ground: expected one of {', '.join(GROUND_KINDS)}, got {self.ground!r}")
        rng = as_rng(self.seed)
        self._ground = _ground_texture(self.ground, rng, self.tex_size, self.ground_rgb)
        self._wall = _texture(rng, self.tex_size, self.wall_rgb, 45.0, (25.0, 8.0, -12.0))

    def render(self, T_world_cam, K, width, height, *, noise_std=0.0, rng=None):
        """Render one image.

        Returns (rgb (H, W, 3) uint8, ground_mask (H, W) bool, depth (H, W) float32 z-depth in m,
        inf for sky).
        """
        px, py = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
        t_best, kind, o, d = self._cast(T_world_cam, K, np.stack([px.ravel(), py.ravel()], axis=1))
        n = len(d)
        img = np.empty((n, 3), dtype=np.float32)
        img[:] = np.asarray(self.sky_rgb, np.float32)
        pix_ang = 1.0 / K[0, 0]
        dn = np.linalg.norm(d, axis=1)
        for k_, pyr in ((1, self._ground), (2, self._wall)):
            m = kind == k_
            if not m.any():
                continue
            t = t_best[m]
            p = o[None, :] + t[:, None] * d[m]
            if k_ == 1:
                a, b = p[:, 0], p[:, 2]
                cosang = np.abs(d[m, 1]) / dn[m]
            else:
                a, b, cosang = self._wall_coords(p, d[m], dn[m])
            foot = t * dn[m] * pix_ang / np.maximum(cosang, 0.05)
            # Trilinear filtering: blend the two mip levels around the footprint, so that a surface
            # point's appearance changes smoothly as it approaches (no level switching).
            lev = np.clip(np.log2(np.maximum(foot / self.texel, 1.0)) + 0.5, 0, len(pyr) - 1.001)
            l0 = np.floor(lev).astype(np.intp)
            wgt = (lev - l0).astype(np.float32)[:, None]
            img[m] = (_sample(pyr, a / self.texel, b / self.texel, l0) * (1 - wgt)
                      + _sample(pyr, a / self.texel, b / self.texel, l0 + 1) * wgt)
        if noise_std > 0:
            img += as_rng(rng).normal(0.0, noise_std, img.shape).astype(np.float32)
        rgb = np.clip(np.rint(img), 0, 255).astype(np.uint8).reshape(height, width, 3)
        depth = np.where(kind > 0, t_best, np.inf).astype(np.float32).reshape(height, width)
        return rgb, (kind == 1).reshape(height, width), depth

    def raycast(self, T_world_cam, K, pixels):
        """Exact z-depth (n,) in m (inf: sky) and surface kind (n,) (0 sky, 1 ground, 2 wall) of
        sub-pixel positions (n, 2) (column, row)."""
        t, kind, _, _ = self._cast(T_world_cam, K, np.asarray(pixels, dtype=np.float64))
        return np.where(kind > 0, t, np.inf), kind

    def _cast(self, T_world_cam, K, pix):
        R = T_world_cam[:3, :3]
        o = T_world_cam[:3, 3]
        dc = np.stack([(pix[:, 0] - K[0, 2]) / K[0, 0], (pix[:, 1] - K[1, 2]) / K[1, 1],
                       np.ones(len(pix))], axis=1)  # camera ray with z = 1: its parameter is the z-depth
        d = dc @ R.T
        h = self.camera_height
        n = len(d)
        t_best = np.full(n, np.inf)
        kind = np.zeros(n, dtype=np.int8)  # 0 sky, 1 ground, 2 wall
        with np.errstate(divide="ignore", invalid="ignore"):
            tg = np.where(d[:, 1] > 1e-9, (h - o[1]) / d[:, 1], np.inf)
        hit = (tg > 0) & (tg < t_best)
        t_best[hit], kind[hit] = tg[hit], 1
        for tw, _ in self._walls(o, d):
            y = o[1] + tw * d[:, 1]
            ok = np.isfinite(tw) & (tw > 0) & (tw < t_best) & (y >= h - self.wall_height) & (y <= h)
            t_best[ok], kind[ok] = tw[ok], 2
        return t_best, kind, o, d

    def _walls(self, o, d):
        """Ray parameters of the two walls (with their along-wall coordinate unused here)."""
        hw = self.half_width
        k = self.curvature
        with np.errstate(divide="ignore", invalid="ignore"):
            if abs(k) < 1e-12:
                for x_w in (-hw, hw):
                    yield np.where(np.abs(d[:, 0]) > 1e-12, (x_w - o[0]) / d[:, 0], np.inf), None
                return
            Rc = 1.0 / k  # turning centre at (Rc, 0), radii |Rc| -+ hw
            cx = o[0] - Rc
            cz = o[2]
            a = d[:, 0] ** 2 + d[:, 2] ** 2
            b = 2.0 * (cx * d[:, 0] + cz * d[:, 2])
            for rad in (abs(Rc) - hw, abs(Rc) + hw):
                c = cx * cx + cz * cz - rad * rad
                disc = b * b - 4 * a * c
                sq = np.sqrt(np.maximum(disc, 0.0))
                t1 = (-b - sq) / (2 * a)
                t2 = (-b + sq) / (2 * a)
                t = np.where(t1 > 1e-9, t1, t2)
                yield np.where(disc >= 0, t, np.inf), None

    def _wall_coords(self, p, d, dn):
        """Texture coordinates (along, up) and incidence cosine of wall points (m, 3)."""
        k = self.curvature
        if abs(k) < 1e-12:
            nrm = np.stack([np.ones(len(p)), np.zeros(len(p)), np.zeros(len(p))], axis=1)
            along = p[:, 2] + np.where(p[:, 0] > 0, 1000.0, 0.0)
        else:
            Rc = 1.0 / k
            rx, rz = p[:, 0] - Rc, p[:, 2]
            r = np.hypot(rx, rz)
            nrm = np.stack([rx / r, np.zeros(len(p)), rz / r], axis=1)
            along = np.arctan2(rz, -rx * np.sign(Rc)) * r + np.where(r > abs(Rc), 1000.0, 0.0)
        cosang = np.abs(np.sum(nrm * d, axis=1)) / dn
        return along, p[:, 1], cosang


def make_sequence(n_frames, *, width=640, height=480, fovy_deg=60.0, speed=5.0, yaw_rate=0.1, dt=0.1,
                  camera_height=1.0, half_width=4.0, noise_std=1.0, pitch=0.0, roll=0.0, seed=0, ground="noise",
                  accel=None, sky_rgb=None, slip=0.0):
    """Render a synthetic sequence along an exact unicycle path.

    ``pitch`` (rad, > 0 down) tilts the camera about its x axis relative to the level vehicle frame
    (the optical centre stays on the path, ``camera_height`` above the ground); ``roll`` (rad, > 0 turns
    the image clockwise) then turns it about its optical axis, as a chassis leaning in a turn does, so
    that the ground slopes across the image. ``ground`` is the
    ground texture (:data:`GROUND_KINDS`). With ``accel`` (m/s²) the camera starts from rest and speeds
    up to ``speed`` on the same circle; ``speeds`` (n,) holds the true speed at every image. ``sky_rgb``
    (3,) paints the plain sky (None: :class:`CorridorScene`'s light blue). ``slip`` (s) turns the
    camera about its vertical by arctan(slip ω) from the path's tangent, so that its velocity points
    t1 = -slip ω to the side of its optical axis (tyres creeping outward in a turn: slip > 0; a camera
    ahead of a car's rear axle: slip < 0; ``MotionConfig.slip``).

    Returns a dict: ``rgb`` (n, H, W, 3) uint8, ``ground_mask`` (n, H, W) bool, ``depth`` (n, H, W)
    float32, ``poses`` (n, 4, 4) (KITTI: camera k in camera 0's frame), ``times`` (n,), ``K`` (3, 3),
    ``camera_height``, ``speed``, ``yaw_rate``, ``pitch``, ``roll``, ``slip``.
    """
    K = pinhole_intrinsics(width, height, fovy_deg)
    curv = yaw_rate / speed if speed > 0 else 0.0
    sky = {} if sky_rgb is None else {"sky_rgb": tuple(sky_rgb)}
    scene = CorridorScene(camera_height=camera_height, half_width=half_width, curvature=curv, seed=seed, ground=ground,
                          **sky)
    level = unicycle_poses(n_frames, dt, speed, yaw_rate, accel)
    times = np.arange(n_frames) * dt
    speeds = np.full(n_frames, float(speed)) if accel is None else np.minimum(accel * times, speed)
    if slip:
        d = np.arctan(slip * curv * speeds)  # the yaw rate at each image is curv x speed
        turn = np.tile(np.eye(4), (n_frames, 1, 1))
        turn[:, 0, 0], turn[:, 0, 2], turn[:, 2, 0], turn[:, 2, 2] = np.cos(d), np.sin(d), -np.sin(d), np.cos(d)
        level = level @ turn
    M = np.eye(4)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    M[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]]) @ [[cr, -sr, 0.0], [sr, cr, 0.0],
                                                                              [0.0, 0.0, 1.0]]  # camera -> level
    world_cam = level @ M  # world = level frame of camera 0
    poses = np.linalg.inv(M) @ level @ M  # camera k in camera 0's frame
    rng = as_rng(seed + 1)
    rgb = np.empty((n_frames, height, width, 3), np.uint8)
    mask = np.empty((n_frames, height, width), bool)
    depth = np.empty((n_frames, height, width), np.float32)
    for i, T in enumerate(world_cam):
        rgb[i], mask[i], depth[i] = scene.render(T, K, width, height, noise_std=noise_std, rng=rng)
    return dict(rgb=rgb, ground_mask=mask, depth=depth, poses=poses, times=times, K=K, camera_height=camera_height,
                speed=speed, yaw_rate=yaw_rate, pitch=pitch, roll=roll, speeds=speeds, slip=slip)


def check_data():
    """:class:`polar_sim.params.CheckData` of :class:`polar_sim.ground.GroundVO`: four 160x120
    frames of a curving drive (3 m/s, 0.05 rad/s), and the intrinsics and camera height they need."""
    from polar_sim.params import CheckData

    s = make_sequence(4, width=160, height=120, speed=3.0, yaw_rate=0.05, camera_height=1.0, seed=0)
    return CheckData(init={"K": s["K"], "camera_height": s["camera_height"]},
                     frames=tuple((s["rgb"][i], float(s["times"][i])) for i in range(len(s["rgb"]))))
