"""Private helpers of the baselines: the ``reset()`` mixin.

Scan handling (valid beams, end points, sensor offsets, 3D scan forms) is public in
:mod:`polar_sim.registration`, shared with :mod:`polar_sim.gpis.localize`.
"""

from __future__ import annotations


class ResetMixin:
    """``reset()`` deletes the learned state (every attribute whose name ends in ``_``)."""

    def reset(self):
        """Forget all learned state; the parameters are kept. Returns ``self``."""
        for k in [k for k in vars(self) if k.endswith("_") and not k.startswith("__")]:
            delattr(self, k)
        return self
