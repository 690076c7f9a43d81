"""Progress bars for long work (recordings, experiment trials, ``reproduce``): tqdm on stderr.

A bar shows only when stderr is a terminal, so logs, pipes and CI stay clean, and never when
``POLAR_SIM_QUIET=1`` is set in the environment (``polar-sim ... --quiet`` sets it; worker
processes inherit it). A caller's ``enabled=False`` turns one bar off.

>>> from polar_sim.progress import progress_bar
>>> for frame in progress_bar(range(450), desc="mug_touch", unit="frame"):
...     pass
"""

from __future__ import annotations

import os

from tqdm.auto import tqdm

__all__ = ["progress_bar", "quiet", "QUIET_ENV"]

#: The environment variable that silences every bar (``"1"``).
QUIET_ENV = "POLAR_SIM_QUIET"


def quiet() -> bool:
    """True when ``POLAR_SIM_QUIET=1``: no progress bar anywhere."""
    return os.environ.get(QUIET_ENV, "") == "1"


def progress_bar(iterable=None, *, enabled: bool | None = None, **kwargs) -> tqdm:
    """A ``tqdm`` bar on stderr over ``iterable`` (or ``total=`` for manual updates).

    ``enabled``: ``False`` turns it off; ``None`` or ``True`` show it only when stderr is a
    terminal and :func:`quiet` is false. Other keyword arguments go to ``tqdm`` (``desc``,
    ``total``, ``unit``, ``leave``, ...). Returns the bar (a no-op bar when off).
    """
    disable = True if (enabled is False or quiet()) else None     # None: tqdm's "off unless a TTY"
    kwargs.setdefault("dynamic_ncols", True)
    return tqdm(iterable, disable=disable, **kwargs)
