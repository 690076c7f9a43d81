"""Gymnasium environments: closed-loop evaluation of the modules against exact truth.

Importing ``polar_sim.envs`` registers the ids (``import polar_sim`` alone does not, so the
modules and metrics import without gymnasium); ``gym.make("polar_sim/GPISNav-v1")`` then builds
one. The module-prefixed id ``gym.make("polar_sim.envs:polar_sim/GPISNav-v1")`` imports and
registers by itself, which is what ``spawn``/``forkserver`` vector-env workers need.
"""

from gymnasium.envs.registration import register

__all__ = ["ENV_IDS", "register_envs"]

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
    "polar_sim/RoverDrive-v0": ("polar_sim.envs.rover_drive_v0:RoverDriveEnv", 1000, {}),
    "polar_sim/GroundVO-v0": ("polar_sim.envs.ground_vo_v0:GroundVOEnv", 1000, {}),
    "polar_sim/TabletopReach-v0": ("polar_sim.envs.tabletop_reach_v0:TabletopReachEnv", 300, {}),
    "polar_sim/ObjectTrack-v0": ("polar_sim.envs.object_track_v0:ObjectTrackEnv", 300, {}),
}


def register_envs():
    """Register every polar_sim environment id with gymnasium (idempotent; done on import)."""
    from gymnasium.envs.registration import registry

    for env_id, (entry, steps, kwargs) in ENV_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry, max_episode_steps=steps, kwargs=dict(kwargs))


register_envs()
