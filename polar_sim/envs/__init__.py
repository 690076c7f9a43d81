"""Gymnasium environments: closed-loop evaluation of the modules against exact truth.

Importing ``polar_sim`` registers the ids; ``gym.make("polar_sim/GPISNav-v0")`` builds one, and
``gym.make("polar_sim:polar_sim/GPISNav-v0")`` also works in ``spawn``/``forkserver`` children.
"""

from gymnasium.envs.registration import register

__all__ = ["ENV_IDS", "register_envs"]

ENV_IDS = {
    "polar_sim/LidarNav-v0": ("polar_sim.envs.lidar_nav_v0:LidarNavEnv", 600),
    "polar_sim/GPISNav-v0": ("polar_sim.envs.gpis_nav_v0:GPISNavEnv", 600),
    "polar_sim/RoverDrive-v0": ("polar_sim.envs.rover_drive_v0:RoverDriveEnv", 1000),
    "polar_sim/GroundVO-v0": ("polar_sim.envs.ground_vo_v0:GroundVOEnv", 1000),
    "polar_sim/TabletopReach-v0": ("polar_sim.envs.tabletop_reach_v0:TabletopReachEnv", 300),
    "polar_sim/ObjectTrack-v0": ("polar_sim.envs.object_track_v0:ObjectTrackEnv", 300),
}


def register_envs():
    """Register every polar_sim environment id with gymnasium (idempotent)."""
    from gymnasium.envs.registration import registry

    for env_id, (entry, steps) in ENV_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry, max_episode_steps=steps)
