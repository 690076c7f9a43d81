"""Module adapters shared by the environments and their module wrappers.

An adapter turns raw sensor data into a module's observation, so the same code serves a
registered environment (``GPISNav-v0`` holds one internally) and a wrapper around a raw
environment (``GPISObservation(LidarNav-v0)``). Users swap in their own module by passing any
object with the same small interface.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SDFStencil", "GPISSource", "TruthSource", "OccupancyEDTSource", "make_sdf_source", "SDF_SOURCES",
           "RoutePath", "VOOdometry", "TrackerPose", "pose7", "grasp_yaw_error"]


def robot_to_world(pose2d, points):
    """Points (n, 2) in the frame of pose (x, y, theta) carried into the world: the position part
    of :func:`polar_sim.geometry.compose2d`, the same operations, without its stacking."""
    x, y, th = float(pose2d[0]), float(pose2d[1]), float(pose2d[2])
    c, s = float(np.cos(th)), float(np.sin(th))
    px, py = points[:, 0], points[:, 1]
    out = np.empty((len(points), 2))
    out[:, 0] = x + c * px - s * py
    out[:, 1] = y + s * px + c * py
    return out


class SDFStencil:
    """A robot-centred polar stencil: ``n_rays`` directions x ``radii`` distances.

    ``points_robot`` (n, 2) are in the robot frame (x forward, y left), metres, ordered
    ray-major (all radii of ray 0, then ray 1, ...).
    """

    #: Limits of the stencil: directions, and distances per direction.
    MAX_RAYS, MAX_RADII = 1024, 64

    def __init__(self, n_rays=16, radii=(0.5, 1.0, 2.0, 3.0)):
        from polar_sim._validation import as_float_array, as_int

        self.n_rays = as_int(n_rays, "stencil_rays", minimum=1, maximum=self.MAX_RAYS)
        self.radii = as_float_array(radii, "stencil_radii")
        if self.radii.ndim != 1 or not 1 <= len(self.radii) <= self.MAX_RADII:
            raise ValueError(f"stencil_radii: expected 1..{self.MAX_RADII} distances (m), got shape {self.radii.shape}")
        if not np.isfinite(self.radii).all() or np.any(self.radii <= 0):
            raise ValueError(f"stencil_radii: expected finite distances > 0 (m), got {self.radii.tolist()}")
        self.radii = self.radii.copy()
        ang = np.linspace(-np.pi, np.pi, self.n_rays, endpoint=False)
        A, R = np.meshgrid(ang, self.radii, indexing="ij")
        self.points_robot = np.stack([R * np.cos(A), R * np.sin(A)], -1).reshape(-1, 2)

    @property
    def size(self):
        return len(self.points_robot)

    def world_points(self, pose2d):
        """Stencil points (n, 2) in the world for a robot pose (x, y, theta)."""
        return robot_to_world(pose2d, self.points_robot)


class GPISSource:
    """The online GPIS map (default mode: faithful distance) as an SDF source."""

    name = "gpis"

    def __init__(self, **params):
        from polar_sim.gpis import GPISMap2D

        if "sensor_offset" in params:
            raise ValueError("sdf_params: sensor_offset is set by the environment (it passes the sensor's own pose)")
        # The registered versions are frozen: they keep the re-evaluation they were recorded with
        # ("gated"; tests/envs/test_trajectories.py replays them bit for bit), and sdf_params
        # may still choose another. Then the caller's parameters or stage fields
        # (local_gp__map_scale=1.0), checked by set_params.
        self.map = GPISMap2D(sensor_offset=(0.0, 0.0)).set_params(noise__reevaluation="gated")
        self.map.set_params(**params)

    def reset(self):
        self.map.reset()

    def update(self, angles, ranges, sensor_pose2d):
        self.map.update(angles, ranges, sensor_pose2d)

    def query(self, points):
        """(sdf (n,), grad (n, 2), var (n,)); before any data: distance 0, no gradient, var inf."""
        if getattr(self.map, "n_updates_", 0) == 0:
            return np.zeros(len(points)), np.zeros((len(points), 2)), np.full(len(points), np.inf)
        return self.map.query(points)

    def _register_native(self, *args):
        """ICP-G in the map's compiled loop (``register_sdf`` looks for it); None before data."""
        return self.map._register_native(*args)


