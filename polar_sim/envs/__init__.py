"""Gymnasium environments: closed-loop evaluation of the modules against exact truth.

Importing ``polar_sim.envs`` registers the ids (``import polar_sim`` alone does not, so the
modules and metrics import without gymnasium); ``gym.make("polar_sim/GPISNav-v1")`` then builds
one. The module-prefixed id ``gym.make("polar_sim.envs:polar_sim/GPISNav-v1")`` imports and
registers by itself, which is what ``spawn``/``forkserver`` vector-env workers need.
"""

from gymnasium.envs.registration import register

__all__ = ["ENV_IDS", "ENV_SUMMARIES", "register_envs", "pretrained", "pretrained_ids"]

_NAV = "polar_sim.envs.gpis_nav:GPISNavEnv"
_LIDAR = "polar_sim.envs.lidar_nav:LidarNavEnv"

#: id -> (entry point, max_episode_steps, registered kwargs)
ENV_IDS = {
    "polar_sim/LidarNav-v0": (_LIDAR, 600, {"version": 0}),
    "polar_sim/GPISNav-v0": (_NAV, 600, {"version": 0}),
    "polar_sim/LidarNav-v1": (_LIDAR, 600, {}),
    "polar_sim/GPISNav-v1": (_NAV, 600, {}),
    "polar_sim/GPISNav-Rooms2-v1": (_NAV, 600, {"tier": "rooms2"}),
    "polar_sim/GPISNav-Room-v1": (_NAV, 300, {"tier": "room"}),
    "polar_sim/LidarNav-v2": (_LIDAR, 600, {"version": 2}),
    "polar_sim/GPISNav-v2": (_NAV, 600, {"version": 2}),
    "polar_sim/GPISNav-Rooms2-v2": (_NAV, 600, {"tier": "rooms2", "version": 2}),
    "polar_sim/GPISNav-Room-v2": (_NAV, 300, {"tier": "room", "version": 2}),
    "polar_sim/RoverDrive-v0": ("polar_sim.envs.rover_drive_v0:RoverDriveEnv", 1000, {}),
    "polar_sim/GroundVO-v0": ("polar_sim.envs.ground_vo_v0:GroundVOEnv", 1000, {}),
    "polar_sim/TabletopReach-v0": ("polar_sim.envs.tabletop_reach_v0:TabletopReachEnv", 300, {}),
    "polar_sim/ObjectTrack-v0": ("polar_sim.envs.object_track_v0:ObjectTrackEnv", 300, {}),
}

#: id -> one line for ``polar-sim list``: what the agent sees and where its pose comes from
ENV_SUMMARIES = {
    "polar_sim/LidarNav-v0": "navworld rooms to a goal; exact lidar, goal in the true robot frame (GPS+compass)",
    "polar_sim/GPISNav-v0": "online GPIS map fused at the TRUE pose (GPS+compass variant), noise-free lidar",
    "polar_sim/LidarNav-v1": "navworld rooms to a goal; noisy lidar and wheel odometry, goal in the start frame",
    "polar_sim/GPISNav-v1": "online GPIS map at the ESTIMATED pose (ICP-G on the map), 3x3 rooms; noisy sensors",
    "polar_sim/GPISNav-Rooms2-v1": "GPISNav-v1 on the 2x2-room tier",
    "polar_sim/GPISNav-Room-v1": "GPISNav-v1 on the one-room-with-clutter tier (a memoryless policy can solve it)",
    "polar_sim/LidarNav-v2": "LidarNav-v1 with the kinematic rover (exact unicycle, MuJoCo contacts): faster",
    "polar_sim/GPISNav-v2": "GPISNav-v1 with the kinematic rover (exact unicycle, MuJoCo contacts): faster",
    "polar_sim/GPISNav-Rooms2-v2": "GPISNav-Rooms2-v1 with the kinematic rover: faster, for learning",
    "polar_sim/GPISNav-Room-v2": "GPISNav-Room-v1 with the kinematic rover: faster, for learning",
    "polar_sim/RoverDrive-v0": "car-sized rover along a route over hills; raw camera image",
    "polar_sim/GroundVO-v0": "RoverDrive-v0 with GroundVO monocular odometry as the robot's pose",
    "polar_sim/TabletopReach-v0": "hand to a pre-grasp pose over a moving tabletop object; raw RGB-D",
    "polar_sim/ObjectTrack-v0": "TabletopReach-v0 with the ObjectTracker's pose of the object",
}
assert set(ENV_SUMMARIES) == set(ENV_IDS)


def register_envs():
    """Register every polar_sim environment id with gymnasium (idempotent; done on import)."""
    from gymnasium.envs.registration import registry

    for env_id, (entry, steps, kwargs) in ENV_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry, max_episode_steps=steps, kwargs=dict(kwargs))


register_envs()

from polar_sim.envs.shipped import pretrained, pretrained_ids  # noqa: E402  (after the ids exist)
