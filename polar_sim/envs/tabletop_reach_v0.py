"""TabletopReach-v0: the raw base of reaching a pre-grasp pose on an object that moves by itself."""

from __future__ import annotations

import dataclasses

import numpy as np
from gymnasium import spaces

from polar_sim.envs.base import PolarMujocoEnv, check_kwargs
from polar_sim.envs.observers import POSITION_BOUND, grasp_yaw_error, pose7
from polar_sim.envs.rover_drive_v0 import _positive

__all__ = ["TabletopReachEnv", "ReachTask", "DEPTH_MAX"]

DEPTH_MAX = 10.0  # m; the room's walls are within 3 m. Missing depth is 0 in the observation.
SUCCESS_BONUS = 10.0
DROP_PENALTY = 10.0
DROP_HEIGHT = 0.05  # m below the table top at which the object counts as knocked off the table
YAW_WEIGHT = 0.05  # m per rad of yaw error in the distance to the pre-grasp pose
PALM_HALF_THICKNESS = 0.012  # m, polar_sim.sim.actors.hand.PALM_HALF[2]


@dataclasses.dataclass(frozen=True)
class ReachTask:
    """What the robot is told at the start of an episode: the object, its camera, the grasp.

    Attributes
    ----------
    target : str, the object's name.
    model_points, model_normals : (M, 3) surface points and outward normals, object frame, m.
    K : (3, 3) intrinsics of the images in the observation (OpenCV).
    T_world_cam : (4, 4) the calibrated (static) camera's pose, OpenCV axes.
    initial_object_pose : (4, 4) the object's world pose at reset (a tracker's initialisation,
        as in tracking benchmarks: the first frame's pose is given).
    T_obj_pregrasp : (4, 4) the pre-grasp hand pose in the object frame.
    grasp_symmetry : "pi" (the grasp is the same turned by 180 deg about the vertical) or
        "continuous" (the object is symmetric about its axis: any yaw).
    dt : float, s per step.
    seed : int, the episode's seed for the modules, drawn from the env's RNG.
    """

    target: str
    model_points: np.ndarray
    model_normals: np.ndarray
    K: np.ndarray
    T_world_cam: np.ndarray
    initial_object_pose: np.ndarray
    T_obj_pregrasp: np.ndarray
    grasp_symmetry: str
    dt: float
    seed: int


def pregrasp_offset(mesh, clearance):
    """Pre-grasp hand pose (4, 4) in the object frame for an object standing upright: the palm
    down, centred over the object's bounding box, its underside ``clearance`` m above the top,
    the fingers and thumb across the object's narrower horizontal side."""
    lo, hi = mesh.bounds
    T = np.eye(4)
    if hi[0] - lo[0] <= hi[1] - lo[1]:
        # The grip runs along the hand's y axis: turn it onto the object's narrower x.
        T[:3, :3] = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T[:3, 3] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] + clearance + PALM_HALF_THICKNESS]
    return T