class OccupancyEDTSource:
    """A log-odds occupancy grid and the signed EDT of it (the grid baseline) as an SDF source."""

    name = "occupancy_edt"

    def __init__(self, cell_size=0.05, max_range=30.0):
        from polar_sim.baselines import OccupancyGrid2D

        self.grid = OccupancyGrid2D(cell_size=cell_size, max_range=max_range)
        self._sdf = None

    def reset(self):
        self.grid.reset()
        self._sdf = None

    def update(self, angles, ranges, sensor_pose2d):
        self.grid.update(angles, ranges, sensor_pose2d, sensor_offset=(0.0, 0.0))
        self._sdf = None

    def query(self, points):
        from polar_sim.baselines import DiscreteSDF2D

        if getattr(self.grid, "n_scans_", 0) == 0:
            return np.zeros(len(points)), np.zeros((len(points), 2)), np.full(len(points), np.inf)
        if self._sdf is None:
            self._sdf = DiscreteSDF2D.from_grid(self.grid)
        out = self._sdf.query(points)
        d, g = out[0], out[1]
        v = out[2] if len(out) > 2 else np.zeros(len(points))
        return d, g, v


class TruthSource:
    """The exact SDF of the scene in the lidar plane (``World.sdf``): the perfect map.

    The gradient is a central difference of the exact field (step 1 mm); the variance is 0.
    ``origin`` (x, y, theta), the map frame's pose in the world (None: the world itself), lets
    the perfect map be queried in the robot's start frame.
    """

    name = "truth"

    def __init__(self, world=None, origin=None):
        self.world = world
        self.origin = origin

    def reset(self):
        pass

    def update(self, angles, ranges, sensor_pose2d):
        pass

    def query(self, points):
        o = self.origin
        if o is not None:
            points = robot_to_world(o, points)
        d, g = self.world.sdf_gradient(points, step=1e-3)
        if o is not None:  # the gradient back in the map frame
            c, s = float(np.cos(o[2])), float(np.sin(o[2]))
            gx, gy = g[:, 0].copy(), g[:, 1].copy()
            g[:, 0] = c * gx + s * gy
            g[:, 1] = -s * gx + c * gy
        return d, g, np.zeros(len(points))

    def query_stencil(self, pose2d, offsets):
        """:meth:`query` at the points ``offsets`` (n, 2) given in the frame of ``pose2d`` (in the
        map frame), in one call: the same values as ``query(robot_to_world(pose2d, offsets))``."""
        d, g = self.world.sdf_stencil(pose2d, offsets, frame=self.origin, step=1e-3)
        return d, g, np.zeros(len(offsets))


SDF_SOURCES = ("gpis", "truth", "occupancy_edt")


def make_sdf_source(source, **params):
    """An SDF source by name (see :data:`SDF_SOURCES`), or ``source`` itself if it is an object
    with ``reset()``, ``update(angles, ranges, sensor_pose2d)`` and ``query(points)``."""
    if not isinstance(source, str):
        for m in ("reset", "update", "query"):
            if not callable(getattr(source, m, None)):
                raise TypeError(f"sdf_source: a custom source needs a {m}() method; got {type(source).__name__}")
        return source
    if source == "gpis":
        return GPISSource(**params)
    if source == "truth":
        return TruthSource()
    if source == "occupancy_edt":
        return OccupancyEDTSource(**params)
    raise ValueError(f"sdf_source: unknown source {source!r}; expected one of {', '.join(SDF_SOURCES)} or an object")


# -- route following on visual odometry (GroundVO-v0, GroundOdometry) ----------------------------

