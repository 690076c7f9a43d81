"""RoverDrive-v0: the raw base of route following on a car rover's monocular camera."""

from __future__ import annotations

import dataclasses

import numpy as np
from gymnasium import spaces

from polar_sim.envs.base import PolarMujocoEnv, check_kwargs
from polar_sim.envs.observers import RoutePath
from polar_sim.geometry import inv_pose

__all__ = ["RoverDriveEnv", "RouteTask"]

PROGRESS_WEIGHT = 0.1  # reward per metre of progress along the route
CROSS_TRACK_WEIGHT = 0.02  # cost per metre of cross-track error, per step
FAIL_PENALTY = 10.0  # leaving the route or a collision
SUCCESS_BONUS = 10.0
ROUTE_EXTENSION = 60.0  # m of route beyond the end, for look-ahead points (the loop continues)
SCENES = ("rover_terrain", "rover_flat")


@dataclasses.dataclass(frozen=True)
class RouteTask:
    """What the robot is told at the start of an episode: the route, where it starts, its camera.

    Attributes
    ----------
    route : (n, 2) waypoints, world frame, m, 1 m apart, from the start along the loop; they run
        ``ROUTE_EXTENSION`` m past the end of the segment so look-ahead points exist there.
    route_length : float, m; the segment to drive (the end lies ``route_length`` along ``route``).
    start_pose : (4, 4) the robot body's pose at reset, world frame (the localisation prior).
    K : (3, 3) intrinsics of the images in the observation (OpenCV).
    camera_height : float, m above flat ground at rest.
    T_body_cam : (4, 4) camera pose in the body frame, OpenCV camera axes.
    dt : float, s per step.
    seed : int, the episode's seed for the modules (RANSAC, ...), drawn from the env's RNG.
    """

    route: np.ndarray
    route_length: float
    start_pose: np.ndarray
    K: np.ndarray
    camera_height: float
    T_body_cam: np.ndarray
    dt: float
    seed: int


