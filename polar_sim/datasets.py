"""Where the real sensor data recorded outside this project lives, and loaders for it.

The data is not shipped in the wheel. It is found, in order, under ``$POLAR_SIM_DATA`` or
``<repository>/../shared/data``. A missing file raises ``FileNotFoundError`` that says where it
looked, so a test that needs the data fails loudly instead of being skipped.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["data_dir", "data_path", "load_gazebo1"]


def _candidates():
    env = os.environ.get("POLAR_SIM_DATA")
    if env:
        yield Path(env)
    here = Path(__file__).resolve()
    for parent in list(here.parents)[:4]:
        yield parent / "shared" / "data"
        yield parent.parent / "shared" / "data"
    yield Path.cwd().parent / "shared" / "data"


def data_dir() -> Path:
    """The directory holding the shared data (``gazebo1.npz``, ``gpismap/``)."""
    tried = []
    for c in _candidates():
        tried.append(str(c))
        if (c / "gazebo1.npz").is_file():
            return c
    raise FileNotFoundError(
        "shared sensor data not found; set POLAR_SIM_DATA to the folder holding gazebo1.npz. "
        f"Looked in: {', '.join(dict.fromkeys(tried))}"
    )


def data_path(name: str) -> Path:
    """Path of a file inside the shared data folder, e.g. ``data_path("gpismap/local_gp.npz")``."""
    p = data_dir() / name
    if not p.is_file():
        raise FileNotFoundError(f"name: {name!r} is not in the shared data folder {data_dir()}")
    return p


def load_gazebo1():
    """The ``gazebo1`` log: 2879 planar scans in a Gazebo office, from the GPisMap authors.

    Returns
    -------
    dict with
        ``poses`` (2879, 3): robot base (x, y, yaw) in m, rad;
        ``thetas`` (270,): beam angles in rad; ``ranges`` (2879, 270) in m;
        ``sensor_offset`` (2,): laser position in the base frame, m;
        ``demo_frames``: indices of the 28 demo scans.
    """
    with np.load(data_path("gazebo1.npz"), allow_pickle=False) as z:
        out = {k: z[k] for k in z.files}
    out.setdefault("sensor_offset", np.array([0.08, 0.0]))
    return out
