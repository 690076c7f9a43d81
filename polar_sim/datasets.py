"""Sensor data recorded outside this project, shipped with it, and loaders for it.

The files live in ``polar_sim/data/`` (inside the wheel, so a fresh clone or an installed package
has them); ``polar_sim/data/README.md`` gives their provenance, licences and what was converted.
``$POLAR_SIM_DATA`` overrides the folder: a folder of your own with the same file names.

- :func:`load_gazebo1`: 2879 planar laser scans of a **simulated** (Gazebo) office, from the
  GPisMap authors.
- :func:`load_intel_lab`: the **real** Intel Research Lab log (Dirk Hähnel, 2003), 910 scans with
  GMapping-corrected poses and the SLAM-benchmark relations of Kümmerle et al. (2009).
- :func:`data_path`: the path of any shipped file, e.g. ``data_path("gpismap/local_gp.npz")``.

A missing file raises ``FileNotFoundError`` naming it; a corrupt file, or one without an array the
loader needs, raises ``ValueError`` naming the file and the array.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["data_dir", "data_path", "load_npz", "load_gazebo1", "load_intel_lab"]

_SHIPPED = Path(__file__).resolve().parent / "data"


def data_dir() -> Path:
    """The data folder: ``$POLAR_SIM_DATA`` if set, else the copy shipped in ``polar_sim/data``."""
    env = os.environ.get("POLAR_SIM_DATA")
    if env:
        d = Path(env).expanduser()
        if not d.is_dir():
            raise FileNotFoundError(f"POLAR_SIM_DATA: {str(d)!r} is not a directory")
        return d
    return _SHIPPED


def data_path(name: str) -> Path:
    """Path of a file inside the data folder, e.g. ``data_path("gpismap/local_gp.npz")``."""
    if not isinstance(name, str) or not name:
        raise TypeError(f"name: expected a non-empty str, got {name!r}")
    root = data_dir()
    p = (root / name).resolve()
    if not p.is_relative_to(root.resolve()):
        raise ValueError(f"name: {name!r} escapes the data folder {root}")
    if not p.is_file():
        raise FileNotFoundError(f"name: {name!r} is not in the data folder {root}")
    return p


def load_npz(name: str, required=()) -> dict:
    """All arrays of a data file as a dict, checking that ``required`` ones are there.

    Never unpickles. Raises ``ValueError`` naming the file for a corrupt archive, and naming the
    file and the array for a missing one.
    """
    path = data_path(name)
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise ValueError(f"{path}: not a readable .npz data file ({type(exc).__name__}: {exc})") from None
    missing = [k for k in required if k not in out]
    if missing:
        raise ValueError(f"{path}: missing array(s) {', '.join(missing)}")
    return out


def _check(path, name, a, *, shape=None, finite=True, dtype_kind="f"):
    if a.dtype.kind not in dtype_kind:
        raise ValueError(f"{path}: array {name!r} has dtype {a.dtype}, expected kind {dtype_kind!r}")
    if shape is not None and (a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape))):
        raise ValueError(f"{path}: array {name!r} has shape {a.shape}, expected {shape}")
    if finite and not np.isfinite(a).all():
        raise ValueError(f"{path}: array {name!r} holds NaN or inf")


def _provenance(out):
    p = out.get("provenance")
    if p is None:
        return {}
    try:
        return json.loads(str(p))
    except json.JSONDecodeError:
        return {"text": str(p)}


def load_gazebo1():
    """The ``gazebo1`` log: 2879 planar scans of a **Gazebo simulation** of an office.

    Recorded by the GPisMap authors for their demos (simulated, not real data; licence and source in
    ``polar_sim/data/README.md``).

    Returns
    -------
    dict with
        ``poses`` (2879, 3): robot *base* (x, y, yaw) in m, rad;
        ``thetas`` (270,): beam angles in the laser frame, rad; ``ranges`` (2879, 270) float64, m;
        ``sensor_offset`` (2,): the laser's position in the base frame, (0.08, 0) m. Pass it on:
        ``GPISMap2D(sensor_offset=g["sensor_offset"])``, since the maps take the sensor pose
        by default;
        ``demo_frames`` (28,): the scans the published demos feed (100, 200, ..., 2800);
        ``provenance`` (dict).
    """
    path = data_path("gazebo1.npz")
    out = load_npz("gazebo1.npz", required=("poses", "thetas", "ranges", "demo_frames", "sensor_offset"))
    n, m = out["ranges"].shape if out["ranges"].ndim == 2 else (None, None)
    _check(path, "ranges", out["ranges"], shape=(None, None))
    _check(path, "poses", out["poses"], shape=(n, 3))
    _check(path, "thetas", out["thetas"], shape=(m,))
    _check(path, "sensor_offset", out["sensor_offset"], shape=(2,))
    _check(path, "demo_frames", out["demo_frames"], shape=(None,), dtype_kind="iu")
    if out["demo_frames"].size and (out["demo_frames"].min() < 0 or out["demo_frames"].max() >= n):
        raise ValueError(f"{path}: array 'demo_frames' indexes past the {n} scans")
    out["ranges"] = out["ranges"].astype(np.float64)
    out["provenance"] = _provenance(out)
    out.pop("readme", None)
    return out


def load_intel_lab():
    """The Intel Research Lab log (Seattle, 2003): **real** 2D laser data with corrected poses.

    Recorded by Dirk Hähnel; the poses are GMapping's corrected trajectory (``intel.gfs.log``;
    cite Grisetti, Stachniss and Burgard, T-RO 2007). Provenance, checksums and licence notes are
    in ``out["provenance"]`` and ``polar_sim/data/README.md``.

    Returns
    -------
    dict with
        ``poses`` (910, 3): laser pose (x, y, yaw), m, rad (laser = robot centre in this log);
        ``angles`` (180,): beam angles, rad (-90 to +89 deg); ``ranges`` (910, 180), m, ``inf``
        where the laser saw nothing (the log's 81.83 m code);
        ``t`` (910,): seconds from the start; ``t_abs`` (910,): Unix time of each scan;
        ``odom`` (910, 3): raw wheel odometry (x, y, yaw);
        ``benchmark_relations`` (2984, 5): the Freiburg SLAM-benchmark relations
        (t_i, t_j, dx, dy, dyaw): the pose at ``t_j`` in the frame of the pose at ``t_i``, scans
        matched by ``t_abs`` (90 pairs have both scans among these 910);
        ``provenance`` (dict).
    """
    path = data_path("intel_lab.npz")
    out = load_npz("intel_lab.npz", required=("poses", "angles", "ranges", "t", "t_abs", "odom",
                                              "benchmark_relations"))
    r = out["ranges"]
    _check(path, "ranges", r, shape=(None, None), finite=False)
    if np.isnan(r).any() or (r <= 0).any():
        raise ValueError(f"{path}: array 'ranges' holds NaN or non-positive ranges")
    n, m = r.shape
    _check(path, "poses", out["poses"], shape=(n, 3))
    _check(path, "angles", out["angles"], shape=(m,))
    _check(path, "t", out["t"], shape=(n,))
    _check(path, "t_abs", out["t_abs"], shape=(n,))
    _check(path, "odom", out["odom"], shape=(n, 3))
    _check(path, "benchmark_relations", out["benchmark_relations"], shape=(None, 5))
    out["provenance"] = _provenance(out)
    return out
