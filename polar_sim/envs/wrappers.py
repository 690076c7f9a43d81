"""Behaviour wrappers for the polar_sim environments, in gymnasium's style: one small class per
behaviour, which checks its own arguments and overrides only what it changes.

The modules are not wrappers: each module environment (``GPISNav``, ``GroundVO``,
``ObjectTrack``) is the composition of a raw task environment and the module
(:class:`polar_sim.envs.module_env.ModuleEnv`), registered as such, and a module of your own takes
the place of ours through the module environment's arguments (``sdf_source=``, ``vo=``,
``tracker=``).
"""

from __future__ import annotations

__all__: list[str] = []
