"""Recorded data: routes driven and orbits flown through the scenes, the cached sequences the
experiments read, and :class:`~polar_sim.sim.recorders.recording.Recording` (frames and truth,
saved as ``.npz`` + JSON).

Importing this package does not load MuJoCo: replaying a recording needs numpy only.
"""
