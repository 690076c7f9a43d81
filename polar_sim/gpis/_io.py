"""Save and load GPIS maps as versioned .npz files (never pickle)."""

from __future__ import annotations

import json
import zipfile

import numpy as np

from polar_sim.fileio import atomic_write, check_destination, check_source
from polar_sim.gpis import _loadcheck

__all__ = ["save", "load", "FORMAT", "VERSION"]

FORMAT = "polar_sim.gpis"
VERSION = 1
MAX_FILE_BYTES = 16 << 30     # declared array bytes a map file may hold (16 GiB)


def _params_json(m):
    def conv(v):
        if isinstance(v, np.ndarray):
            return v.tolist()
        if isinstance(v, tuple):
            return list(v)
        if isinstance(v, (np.floating, np.integer, np.bool_)):
            return v.item()
        return v
    return json.dumps({k: conv(getattr(m, k)) for k in m._PARAMS})


def save(m, path):
    """Write map ``m`` to ``path`` atomically; an un-updated map stores only its parameters.

    The file is written to a temporary file in the same folder and moved over ``path`` with
    ``os.replace`` (:func:`polar_sim.fileio.atomic_write`): a crash mid-save leaves the previous
    file intact and no temporary file behind. ``path`` must be a ``str``/``os.PathLike`` naming a
    new file or an existing regular file (``TypeError`` for an ``int``, ``ValueError`` for a
    directory, device, FIFO or socket), checked before anything is written.
    """
    path = check_destination(path, "path")
    arrs = {"format": np.array(FORMAT), "version": np.array(VERSION),
            "cls": np.array(type(m).__name__), "params": np.array(_params_json(m)),
            "fitted": np.array(hasattr(m, "tree_"))}
    if hasattr(m, "tree_"):
        for k, v in m.tree_.state().items():
            arrs["tree/" + k] = v
        g = m.gps_
        arrs.update({"gp/gp_obs": g.gp_obs, "gp/gp_tri": g.gp_tri, "gp/gp_m": g.gp_m,
                     "gp/X": g.X[: g.n_obs], "gp/kinds": g.kinds[: g.n_obs],
                     "gp/alpha": g.alpha[: g.n_obs], "gp/Lbuf": g.Lbuf[: g.n_tri]})
        for k, v in m.free_.state().items():
            arrs["free/" + k] = v
        arrs.update({"slot_gen": m.slot_gen_, "gp_gen": m.gp_gen_, "active": m.active_,
                     "n_updates": np.array(m.n_updates_)})
    with atomic_write(path, "path") as f:
        np.savez(f, **arrs)


def _read(path):
    """All arrays of the .npz at ``path`` (no pickle; members declared larger than the limit are
    refused before they are read, so a small compressed file cannot expand without bound)."""
    try:
        with zipfile.ZipFile(path) as zf:
            total = sum(i.file_size for i in zf.infolist())
    except (OSError, zipfile.BadZipFile, EOFError, ValueError) as exc:
        raise ValueError(f"path: {path} is not a readable GPIS map file ({exc})") from None
    if total > MAX_FILE_BYTES:
        raise ValueError(f"path: {path} declares {total} bytes of arrays, over the "
                         f"{MAX_FILE_BYTES}-byte limit of a GPIS map file")
    key = None
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {}
            for key in z.files:
                out[key] = z[key]
            return out
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, RuntimeError) as exc:
        where = "" if key is None else f", array {key!r}"
        raise ValueError(f"path: {path} is not a readable GPIS map file{where} ({exc})") from None


def load(cls, path):
    """Read a map of class ``cls`` from ``path``.

    The file is untrusted input: every array is validated (:mod:`polar_sim.gpis._loadcheck`:
    keys, dtypes, shapes, finiteness, index bounds, tree structure, integer version) before any
    kernel sees it. ``TypeError`` for a non-path, ``FileNotFoundError`` for a missing file, and
    ``ValueError`` naming the file (and the array) for anything else.
    """
    path = check_source(path, "path")
    data = _read(path)
    ver, name, params_text, fitted = _loadcheck.check_meta(path, data)
    if str(data["format"]) != FORMAT:
        raise ValueError(f"path: {path} is not a GPIS map (format {data['format']!s})")
    if ver != VERSION:
        raise ValueError(f"path: {path} has format version {ver}; this code reads {VERSION}")
    if name != cls.__name__:
        raise ValueError(f"path: {path} holds a {name}, not a {cls.__name__}")
    _loadcheck.check_keys(path, data, fitted, cls.dim)
    try:
        params = json.loads(params_text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"path: {path}: array 'params' is not JSON ({exc})") from None
    if not isinstance(params, dict) or not set(params) <= set(cls._PARAMS):
        raise ValueError(f"path: {path}: array 'params' is not a dict of {cls.__name__} parameters")
    for k in ("sensor_offset", "angle_obs_limit"):      # JSON has no tuples
        if isinstance(params.get(k), list):
            params[k] = tuple(params[k])
    m = cls(**params)
    try:
        m._checked_params()
        if fitted:
            m._init_state()
    except (ValueError, TypeError) as exc:
        raise ValueError(f"path: {path}: array 'params': {exc}") from None
    if not fitted:
        return m
    _loadcheck.check_arrays(path, data, m)
    m.tree_.set_state({k[5:]: v for k, v in data.items() if k.startswith("tree/")})
    m.gps_.set_state({k[3:]: v for k, v in data.items() if k.startswith("gp/")})
    m.free_.set_state({k[5:]: v for k, v in data.items() if k.startswith("free/")})
    m.slot_gen_ = data["slot_gen"].copy()
    m.gp_gen_ = data["gp_gen"].copy()
    m.active_ = data["active"].copy()
    m.n_updates_ = int(data["n_updates"])
    m.version_ = 1
    m._index_samples()
    return m