class TabletopReachEnv(PolarMujocoEnv):
    """## Description
    In ``tabletop`` (a table with 4-6 objects, a static Kinect-like RGB-D camera), the hand must
    reach a pre-grasp pose over the target object: palm down, centred over it, 8 cm above its top,
    fingers across its narrower side. A scripted disturbance keeps sliding the target about the
    front of the table (4-10 cm at a time, turning up to 0.5 rad, every 0.8-2 s; the tabletop
    script ``reach``). Every episode builds a new table from the episode seed. This base
    environment emits the raw RGB-D image and the hand pose; where the object is comes from
    whatever the user adds; ``ObjectTrack-v0`` composes it with the ``ObjectTracker``. The task (object model, intrinsics, camera pose, initial object
    pose, grasp offset) is ``env.unwrapped.task`` after ``reset``.

    The camera renders at ``camera_size`` (default 320x240, half the scene's 640x480, for speed:
    f = 292.4 px, the intrinsics scale with the size), with Kinect-like depth noise by default.

    ## Observation Space
    ``Dict``, keys sorted:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``depth`` | (240, 320) | float32 | metric depth along the optical axis, m, [0, 10]; 0 = no return |
    | ``hand_pose`` | (7,) | float32 | the hand's position (m, world) and quaternion (w, x, y, z), w >= 0 |
    | ``rgb`` | (240, 320, 3) | uint8 | the camera image |

    ## Action Space
    ``Box(-1, 1, (4,))``: a normalised hand velocity command, world frame: (vx, vy, vz) x
    ``max_speed`` (m/s) and a yaw rate x ``max_yaw_rate`` (rad/s, about the vertical); the palm
    stays down. The palm centre stays inside the workspace box x in [-0.55, 0.55], y in [-0.45,
    0.55], z in [0.83, 1.45] m (fingertips above the table): motion stops at its faces. The hand
    touches only the target (it can push it). Actions outside the box or with NaN raise
    ``ValueError`` and leave the environment unchanged; within 1e-6 of the box they are taken as
    its bound.

    ## Reward
    ``distance`` (minus the true distance to the pre-grasp pose: position error (m) + 0.05 m/rad x
    yaw error, every step) + ``success`` (+10 on success) + ``dropped`` (-10 when the hand knocks
    the object off the table). The terms are in ``info["reward_terms"]``.

    ## Episode End
    Terminated on success: the hand within ``success_position`` (2 cm) and ``success_yaw`` (10
    deg) of the true pre-grasp pose; or when the object has been knocked off the table (its origin
    5 cm below the table top). Truncated by the ``TimeLimit`` of the registration (300 steps = 10 s
    at 30 Hz).

    ## Arguments
    | argument | default | meaning |
    |---|---|---|
    | ``render_mode`` | None | ``"rgb_array"``: a third-person view beside the camera image |
    | ``target`` | None | the object to reach (``mug``, ``box``, ``can``, ``bottle``, ``drill``, ``bracket``, ``cube``); None: from the episode seed |
    | ``n_objects`` | 4 | objects on the table, 4-6 |
    | ``camera_size`` | (320, 240) | image width, height, px |
    | ``depth_noise`` | True | Kinect-like depth and RGB noise (``polar_sim.sim.DepthNoise``) |
    | ``max_speed`` | 0.3 | m/s at action 1 |
    | ``max_yaw_rate`` | 1.5 | rad/s at action 1 |
    | ``pregrasp_clearance`` | 0.08 | m between the palm's underside and the object's top |
    | ``success_position`` | 0.02 | m |
    | ``success_yaw`` | 10.0 | deg |

    ## Truth in ``info``
    ``object_pose`` (4, 4, world), ``object_pose_cam`` (T_cam_obj), ``pregrasp_pose`` (4, 4,
    world), ``hand_pose`` (4, 4), ``position_error`` (m), ``yaw_error`` (rad, the turn the hand
    still needs), ``distance``, ``in_contact`` (hand touches the target), ``dropped`` (the object
    was knocked off the table), ``disturbance``
    (``"slide"`` or ``"rest"``), ``is_success``, ``target``, ``layout_seed``, ``time`` (s, of the
    frame in the observation).

    ## Version History
    - v0: first release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, *, render_mode=None, render_size=(480, 360), target=None, n_objects=4, camera_size=(320, 240),
                 depth_noise=True, max_speed=0.3, max_yaw_rate=1.5, pregrasp_clearance=0.08, success_position=0.02,
                 success_yaw=10.0, **unknown):
        check_kwargs(type(self), unknown)
        super().__init__(render_mode=render_mode, render_size=render_size)
        from polar_sim.sim.builders.objects import object_names

        if target is not None and target not in object_names():
            raise ValueError(f"target: unknown object {target!r}; expected one of {', '.join(object_names())} or None")
        self._target = target
        if isinstance(n_objects, bool) or not isinstance(n_objects, (int, np.integer)) or not 4 <= n_objects <= 6:
            raise ValueError(f"n_objects: expected an integer in 4..6, got {n_objects!r}")
        self._n_objects = int(n_objects)
        size = tuple(int(v) for v in np.ravel(camera_size))
        if len(size) != 2 or min(size) < 32 or size[0] > 1280 or size[1] > 960:
            raise ValueError(f"camera_size: expected (width, height) within 32..1280 x 32..960 px, got {camera_size!r}")
        self._camera_size = size
        self._depth_noise = bool(depth_noise)
        self._max_speed = _positive(max_speed, "max_speed")
        self._max_yaw_rate = _positive(max_yaw_rate, "max_yaw_rate")
        self._clearance = _positive(pregrasp_clearance, "pregrasp_clearance")
        self._success_pos = _positive(success_position, "success_position")
        self._success_yaw = np.radians(_positive(success_yaw, "success_yaw"))
        self.task = None
        self.action_space = spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_space = spaces.Dict(self._obs_spaces())

    def _obs_spaces(self):
        w, h = self._camera_size
        b = POSITION_BOUND
        return {
            "depth": spaces.Box(0.0, DEPTH_MAX, (h, w), np.float32),
            "hand_pose": spaces.Box(np.array([-b] * 3 + [-1.0] * 4, np.float32),
                                    np.array([b] * 3 + [1.0] * 4, np.float32)),
            "rgb": spaces.Box(0, 255, (h, w, 3), np.uint8),
        }

    # -- world ----------------------------------------------------------------------------
    def _make_world(self, layout_seed):
        from polar_sim.sim import World
        from polar_sim.sim.sensors import DepthNoise

        self._layout_seed = layout_seed
        noise = {"rgbd": DepthNoise()} if self._depth_noise else None
        return World("tabletop", seed=layout_seed, script="reach", target=self._target, n_objects=self._n_objects,
                     noise=noise)

    def _reset_scene(self):
        from polar_sim.sim.builders.objects import object_info

        w = self._world
        tgt = w.meta.target
        P, N = w.object_points(tgt, 3000)
        self._frame()
        sym = "continuous" if object_info(tgt).symmetry == "z-continuous" else "pi"
        module_seed = int(self.np_random.integers(0, 2**31 - 1))
        tr = w.truth()
        self.task = ReachTask(tgt, P, N, self._K.copy(), self._T_world_cam.copy(), tr["objects"][tgt],
                              pregrasp_offset(w.object_mesh(tgt), self._clearance), sym, float(w.dt), module_seed)
        self._truth = tr

    def _frame(self):
        width, height = self._camera_size
        f = self._world.camera("rgbd", width=width, height=height)
        self._rgb = f.rgb
        d = np.where(np.isfinite(f.depth), f.depth, 0.0).astype(np.float32)
        self._depth = np.minimum(d, np.float32(DEPTH_MAX))
        self._K, self._T_world_cam = f.K, f.T_world_cam

    def _apply_action(self, a):
        self._world.command_hand(a[:3] * self._max_speed, a[3] * self._max_yaw_rate)
        self._world.step()
        self._truth = self._world.truth()
        self._frame()

    # -- truth ----------------------------------------------------------------------------
    def _errors(self):
        tr = self._truth
        G = tr["objects"][self.task.target] @ self.task.T_obj_pregrasp
        H = tr["hand_pose"]
        pos = float(np.linalg.norm(G[:3, 3] - H[:3, 3]))
        yaw = grasp_yaw_error(G[:3, :3], H[:3, :3], self.task.grasp_symmetry)
        return G, pos, yaw

    def _success(self, pos, yaw):
        return pos < self._success_pos and abs(yaw) < self._success_yaw and not self._dropped()

    def _dropped(self):
        return bool(self._truth["objects"][self.task.target][2, 3] < self._world.meta.table_z - DROP_HEIGHT)

    # -- observation, info, reward --------------------------------------------------------
    def _hand_obs(self):
        return pose7(self._truth["hand_pose"]).astype(np.float32)

    def _get_obs(self):
        return {"depth": self._depth.copy(), "hand_pose": self._hand_obs(), "rgb": self._rgb.copy()}

    def _get_info(self):
        from polar_sim.geometry import inv_pose

        tr = self._truth
        G, pos, yaw = self._errors()
        T_obj = tr["objects"][self.task.target]
        return {"object_pose": T_obj.copy(), "object_pose_cam": inv_pose(self._T_world_cam) @ T_obj,
                "pregrasp_pose": G, "hand_pose": tr["hand_pose"].copy(), "position_error": pos, "yaw_error": yaw,
                "distance": pos + YAW_WEIGHT * abs(yaw), "in_contact": bool(tr["in_contact"]),
                "dropped": self._dropped(),
                "disturbance": str(tr["phase"]), "is_success": self._success(pos, yaw), "target": self.task.target,
                "layout_seed": self._layout_seed, "time": self._world.time}

    def _get_reward(self):
        _, pos, yaw = self._errors()
        ok, dropped = self._success(pos, yaw), self._dropped()
        terms = {"distance": -(pos + YAW_WEIGHT * abs(yaw)), "success": SUCCESS_BONUS if ok else 0.0,
                 "dropped": -DROP_PENALTY if dropped else 0.0}
        return sum(terms.values()), ok or dropped, terms

    def _render_frame(self):
        """A third-person view of the table beside the camera image."""
        return self.view_beside(self._rgb)

    def view_beside(self, image):
        """A third-person view of the table (``render_size``) beside ``image`` (H, W, 3) uint8,
        scaled to the view's height."""
        import cv2

        w, h = self._render_size
        view = self._world.render_view(width=w, height=h, lookat=[0.0, 0.0, 0.85], distance=1.25, azimuth=-60.0,
                                       elevation=-28.0)
        cam = cv2.resize(image, (int(round(h * image.shape[1] / image.shape[0])), h), interpolation=cv2.INTER_AREA)
        return np.hstack([view, cam])
