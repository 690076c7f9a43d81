"""Save and load GPIS maps as versioned .npz files (never pickle)."""

from __future__ import annotations

import json
import zipfile

import numpy as np

__all__ = ["save", "load", "FORMAT", "VERSION"]

FORMAT = "polar_sim.gpis"
VERSION = 1


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
    """Write map ``m`` to ``path``; an un-updated map stores only its parameters."""
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
    with open(path, "wb") as f:
        np.savez(f, **arrs)


def load(cls, path):
    """Read a map of class ``cls`` from ``path``; any defect raises ``ValueError``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        raise ValueError(f"path: {path} is not a readable GPIS map file ({exc})") from exc
    try:
        if str(data["format"]) != FORMAT:
            raise ValueError(f"path: {path} is not a GPIS map (format {data['format']!s})")
        ver = int(data["version"])
        if ver != VERSION:
            raise ValueError(f"path: {path} has format version {ver}; this code reads {VERSION}")
        if str(data["cls"]) != cls.__name__:
            raise ValueError(f"path: {path} holds a {data['cls']!s}, not a {cls.__name__}")
        params = json.loads(str(data["params"]))
        for k in ("sensor_offset", "angle_obs_limit"):      # JSON has no tuples
            if isinstance(params.get(k), list):
                params[k] = tuple(params[k])
        m = cls(**params)
        if not bool(data["fitted"]):
            return m
        m._init_state()
        m.tree_.set_state({k[5:]: v for k, v in data.items() if k.startswith("tree/")})
        g = m.gps_
        g.set_state({k[3:]: v for k, v in data.items() if k.startswith("gp/")})
        m.free_.set_state({k[5:]: v for k, v in data.items() if k.startswith("free/")})
        m.slot_gen_ = data["slot_gen"].astype(np.int64).copy()
        m.gp_gen_ = data["gp_gen"].astype(np.int64).copy()
        m.active_ = data["active"].astype(np.int64).reshape(-1, m.dim).copy()
        m.n_updates_ = int(data["n_updates"])
        _consistent(m)
    except ValueError:
        raise
    except (KeyError, TypeError, IndexError, json.JSONDecodeError) as exc:
        raise ValueError(f"path: {path} is a corrupt GPIS map file ({exc!r})") from exc
    return m


def _consistent(m):
    """Cheap structural checks so a tampered file fails here, not inside numba."""
    t, g = m.tree_, m.gps_
    d = m.dim
    S, N = t.node_sample.shape[0], t.pos.shape[0]
    ok = (t.pos.ndim == 2 and t.pos.shape[1] == d and t.nrm.shape == t.pos.shape
          and t.node_internal.shape == t.node_sample.shape and t.node_sample.shape[1] == t.n_nodes
          and t.cgrid.size == int(np.prod(t.gshape)) and t.counts.shape == (4,)
          and 0 <= t.counts[0] <= N and 0 <= t.counts[2] <= S
          and (t.node_sample < N).all() and (t.cgrid < S).all()
          and g.gp_m.shape == g.gp_obs.shape == g.gp_tri.shape
          and m.slot_gen_.shape[0] >= S and m.gp_gen_.shape[0] >= g.gp_m.shape[0]
          and np.isfinite(t.pos).all() and np.isfinite(g.Lbuf).all())
    if ok:
        live = g.gp_m > 0
        ok = (not live.any()) or (
            (g.gp_obs[live] + g.gp_m[live]).max() <= g.X.shape[0]
            and (g.gp_tri[live] + g.gp_m[live] * (g.gp_m[live] + 1) // 2).max() <= g.Lbuf.shape[0])
    if not ok:
        raise ValueError("map file is inconsistent (corrupt arrays)")
    m.version_ = 1
