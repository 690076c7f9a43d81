"""polar_sim: a simulation-in-the-loop testbed for probabilistic online learning of appearance
and structure on robots.

Importing the package registers the gymnasium environment ids (``polar_sim/GPISNav-v0``, ...).
Heavy subpackages (``sim``, ``gpis``, ...) are imported on first use.
"""

__version__ = "0.1.0"

from polar_sim.errors import NotUpdatedError, PolarSimError  # noqa: E402

__all__ = ["__version__", "PolarSimError", "NotUpdatedError"]
