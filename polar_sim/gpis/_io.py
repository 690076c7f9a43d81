"""Save and load GPIS maps as versioned .npz files (never pickle)."""

from __future__ import annotations

import dataclasses
import json
import zipfile

import numpy as np

from polar_sim.fileio import atomic_write, check_destination, check_source
from polar_sim.gpis import _loadcheck
from polar_sim.gpis.config import SWITCHES
from polar_sim.params import check_fields

__all__ = ["save", "load", "FORMAT", "VERSION", "READS"]

FORMAT = "polar_sim.gpis"
#: Version 2 stores the stage configs (:mod:`polar_sim.gpis.config`) as objects of their fields;
#: version 3 adds ``tree/run`` (how far each sample's face was seen to run on, for the surface's
#: face end; a file without it loads with every face running on, the gate it was built with);
#: versions 1 (flat parameters and ``legacy``) and 2 are still read.
VERSION = 3
READS = (1, 2, 3)
MAX_FILE_BYTES = 16 << 30     # declared array bytes a map file may hold (16 GiB)


def _plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, tuple):
        return list(v)
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    return v


def _params_json(m):
    """The parameters as JSON: each stage config as an object of its fields."""
    params = m.get_params(deep=False)
    return json.dumps({k: {f.name: _plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
                       if k in m._STAGES else _plain(v) for k, v in params.items()})


def _from_version1(cls, params):
    """Version-1 parameters (flat, with ``legacy``) as version-2 ones (stage configs as dicts)."""
    legacy = params.pop("legacy", False)
    out = {k: params.pop(k) for k in cls._param_names() if k in params and k not in cls._STAGES}
    for stage, config in cls._STAGES.items():
        names = {f.name for f in dataclasses.fields(config)}
        fields = {k: params.pop(k) for k in sorted(names & set(params))}
        if legacy is True:
            fields.update({k: SWITCHES[k][1] for k in names & set(SWITCHES)})
        out[stage] = fields
    if params or not isinstance(legacy, bool):
        raise ValueError(f"{sorted(params) or ['legacy']}: not {cls.__name__} parameters of format version 1")
    return out


def _params(cls, path, text, version):
    """The constructor arguments stored in a file's 'params' text."""
    try:
        params = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"path: {path}: array 'params' is not JSON ({exc})") from None
    if not isinstance(params, dict):
        raise ValueError(f"path: {path}: array 'params' is not a dict of {cls.__name__} parameters")
    try:
        if version == 1:
            params = _from_version1(cls, params)
        if not set(params) <= set(cls._param_names()):
            raise ValueError(f"{sorted(set(params) - set(cls._param_names()))[0]}: unknown parameter")
        if cls.dim == 2 and isinstance(params.get("noise", {}), dict) and "reevaluation" not in params.get("noise", {}):
            # written before NoiseConfig2D.reevaluation existed, so built with the gates alone: the
            # map goes on as it was built, not with today's default ("on_returns")
            params["noise"] = {**params.get("noise", {}), "reevaluation": "gated"}
        for stage, config in cls._STAGES.items():
            if stage in params:
                if not isinstance(params[stage], dict):
                    raise ValueError(f"{stage}: expected an object of {config.__name__} fields")
                check_fields(config, stage, params[stage])
                params[stage] = config(**params[stage])
    except (ValueError, TypeError) as exc:
        raise ValueError(f"path: {path}: array 'params': {exc}") from None
    for k in ("sensor_offset", "angle_obs_limit"):      # JSON has no tuples
        if isinstance(params.get(k), list):
            params[k] = tuple(params[k])
    return params


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
    if ver not in READS:
        raise ValueError(f"path: {path} has format version {ver}; this code reads {', '.join(map(str, READS))}")
    if name != cls.__name__:
        raise ValueError(f"path: {path} holds a {name}, not a {cls.__name__}")
    _loadcheck.check_keys(path, data, fitted, cls.dim, ver)
    params = _params(cls, path, params_text, ver)
    try:
        m = cls(**params)
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
