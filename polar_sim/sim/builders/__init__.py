"""Scene builders and their looks: the seeded worlds (rover terrain, office, warehouse, navigation
rooms, tabletop), the object meshes, and the textures and appearance families they are drawn with.

Each builder fills an ``mujoco.MjSpec`` for :func:`polar_sim.sim.scenes.load_scene` and returns the
scene's metadata; use them through :class:`polar_sim.sim.World` (``World("warehouse2d", seed=3)``).
"""