class RoutePath:
    """An open polyline with arc length: local projection and interpolation.

    ``project(xy, s_near)`` searches only the segments within ``[s_near - back, s_near + ahead]``
    metres of arc, so a route that passes near itself (or repeats a loop) is followed segment by
    segment.
    """

    def __init__(self, points, back=10.0, ahead=40.0):
        self.points = np.asarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 2 or len(self.points) < 2:
            raise ValueError(f"points: expected shape (n >= 2, 2), got {self.points.shape}")
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])
        self.back, self.ahead = float(back), float(ahead)

    @property
    def length(self):
        return float(self.s[-1])

    def project(self, xy, s_near):
        """(arc length (m), distance (m)) of the path point nearest to ``xy`` (2,) near ``s_near``."""
        i0 = max(int(np.searchsorted(self.s, s_near - self.back)) - 1, 0)
        i1 = min(int(np.searchsorted(self.s, s_near + self.ahead)) + 1, len(self.points) - 1)
        i1 = max(i1, i0 + 1)
        a, b = self.points[i0:i1], self.points[i0 + 1 : i1 + 1]
        ab = b - a
        t = np.clip(((xy - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0.0, 1.0)
        d = np.linalg.norm(a + t[:, None] * ab - xy, axis=1)
        k = int(np.argmin(d))
        return float(self.s[i0 + k] + t[k] * (self.s[i0 + k + 1] - self.s[i0 + k])), float(d[k])

    def point_at(self, s):
        """Point (2,) at arc length ``s``, m (clamped to the path)."""
        return np.array([np.interp(s, self.s, self.points[:, 0]), np.interp(s, self.s, self.points[:, 1])])


#: Observation bounds of the odometry keys (values beyond them are clipped).
POSE_BOUND = 1000.0  # m
WAYPOINT_BOUND = 200.0  # m
SPEED_BOUND = 30.0  # m/s
YAW_RATE_BOUND = 5.0  # rad/s


def _make_groundvo(K, camera_height, *, seed, **params):
    from polar_sim.ground import GroundVO, MotionConfig
    from polar_sim.sim.recorders.rover_sequences import ROVER_SLIP

    # The route images are already at the VO's working size (about 620 px wide, as KITTI's
    # reduced images), so no pyramid level; the 3D integration follows the hills; the rover's
    # tyres creep sideways in turns.
    params = {"downsample": 1, "integration": "3d", "motion": MotionConfig(slip=ROVER_SLIP), **params}
    return GroundVO(K, camera_height, seed=seed, **params)


class VOOdometry:
    """Monocular visual odometry as the robot's only localisation on a route.

    Every image goes to the VO; its pose (camera k in camera 0's frame, OpenCV axes) is chained
    onto the known start pose to give the estimated robot pose in the world, and the route is
    followed on that estimate: the waypoint is the route point ``waypoint_lookahead`` metres
    ahead of the estimated pose's projection on the route, expressed in the estimated robot frame.

    Parameters
    ----------
    vo : "groundvo" or callable
        ``"groundvo"``: :class:`polar_sim.ground.GroundVO` (``downsample=1``,
        ``integration="3d"``, the rover's sideways slip ``motion=MotionConfig(slip=ROVER_SLIP)``,
        seeded from the task). Or a factory ``vo(K, camera_height, seed=...,
        **vo_params)`` returning an object whose ``process(rgb, t)`` gives a result with ``pose``
        (4, 4) (camera k in camera 0's frame, OpenCV axes), ``speed`` (m/s), ``yaw_rate`` (rad/s
        about camera +y, > 0 turning right) and optionally ``ground_prob`` (H, W) in [0, 1] and
        ``status``: the :class:`~polar_sim.ground.GroundEstimate` conventions.
    vo_params : dict, optional
        Keyword arguments of the VO (e.g. ``{"model": "2param"}``).
    waypoint_lookahead : float
        Distance (m) along the route from the estimated position to the waypoint.
    ground_prob_size : (int, int)
        Width and height of the downsampled ground-probability image, pixels.
    """

    def __init__(self, vo="groundvo", *, vo_params=None, waypoint_lookahead=10.0, ground_prob_size=(80, 24)):
        if isinstance(vo, str):
            if vo != "groundvo":
                raise ValueError(f"vo: unknown VO {vo!r}; expected 'groundvo' or a factory callable")
            self._factory = _make_groundvo
        elif callable(vo):
            self._factory = vo
        else:
            raise TypeError(f"vo: expected 'groundvo' or a callable factory, got {type(vo).__name__}")
        self.name = vo if isinstance(vo, str) else getattr(vo, "__name__", type(vo).__name__)
        self._params = dict(vo_params or {})
        self.lookahead = float(waypoint_lookahead)
        if not np.isfinite(self.lookahead) or self.lookahead <= 0:
            raise ValueError(f"waypoint_lookahead: expected a positive number of metres, got {waypoint_lookahead!r}")
        size = tuple(int(v) for v in np.ravel(ground_prob_size))
        if len(size) != 2 or min(size) < 1:
            raise ValueError(f"ground_prob_size: expected (width, height) >= 1 px, got {ground_prob_size!r}")
        self.ground_prob_size = size

    def observation_spaces(self):
        """The observation keys this adapter produces and their spaces."""
        from gymnasium import spaces

        w, h = self.ground_prob_size
        return {
            "ground_prob": spaces.Box(0.0, 1.0, (h, w), np.float32),
            "pose": spaces.Box(np.array([-POSE_BOUND, -POSE_BOUND, -np.pi], np.float32),
                               np.array([POSE_BOUND, POSE_BOUND, np.pi], np.float32)),
            "twist": spaces.Box(np.array([-SPEED_BOUND, -YAW_RATE_BOUND], np.float32),
                                np.array([SPEED_BOUND, YAW_RATE_BOUND], np.float32)),
            "waypoint": spaces.Box(-WAYPOINT_BOUND, WAYPOINT_BOUND, (2,), np.float32),
        }

    def reset(self, task, rgb, t):
        """Start an episode of ``task`` (a :class:`~polar_sim.envs.rover_drive_v0.RouteTask`) with
        its first image ``rgb`` taken at time ``t`` (s)."""
        from polar_sim.geometry import inv_pose

        self.vo = self._factory(task.K, task.camera_height, seed=task.seed, **self._params)
        if not callable(getattr(self.vo, "process", None)):
            raise TypeError(f"vo: the factory returned {type(self.vo).__name__}, which has no process(rgb, t)")
        self._T_world_cam0 = task.start_pose @ task.T_body_cam
        self._T_cam_body = inv_pose(task.T_body_cam)
        self._path = RoutePath(task.route)
        self.est_progress = self._path.project(task.start_pose[:2, 3], 0.0)[0]
        self._s = self.est_progress
        self.update(rgb, t)

    def update(self, rgb, t):
        """Process the next image; the estimate is in ``pose2d``, ``T_world_body``, ``speed`` ..."""
        import cv2

        from polar_sim.geometry import T_to_pose2d

        e = self.vo.process(rgb, t)
        self.estimate = e
        self.T_world_body = self._T_world_cam0 @ np.asarray(e.pose, dtype=np.float64) @ self._T_cam_body
        self.pose2d = T_to_pose2d(self.T_world_body)
        self.speed = float(e.speed) if np.isfinite(e.speed) else 0.0
        # The VO's yaw rate is about the camera's +y (down) axis: the robot's is about +z (up).
        self.yaw_rate = -float(e.yaw_rate) if np.isfinite(e.yaw_rate) else 0.0
        gp = getattr(e, "ground_prob", None)
        w, h = self.ground_prob_size
        if gp is None:
            self.ground_prob = np.zeros((h, w), np.float32)
        else:
            gp = np.nan_to_num(np.asarray(gp, dtype=np.float32), nan=0.0)
            self.ground_prob = np.clip(cv2.resize(gp, (w, h), interpolation=cv2.INTER_AREA), 0.0, 1.0)
        self._s, _ = self._path.project(self.pose2d[:2], self._s)
        self.est_progress = max(self.est_progress, self._s)

    def waypoint(self):
        """The waypoint (2,) in the estimated robot frame (x forward, y left), m."""
        p = self._path.point_at(self._s + self.lookahead) - self.pose2d[:2]
        c, s = np.cos(self.pose2d[2]), np.sin(self.pose2d[2])
        return np.array([c * p[0] + s * p[1], -s * p[0] + c * p[1]])

    def observation(self):
        """Fresh observation arrays (float32, clipped to :meth:`observation_spaces`)."""
        pose = self.pose2d.copy()
        pose[:2] = np.clip(pose[:2], -POSE_BOUND, POSE_BOUND)
        return {
            "ground_prob": self.ground_prob.copy(),
            "pose": pose.astype(np.float32),
            "twist": np.array([np.clip(self.speed, -SPEED_BOUND, SPEED_BOUND),
                               np.clip(self.yaw_rate, -YAW_RATE_BOUND, YAW_RATE_BOUND)], np.float32),
            "waypoint": np.clip(self.waypoint(), -WAYPOINT_BOUND, WAYPOINT_BOUND).astype(np.float32),
        }

    def info(self, true_pose2d, path_length):
        """Scoring against the true pose (x, y, yaw): ``est_pose2d``, ``drift`` (m, horizontal),
        ``drift_pct`` (% of the distance travelled), ``heading_error`` (rad), ``est_progress``
        (m), ``vo_status``."""
        from polar_sim.geometry import wrap_angle

        drift = float(np.hypot(*(self.pose2d[:2] - true_pose2d[:2])))
        return {"est_pose2d": self.pose2d.copy(), "drift": drift,
                "drift_pct": 100.0 * drift / path_length if path_length > 0 else 0.0,
                "heading_error": float(wrap_angle(self.pose2d[2] - true_pose2d[2])),
                "est_progress": float(self.est_progress), "vo_status": str(getattr(self.estimate, "status", ""))}


# -- reaching a tracked object (ObjectTrack-v0, TrackerObservation) ------------------------------

#: Observation bounds of the tracking keys (values beyond them are clipped).
POSITION_BOUND = 3.0  # m, the room
STD_BOUND = 10.0  # rad or m


def pose7(T):
    """Position (3,) and scalar-first quaternion (4,) with w >= 0 of a 4x4 pose, as one (7,) array."""
    from polar_sim.geometry import matrix_to_quat

    q = matrix_to_quat(T[:3, :3])
    return np.concatenate([T[:3, 3], q if q[0] >= 0 else -q])


def _yaw(R):
    return float(np.arctan2(R[1, 0], R[0, 0]))


def _make_tracker(model_points, K, initial_pose, *, model_normals=None, random_state=0, **params):
    from polar_sim.tracking import ObjectTracker

    return ObjectTracker(model_points, K, initial_pose, model_normals=model_normals, random_state=random_state,
                         **params)


class TrackerPose:
    """A model-based object tracker as the robot's knowledge of where the object is.

    Every RGB-D frame goes to the tracker; its pose (T_cam_obj) is mapped to the world with the
    calibrated camera pose, and the pre-grasp pose follows from the object pose and the task's
    fixed grasp offset. The observation gives the estimated object pose, the tracker's
    uncertainty and the estimated pre-grasp pose relative to the hand.

    Parameters
    ----------
    tracker : "objecttracker" or callable
        ``"objecttracker"``: :class:`polar_sim.tracking.ObjectTracker` (its defaults, seeded from
        the task). Or a factory ``tracker(model_points, K, initial_pose, model_normals=...,
        random_state=..., **tracker_params)`` returning an object whose ``process(rgb, depth, t)``
        gives a result with ``pose`` (4, 4) T_cam_obj and optionally ``covariance`` (6, 6) of
        (rotation rad, translation m) and ``lost``: the :class:`~polar_sim.tracking.TrackResult`
        conventions.
    tracker_params : dict, optional
        Keyword arguments of the tracker (e.g. ``{"appearance": "h"}``).
    """

    def __init__(self, tracker="objecttracker", *, tracker_params=None):
        if isinstance(tracker, str):
            if tracker != "objecttracker":
                raise ValueError(f"tracker: unknown tracker {tracker!r}; expected 'objecttracker' or a factory "
                                 "callable")
            self._factory = _make_tracker
        elif callable(tracker):
            self._factory = tracker
        else:
            raise TypeError(f"tracker: expected 'objecttracker' or a callable factory, got {type(tracker).__name__}")
        self._params = dict(tracker_params or {})

    @staticmethod
    def observation_spaces():
        """The observation keys this adapter produces and their spaces."""
        from gymnasium import spaces

        b = POSITION_BOUND
        return {
            "object_pose": spaces.Box(np.array([-b] * 3 + [-1.0] * 4, np.float32),
                                      np.array([b] * 3 + [1.0] * 4, np.float32)),
            "object_std": spaces.Box(0.0, STD_BOUND, (6,), np.float32),
            "pregrasp": spaces.Box(np.array([-b] * 3 + [-np.pi], np.float32), np.array([b] * 3 + [np.pi], np.float32)),
        }

    def reset(self, task, rgb, depth, t):
        """Start an episode of ``task`` (a :class:`~polar_sim.envs.tabletop_reach_v0.ReachTask`)
        with its first frame (rgb (H, W, 3) uint8, depth (H, W) m) taken at time ``t`` (s)."""
        from polar_sim.geometry import inv_pose

        self._task = task
        T0 = inv_pose(task.T_world_cam) @ task.initial_object_pose
        self.tracker = self._factory(task.model_points, task.K, T0, model_normals=task.model_normals,
                                     random_state=task.seed, **self._params)
        if not callable(getattr(self.tracker, "process", None)):
            raise TypeError(f"tracker: the factory returned {type(self.tracker).__name__}, which has no process()")
        self.update(rgb, depth, t)

    def update(self, rgb, depth, t):
        """Track the next frame; the estimate is in ``T_world_obj``, ``std``, ``lost``."""
        r = self.tracker.process(rgb, depth, t)
        self.result = r
        self.T_cam_obj = np.asarray(r.pose, dtype=np.float64)
        self.T_world_obj = self._task.T_world_cam @ self.T_cam_obj
        cov = getattr(r, "covariance", None)
        if cov is None:
            self.std = np.full(6, STD_BOUND)
        else:
            self.std = np.sqrt(np.clip(np.nan_to_num(np.diag(np.asarray(cov, float)), nan=STD_BOUND ** 2), 0, None))
        self.lost = bool(getattr(r, "lost", False))

    def pregrasp_pose(self):
        """Estimated pre-grasp hand pose (4, 4), world frame."""
        return self.T_world_obj @ self._task.T_obj_pregrasp

    def observation(self, hand_pose):
        """Fresh observation arrays for a hand pose (7,) (position, quaternion w-first)."""
        from polar_sim.geometry import quat_to_matrix

        hp = np.asarray(hand_pose, dtype=np.float64)
        G = self.pregrasp_pose()
        d = np.empty(4)
        d[:3] = G[:3, 3] - hp[:3]
        d[3] = grasp_yaw_error(G[:3, :3], quat_to_matrix(hp[3:]), self._task.grasp_symmetry)
        b = POSITION_BOUND
        obj = pose7(self.T_world_obj)
        obj[:3] = np.clip(obj[:3], -b, b)
        return {"object_pose": obj.astype(np.float32),
                "object_std": np.clip(self.std, 0.0, STD_BOUND).astype(np.float32),
                "pregrasp": np.clip(d, [-b, -b, -b, -np.pi], [b, b, b, np.pi]).astype(np.float32)}

    def info(self, true_T_world_obj):
        """Scoring against the true object pose (4, 4): ``tracking_error`` (m, object origin),
        ``tracking_error_deg``, ``tracking_add`` (m, ADD over the model points), ``tracker_lost``."""
        from polar_sim.geometry import so3_log

        E = self.T_world_obj
        P = self._task.model_points
        add = np.linalg.norm(P @ (E[:3, :3] - true_T_world_obj[:3, :3]).T + (E[:3, 3] - true_T_world_obj[:3, 3]),
                             axis=1).mean()
        return {"est_object_pose": E.copy(),
                "tracking_error": float(np.linalg.norm(E[:3, 3] - true_T_world_obj[:3, 3])),
                "tracking_error_deg": float(np.degrees(np.linalg.norm(so3_log(true_T_world_obj[:3, :3].T
                                                                               @ E[:3, :3])))),
                "tracking_add": float(add), "tracker_lost": self.lost}


def grasp_yaw_error(R_goal, R_hand, symmetry):
    """Yaw (rad) to turn the hand about world z to reach the goal's yaw: wrapped to
    [-pi/2, pi/2) for a two-finger grasp (``symmetry="pi"``: the grasp is the same turned by
    180 deg), 0 for ``"continuous"`` (an object symmetric about its axis), [-pi, pi) for
    ``"none"``."""
    e = _yaw(R_goal) - _yaw(R_hand)
    if symmetry == "continuous":
        return 0.0
    if symmetry == "pi":
        return float((e + np.pi / 2) % np.pi - np.pi / 2)
    return float((e + np.pi) % (2 * np.pi) - np.pi)
