"""One cache for every recorded input: rover routes, tabletop sequences, office drives, orbits.

A recorded input is a deterministic function of (kind, scene, seed, options) and of the code that
generates it. :func:`cached` keys a :class:`~polar_sim.sim.recorders.recording.Recording` by those, plus
a generator ``version`` the caller bumps when its generation code changes, and the recording
format version; it records the input once (under a file lock, so parallel workers that need the
same missing input wait for one recorder) and returns a lazy reader. :func:`cached_arrays` does
the same for derived arrays (e.g. RANSAC candidate sets), saved as ``.npz``.

The cache lives in ``$POLAR_SIM_CACHE`` (default ``~/.cache/polar_sim``), one folder per kind;
deleting any file in it is always safe.

>>> from polar_sim.sim.recorders import sequences
>>> r = sequences.cached("office_drive", {"scene": "office2d", "seed": 3, "duration_s": 60},
...                      lambda: record_drive(...), version=1)
>>> len(r), r.meta, r.stack("pose2d")
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
from pathlib import Path
from collections.abc import Callable, Mapping

import numpy as np

from polar_sim.fileio import atomic_write
from polar_sim.sim.recorders.recording import FORMAT_VERSION, Recording, RecordingReader

__all__ = ["cache_root", "cache_path", "cached", "cached_arrays", "cache_lock"]

logger = logging.getLogger(__name__)
_ARRAYS_VERSION = 1


def cache_root() -> Path:
    """``$POLAR_SIM_CACHE`` or ``~/.cache/polar_sim``."""
    return Path(os.environ.get("POLAR_SIM_CACHE") or Path.home() / ".cache" / "polar_sim").expanduser()


def _check_kind(kind):
    if not isinstance(kind, str) or not re.fullmatch(r"[a-z][a-z0-9_]{0,40}", kind):
        raise ValueError(f"kind: expected a short lower-case name like 'office_drive', got {kind!r}")


def cache_path(kind: str, key: Mapping, *, version: int = 1, suffix: str = ".npz", fmt: int = FORMAT_VERSION) -> Path:
    """The cache file of ``(kind, key, version)``: ``<root>/<kind>/<slug>-<hash>.npz``."""
    _check_kind(kind)
    if not isinstance(key, Mapping):
        raise TypeError(f"key: expected a dict of JSON-able values, got {type(key).__name__}")
    if isinstance(version, bool) or not isinstance(version, int):
        raise TypeError(f"version: expected an int, got {version!r}")
    try:
        text = json.dumps({"kind": kind, "key": key, "version": version, "format": fmt}, sort_keys=True)
    except TypeError as exc:
        raise TypeError(f"key: values must be JSON-able ({exc})") from None
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    slug = re.sub(r"[^A-Za-z0-9.=-]+", "-", "_".join(f"{k}={key[k]}" for k in sorted(key)
                                                      if isinstance(key[k], (str, int, float))))[:80]
    return cache_root() / kind / f"{slug}-{digest}{suffix}"


@contextlib.contextmanager
def cache_lock(path: Path):
    """An exclusive advisory lock (``fcntl.flock``) tied to a cache file."""
    lock = path.with_name(f".{path.name}.lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "a") as fh:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX
            yield
            return
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _open_or_none(path):
    if not path.is_file():
        return None
    try:
        return RecordingReader(path)
    except ValueError as exc:        # a corrupt cache entry is rebuilt, never trusted
        logger.warning("cache entry %s is unreadable (%s); recording it again", path, exc)
        return None


def cached(kind: str, key: Mapping, build: Callable[[], Recording], *, version: int = 1) -> RecordingReader:
    """The recording of ``(kind, key, version)``: read from the cache, or built with ``build()``,
    saved and then read. ``build`` must be deterministic in ``key``."""
    path = cache_path(kind, key, version=version)
    reader = _open_or_none(path)
    if reader is not None:
        return reader
    with cache_lock(path):
        reader = _open_or_none(path)
        if reader is None:
            rec = build()
            if not isinstance(rec, Recording):
                raise TypeError(f"build: expected a Recording, got {type(rec).__name__}")
            rec.meta.setdefault("cache_key", {"kind": kind, "key": dict(key), "version": version})
            rec.save(path)
            reader = RecordingReader(path)
    return reader


def _load_arrays(path):
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError) as exc:
        logger.warning("cache entry %s is unreadable (%s); computing it again", path, exc)
        return None
    out.pop("_cache_format", None)
    return out


def cached_arrays(kind: str, key: Mapping, build: Callable[[], Mapping], *, version: int = 1) -> dict:
    """Derived arrays of ``(kind, key, version)``: read from the cache, or ``build()`` them (a dict
    of numeric arrays), save and return them."""
    path = cache_path(kind, key, version=version, fmt=_ARRAYS_VERSION)
    out = _load_arrays(path)
    if out is not None:
        return out
    with cache_lock(path):
        out = _load_arrays(path)
        if out is None:
            arrays = {k: np.asarray(v) for k, v in dict(build()).items()}
            bad = [k for k, a in arrays.items() if a.dtype.hasobject]
            if bad:
                raise TypeError(f"build: arrays {bad} are object arrays (they would need pickle)")
            with atomic_write(path) as fh:
                np.savez_compressed(fh, _cache_format=np.int64(_ARRAYS_VERSION), **arrays)
            out = arrays
    return out
