"""polar_sim: a simulation-in-the-loop testbed for probabilistic online learning of appearance
and structure on robots.

Importing the package registers the gymnasium environment ids (``polar_sim/GPISNav-v1``, ...)
when gymnasium is installed; a core install without it imports the modules and metrics all the
same. Heavy subpackages (``sim``, ``gpis``, ...) load on first use.
"""

__version__ = "0.1.0"

from polar_sim.errors import NotUpdatedError, PolarSimError  # noqa: E402

try:  # a core install without gymnasium has no envs to register
    from polar_sim.envs import register_envs as _register_envs  # noqa: E402
except ImportError:
    pass
else:
    _register_envs()

__all__ = ["__version__", "PolarSimError", "NotUpdatedError"]
