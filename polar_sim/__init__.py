"""polar_sim: a simulation-in-the-loop testbed for probabilistic online learning of appearance
and structure on robots.

Importing the package imports nothing heavy: subpackages (``sim``, ``gpis``, ...) load on first
use, and the gymnasium environment ids are registered by ``import polar_sim.envs`` (or by the
module-prefixed id ``gym.make("polar_sim.envs:polar_sim/GPISNav-v1")``), so ``import
polar_sim.metrics`` needs neither gymnasium nor MuJoCo.
"""

__version__ = "0.1.0"

from polar_sim.errors import NotUpdatedError, PolarSimError  # noqa: E402

__all__ = ["__version__", "PolarSimError", "NotUpdatedError"]