class RoverDriveEnv(PolarMujocoEnv):
    """## Description
    The car-sized rover of ``rover_terrain`` drives a route segment over rolling hills (up to 10 %
    slopes, four ground textures, obstacles 5.5-10 m beside the route). Every episode builds a new
    world from the episode seed (terrain, closed route, obstacles) and the segment starts where the
    rover stands. This base environment emits only the raw camera image; where the robot is comes
    from whatever odometry the user adds; ``GroundVO-v0`` composes it with the ``GroundVO``
    monocular odometry. The task (route, start pose, intrinsics, camera
    height) is ``env.unwrapped.task`` after ``reset``.

    The camera is KITTI-like: 621x188 px with KITTI's focal length after its 2x reduction
    (f = 359.4 px, vertical field of view 29.3 deg), 1.65 m above the ground, at 10 Hz; as KITTI's
    reduced images, it is rendered at 1242x376 and reduced by one Gaussian pyramid level
    (``supersample``).

    ## Observation Space
    ``Dict``:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``rgb`` | (188, 621, 3) | uint8 | the front camera image (``camera_size``) |

    ## Action Space
    ``Box(-1, 1, (2,))``: normalised ``(v, omega)``; the speed set-point is a0 * ``max_speed``
    (m/s) and the yaw rate a1 * ``max_yaw_rate`` (rad/s). The rover's speed command moves toward
    the set-point at ``max_accel`` (m/s^2, a car's acceleration and braking). Actions outside the
    box or with NaN raise ``ValueError`` and leave the environment unchanged; within 1e-6 of the box
    they are taken as its bound.

    ## Reward
    ``progress`` (0.1 per metre of true progress along the route) + ``cross_track`` (-0.02 per
    metre of true distance to the route, every step) + ``fail`` (-10 on leaving the route or a
    collision) + ``success`` (+10 at the end of the route). The terms are in
    ``info["reward_terms"]``.

    ## Episode End
    Terminated when the true progress reaches ``route_length`` (success), when the rover is more
    than ``max_cross_track`` m from the route, or on a collision (a MuJoCo contact between the
    rover and a non-ground geom). Truncated by the ``TimeLimit`` of the registration (1000 steps
    = 100 s).

    ## Arguments
    | argument | default | meaning |
    |---|---|---|
    | ``render_mode`` | None | ``"rgb_array"``: a chase view behind the rover |
    | ``route_length`` | 300.0 | m of route to drive |
    | ``scene`` | ``"rover_terrain"`` | or ``"rover_flat"`` (the same routes on flat ground) |
    | ``max_speed`` | 10.0 | m/s at action 1 (the rover's limit is 12) |
    | ``max_yaw_rate`` | 1.0 | rad/s at action 1 (the rover's limit) |
    | ``max_accel`` | 3.0 | m/s^2 toward the speed set-point; None: no limit |
    | ``max_cross_track`` | 6.0 | m from the route beyond which the episode ends |
    | ``camera_size`` | (621, 188) | image width, height in pixels (the vertical field of view is fixed) |
    | ``appearance`` | None | the scene's ``appearance`` option (:mod:`polar_sim.sim.builders.rover_appearance`); ``reset(options={"appearance": ...})`` overrides it for one episode (``AppearanceRandomization`` draws one per episode) |
    | ``supersample`` | True | render at twice the size (1242x376) and reduce 2x by a Gaussian pyramid level, as KITTI's reduced images and the route recordings are made; False renders at ``camera_size`` directly: 1.7x faster steps, an aliased image and a less robust VO |

    ## Truth in ``info``
    ``robot_pose2d`` (x, y, yaw), ``speed`` (m/s), ``yaw_rate`` (rad/s), ``progress`` (m, true,
    monotone), ``route_length``, ``cross_track_error`` (m), ``collision``, ``path_length`` (m),
    ``is_success``, ``layout_seed``, ``time`` (s, of the image in the observation).

    ## Version History
    - v0: first release. (Fixed without a version bump, since no accepted action behaves
      differently: an action within the box's 1e-6 tolerance is clipped to the box; it used to
      set the speed command and then be rejected by the rover.)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, *, render_mode=None, render_size=(640, 360), route_length=300.0, scene="rover_terrain",
                 max_speed=10.0, max_yaw_rate=1.0, max_accel=3.0, max_cross_track=6.0, camera_size=(621, 188),
                 supersample=True, appearance=None, **unknown):
        check_kwargs(type(self), unknown)
        super().__init__(render_mode=render_mode, render_size=render_size)
        if scene not in SCENES:
            raise ValueError(f"scene: expected one of {SCENES}, got {scene!r}")
        self._route_length = _positive(route_length, "route_length")
        self._scene = scene
        self._max_speed = _positive(max_speed, "max_speed")
        self._max_yaw_rate = _positive(max_yaw_rate, "max_yaw_rate")
        if self._max_speed > 12.0 or self._max_yaw_rate > 1.0:
            raise ValueError(f"max_speed, max_yaw_rate: the rover's limits are 12 m/s and 1 rad/s, "
                             f"got {max_speed}, {max_yaw_rate}")
        self._max_accel = None if max_accel is None else _positive(max_accel, "max_accel")
        self._max_cte = _positive(max_cross_track, "max_cross_track")
        size = tuple(int(v) for v in np.ravel(camera_size))
        if len(size) != 2 or min(size) < 32 or max(size) > 1280:
            raise ValueError(f"camera_size: expected (width, height) in 32..1280 px, got {camera_size!r}")
        self._camera_size = size
        self._supersample = bool(supersample)
        from polar_sim.sim.builders.rover_appearance import resolve_appearance

        resolve_appearance(appearance, 0)  # a bad appearance raises now, not at the first reset
        self._appearance = self._episode_appearance = appearance
        self.task = None
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = spaces.Dict(self._obs_spaces())

    def _obs_spaces(self):
        w, h = self._camera_size
        return {"rgb": spaces.Box(0, 255, (h, w, 3), np.uint8)}

    # -- world ----------------------------------------------------------------------------
    def _make_world(self, layout_seed):
        from polar_sim.sim import World
        from polar_sim.sim.recorders.rover_sequences import KITTI_FOVY_DEG

        self._layout_seed = layout_seed
        look = {} if self._episode_appearance is None else {"appearance": self._episode_appearance}
        return World(self._scene, seed=layout_seed, camera_fovy=KITTI_FOVY_DEG, **look)

    RESET_OPTIONS = ("appearance",)

    def _check_option_values(self, options):
        from polar_sim.sim.builders.rover_appearance import resolve_appearance

        resolve_appearance(options.get("appearance", self._appearance), 0)  # before the old world is closed

    def _take_options(self, options):
        self._episode_appearance = options.get("appearance", self._appearance)

    def _reset_scene(self):
        w = self._world
        loop = np.asarray(w.meta.route, dtype=np.float64)
        seg = np.linalg.norm(np.diff(np.vstack([loop, loop[:1]]), axis=0), axis=1)
        laps = int(np.ceil((self._route_length + ROUTE_EXTENSION) / seg.sum()))
        pts = np.vstack([np.tile(loop, (laps, 1)), loop[:1]])
        s = np.concatenate([[0.0], np.cumsum(np.tile(seg, laps))])
        self._path = RoutePath(pts[: int(np.searchsorted(s, self._route_length + ROUTE_EXTENSION)) + 1])
        tr = w.truth()
        self._T, self._pose, self._twist = tr["robot_pose"], tr["robot_pose2d"], tr["robot_twist"]
        width, height = self._camera_size
        k = 2 if self._supersample else 1
        K = w.camera_intrinsics("front", width=k * width, height=k * height)
        if self._supersample:
            K[:2] /= 2.0  # reduced pixel i is centred on full pixel 2i
        cfg = w.meta.rover_config
        T_body_cam = inv_pose(self._T) @ tr["cameras"]["front"]
        module_seed = int(self.np_random.integers(0, 2**31 - 1))
        self.task = RouteTask(self._path.points.copy(), self._route_length, self._T.copy(), K,
                              float(cfg.camera_height), T_body_cam, float(w.dt), module_seed)
        self._s, _ = self._path.project(self._pose[:2], 0.0)
        self._s_max = self._s
        self._prev_s = self._s
        self._path_length = 0.0
        self._collision = False
        self._v_cmd = 0.0
        self._rgb = self._render_camera()

    def _apply_action(self, a):
        target = float(a[0]) * self._max_speed
        if self._max_accel is None:
            v_cmd = target
        else:
            step = self._max_accel * self._world.dt
            v_cmd = self._v_cmd + float(np.clip(target - self._v_cmd, -step, step))
        prev = self._pose
        self._world.step((v_cmd, float(a[1]) * self._max_yaw_rate))
        self._v_cmd = v_cmd  # committed only once the world has taken the command
        tr = self._world.truth()
        self._T, self._pose, self._twist = tr["robot_pose"], tr["robot_pose2d"], tr["robot_twist"]
        self._path_length += float(np.hypot(*(self._pose[:2] - prev[:2])))
        self._collision = bool(tr["robot_collision"])
        self._s, _ = self._path.project(self._pose[:2], self._s)
        self._s_max = max(self._s_max, self._s)
        self._rgb = self._render_camera()

    def _render_camera(self):
        from polar_sim.sim.recorders.rover_sequences import reduce2x

        width, height = self._camera_size
        k = 2 if self._supersample else 1
        rgb = self._world.camera("front", width=k * width, height=k * height, depth=False, labels=False).rgb
        return reduce2x(rgb) if self._supersample else rgb

    def _cross_track(self):
        return self._path.project(self._pose[:2], self._s)[1]

    # -- observation, info, reward --------------------------------------------------------
    def _get_obs(self):
        return {"rgb": self._rgb.copy()}

    def _get_info(self):
        tw = self._twist
        done = self._s_max >= self._route_length
        return {"robot_pose2d": self._pose.copy(), "speed": float(tw[0]), "yaw_rate": float(tw[5]),
                "progress": float(self._s_max), "route_length": self._route_length,
                "cross_track_error": self._cross_track(), "collision": self._collision,
                "path_length": self._path_length,
                "is_success": bool(done and not self._collision and self._cross_track() <= self._max_cte),
                "layout_seed": self._layout_seed, "time": self._world.time}

    def _get_reward(self):
        cte = self._cross_track()
        done = self._s_max >= self._route_length
        off = cte > self._max_cte
        fail = off or self._collision
        terms = {"progress": PROGRESS_WEIGHT * (self._s_max - self._prev_s),
                 "cross_track": -CROSS_TRACK_WEIGHT * cte, "fail": -FAIL_PENALTY if fail else 0.0,
                 "success": SUCCESS_BONUS if (done and not fail) else 0.0}
        self._prev_s = self._s_max
        return sum(terms.values()), bool(done or fail), terms

    def _render_frame(self):
        w, h = self._render_size
        return self._world.render_view(width=w, height=h, distance=14.0, azimuth=float(np.degrees(self._pose[2])),
                                       elevation=-20.0)


def _positive(x, name):
    """A finite number > 0 (an int or float; strings and booleans are refused)."""
    from polar_sim._validation import as_positive_float

    return as_positive_float(x, name)
