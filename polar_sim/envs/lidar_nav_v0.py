"""LidarNav-v0: the raw base of goal-reaching navigation in seeded cluttered indoor worlds."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from polar_sim.envs._gridplan import GeodesicDistance
from polar_sim.envs.base import PolarMujocoEnv, check_kwargs
from polar_sim.geometry import T_to_pose2d, between2d, wrap_angle

__all__ = ["LidarNavEnv"]

GOAL_RADIUS = 0.4  # m
COLLISION_PENALTY = 5.0
SUCCESS_BONUS = 5.0
TIME_COST = 0.01
LIDAR_MAX = 30.0


class LidarNavEnv(PolarMujocoEnv):
    """## Description
    The indoor rover drives to a goal in a procedurally generated world of rooms, doors and
    clutter (``navworld``; a new layout every episode, drawn from the episode seed). This base
    environment emits the raw 2D lidar scan; ``GPISNav-v0`` (and the ``GPISObservation`` wrapper)
    adds SDF observations from an online map.

    ## Observation Space
    ``Dict``, keys sorted:

    | key | shape | dtype | meaning |
    |---|---|---|---|
    | ``goal`` | (2,) | float32 | goal position in the robot frame (x forward, y left), m |
    | ``ranges`` | (n_beams,) | float32 | lidar ranges, m, 270 deg field of view; no return = 30 |
    | ``twist`` | (2,) | float32 | measured forward speed (m/s) and yaw rate (rad/s) |

    ## Action Space
    ``Box(-1, 1, (2,))``: normalised ``(v, omega)``; v = a0 * ``max_speed``, omega = a1 *
    ``max_yaw_rate``. Actions outside the box or with NaN raise ``ValueError``.

    ## Reward
    ``progress`` (decrease of the shortest-path distance to the goal around the walls and
    clutter, m, as in Habitat's PointNav) − ``time`` (0.01 per step) − ``collision`` (5 on a
    collision) + ``success`` (5 on reaching the goal). The terms are in ``info["reward_terms"]``.
    (The straight-line distance would reward pushing into a wall that stands between the robot
    and the goal.)

    ## Episode End
    Terminated when the robot is within 0.4 m of the goal (success) or touches an obstacle (a
    MuJoCo contact between a robot geom and a non-ground geom). Truncated by the ``TimeLimit``
    of the registration (600 steps = 60 s).

    ## Arguments
    | argument | default | meaning |
    |---|---|---|
    | ``render_mode`` | None | ``"rgb_array"``: top-down view |
    | ``render_size`` | (480, 480) | (width, height) of the rendered view, pixels |
    | ``rooms`` | 3 | rooms per side of the world |
    | ``room_size`` | 4.0 | m |
    | ``clutter`` | 10 | pieces of clutter |
    | ``n_beams`` | 270 | lidar beams |
    | ``max_speed`` | 1.0 | m/s at action 1 |
    | ``max_yaw_rate`` | 1.5 | rad/s at action 1 |

    ## Truth in ``info``
    ``robot_pose2d`` (x, y, theta), ``goal`` (world, m), ``goal_distance`` (straight line, m),
    ``geodesic_distance`` (shortest path for the rover, m), ``collision``, ``path_length`` (m),
    ``is_success``, ``layout_seed``.

    ## Version History
    - v0: first release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, *, render_mode=None, render_size=(480, 480), rooms=3, room_size=4.0, clutter=10,
                 n_beams=270, max_speed=1.0, max_yaw_rate=1.5, **unknown):
        check_kwargs(type(self), unknown)
        super().__init__(render_mode=render_mode, render_size=render_size)
        self._rooms = int(rooms)
        self._room_size = float(room_size)
        self._clutter = int(clutter)
        self._n_beams = int(n_beams)
        self._max_speed = float(max_speed)
        self._max_yaw_rate = float(max_yaw_rate)
        half = self._rooms * self._room_size / 2 + 1.0
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = spaces.Dict(self._obs_spaces(half))

    def _obs_spaces(self, half):
        reach = float(2 * half * np.sqrt(2))
        return {
            "goal": spaces.Box(-reach, reach, (2,), np.float32),
            "ranges": spaces.Box(0.0, LIDAR_MAX, (self._n_beams,), np.float32),
            "twist": spaces.Box(np.array([-2 * self._max_speed, -4 * self._max_yaw_rate], np.float32),
                                np.array([2 * self._max_speed, 4 * self._max_yaw_rate], np.float32)),
        }

    # -- world ----------------------------------------------------------------------------
    def _make_world(self, layout_seed):
        from polar_sim.sim import World

        self._layout_seed = layout_seed
        return World("navworld", seed=layout_seed, rooms=self._rooms, room_size=self._room_size,
                     clutter=self._clutter, lidar_beams=self._n_beams)

    def _reset_scene(self):
        w = self._world
        self._goal = np.asarray(w.meta["goal"], dtype=np.float64)
        x0, _, y0, _ = w.meta["bounds"]
        self._geodesic = GeodesicDistance(w.meta["occupancy"], (x0, y0), w.meta["occupancy_res"], self._goal)
        self._truth = w.truth()
        self._pose = self._truth["robot_pose2d"]
        self._geo = self._prev_dist = self._geodesic(self._pose[:2])
        self._path_length = 0.0
        self._collision = False
        self._scan = w.lidar("lidar")

    def _apply_action(self, a):
        v, om = a[0] * self._max_speed, a[1] * self._max_yaw_rate
        prev = self._pose
        self._world.step((v, om))
        self._truth = self._world.truth()
        self._pose = self._truth["robot_pose2d"]
        self._path_length += float(np.hypot(*(self._pose[:2] - prev[:2])))
        self._collision = bool(self._truth["robot_collision"])
        self._geo = self._geodesic(self._pose[:2])  # for the reward and the info alike
        self._scan = self._world.lidar("lidar")
        self._after_scan()

    def _after_scan(self):
        """Hook for subclasses that consume each new scan (map updates)."""

    def _goal_distance(self):
        return float(np.hypot(*(self._goal - self._pose[:2])))

    def _sensor_pose2d(self):
        return T_to_pose2d(self._scan.T_world_sensor)

    # -- observation, info, reward --------------------------------------------------------
    def _goal_robot(self):
        rel = between2d(self._pose, np.array([self._goal[0], self._goal[1], 0.0]))
        return rel[:2].astype(np.float32)

    def _twist(self):
        tw = self._truth["robot_twist"]
        lim = self.observation_space["twist"]
        return np.clip(np.array([tw[0], tw[5]], np.float32), lim.low, lim.high)

    def _get_obs(self):
        r = np.where(np.isfinite(self._scan.ranges), self._scan.ranges, LIDAR_MAX).astype(np.float32)
        return {"goal": self._goal_robot(), "ranges": np.minimum(r, LIDAR_MAX), "twist": self._twist()}

    def _get_info(self):
        d = self._goal_distance()
        return {"robot_pose2d": self._pose.copy(), "goal": self._goal.copy(), "goal_distance": d,
                "geodesic_distance": self._geo, "collision": self._collision,
                "path_length": self._path_length,
                "is_success": bool(d < GOAL_RADIUS and not self._collision), "layout_seed": self._layout_seed}

    def _get_reward(self):
        d = self._goal_distance()
        terms = {"progress": self._prev_dist - self._geo, "time": -TIME_COST,
                 "collision": -COLLISION_PENALTY if self._collision else 0.0,
                 "success": SUCCESS_BONUS if (d < GOAL_RADIUS and not self._collision) else 0.0}
        self._prev_dist = self._geo
        terminated = self._collision or d < GOAL_RADIUS
        return sum(terms.values()), terminated, terms

    def _render_frame(self):
        w, h = self._render_size
        half = self._rooms * self._room_size / 2
        img = self._world.render_view(width=w, height=h, lookat=[0, 0, 0], distance=1.1 * half / np.tan(np.radians(30)),
                                      elevation=-89.99, azimuth=90.0)
        return img
