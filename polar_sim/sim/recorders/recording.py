"""Recordings: a sequence of frames (sensor data plus truth) saved to one ``.npz`` and read back
exactly, so modules and experiments can replay it without running the simulator.

Every frame is a dict with the same keys, shapes and dtypes. uint8/bool/uint16 images are stored
PNG-compressed (lossless); everything else is stacked into arrays and stored with zip
compression. The file holds a JSON header with a format version and the recording's metadata.
No pickle anywhere. :meth:`Recording.load` reads a file into memory; :meth:`Recording.open`
reads it lazily, one frame at a time, for long sequences. A file is untrusted input: its header
is checked against its arrays before anything is decoded.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np

from polar_sim.fileio import atomic_write, check_source

__all__ = ["Recording", "RecordingReader", "FORMAT_VERSION"]

FORMAT_VERSION = 1
_PNG_DTYPES = (np.uint8, np.uint16, np.bool_)
_ALLOWED_KINDS = "biuf"           # bool, signed/unsigned integers, floats: nothing that needs pickle
_SMALL_BYTES = 65536             # per-frame raw values up to this size are read at open; larger ones streamed


def _is_image(a):
    a = np.asarray(a)
    return (a.dtype.type in _PNG_DTYPES and a.ndim in (2, 3) and a.shape[0] >= 8 and a.shape[1] >= 8
            and (a.ndim == 2 or a.shape[2] in (1, 3, 4)))


def _decode_png(buf, shape, dtype, where):
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{where} is corrupt")
    if img.ndim == 3 and img.shape[2] == 3:
        img = img[..., ::-1]
    if img.size != int(np.prod(shape)):
        raise ValueError(f"{where} decodes to shape {img.shape}, the header says {tuple(shape)}")
    return np.ascontiguousarray(img.reshape(shape).astype(dtype))


def _check_meta(meta):
    """A copy of ``meta`` (a dict with string keys and JSON values; None is ``{}``) that saves and
    loads back equal. Raises ``TypeError`` naming ``meta`` for anything else (``0`` or ``[]`` used
    to become ``{}``; a non-string key would come back as a string)."""
    if meta is None:
        return {}
    if not isinstance(meta, Mapping):
        raise TypeError(f"meta: expected a dict of JSON values (or None), got {type(meta).__name__}")
    try:
        _check_keys(meta)
        json.dumps(dict(meta))      # fail early on metadata that cannot be saved
    except (TypeError, ValueError) as exc:
        raise TypeError(str(exc) if str(exc).startswith("meta:") else
                        f"meta: values must be JSON (str, int, float, bool, None, lists, dicts): {exc}") from None
    except RecursionError:
        raise TypeError("meta: nested too deeply (or holds itself)") from None
    return dict(meta)


def _check_keys(value):
    """Every dict key in ``value`` (nested in dicts, lists and tuples) is a string."""
    if isinstance(value, Mapping):
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError(f"meta: keys must be strings (JSON object keys), got {k!r}")
            _check_keys(v)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _check_keys(v)


class Recording:
    """An in-memory sequence of frames with JSON-able metadata.

    >>> rec = Recording(meta={"scene": "rover_flat", "seed": 0})
    >>> rec.append({"rgb": frame.rgb, "T_world_cam": frame.T_world_cam, "t": frame.t})
    >>> rec.save("run.npz"); rec2 = Recording.load("run.npz")
    >>> rec2[0]["rgb"]; rec2.stack("T_world_cam")      # (n, 4, 4)
    >>> with Recording.open("run.npz") as r:            # lazy: one frame in memory at a time
    ...     for i, f in r.frames(keys=("rgb",)): ...
    """

    def __init__(self, meta=None):
        self.meta = _check_meta(meta)
        self._frames = []
        self._schema = None

    def __len__(self):
        return len(self._frames)

    def __getitem__(self, i):
        return dict(self._frames[i])

    def __iter__(self):
        return (dict(f) for f in self._frames)

    @property
    def keys(self):
        return tuple(self._schema or ())

    def append(self, frame: dict):
        """Add one frame; its keys, shapes and dtypes must match the first frame's."""
        if not isinstance(frame, dict) or not frame:
            raise TypeError("frame: expected a non-empty dict of arrays and scalars")
        clean = {}
        for k, v in frame.items():
            if not isinstance(k, str) or not k or "/" in k:
                raise ValueError(f"frame: keys must be non-empty strings without '/', got {k!r}")
            a = np.array(v)  # a copy: the recording must not alias the caller's buffers
            if a.dtype.kind not in _ALLOWED_KINDS:
                raise TypeError(f"frame[{k!r}]: dtype {a.dtype} cannot be recorded (bool, integer or float only)")
            clean[k] = a
        schema = {k: (a.shape, a.dtype.str) for k, a in clean.items()}
        if self._schema is None:
            self._schema = schema
        elif schema != self._schema:
            diff = sorted(set(schema.items()) ^ set(self._schema.items()), key=str)
            raise ValueError(f"frame: keys, shapes or dtypes differ from the first frame: {diff[:4]}")
        self._frames.append(clean)

    def stack(self, key):
        """All frames' values of ``key`` stacked into one array (n, ...)."""
        if self._schema is None or key not in self._schema:
            raise ValueError(f"key: {key!r} is not recorded; keys: {list(self.keys)}")
        return np.stack([f[key] for f in self._frames])

    # -- files ----------------------------------------------------------------------------
    def save(self, path):
        """Write the recording to ``path`` (``.npz``), atomically.

        ``path`` must be a new path or a regular file (``ValueError`` for a directory, device or
        FIFO; ``TypeError`` for an integer). An interrupted save leaves the old file and no
        temporary file.
        """
        if self._schema is None:
            raise ValueError("recording is empty: nothing to save")
        arrays = {}
        header = {"format": "polar_sim.recording", "version": FORMAT_VERSION, "n": len(self),
                  "meta": self.meta, "keys": {}}
        for k, (shape, dtype) in self._schema.items():
            sample = self._frames[0][k]
            if _is_image(sample):
                blobs = []
                for f in self._frames:
                    img = f[k]
                    if img.dtype == np.bool_:
                        img = img.astype(np.uint8)
                    if img.ndim == 3 and img.shape[2] == 3:
                        img = img[..., ::-1]  # OpenCV writes BGR
                    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 3])
                    if not ok:
                        raise ValueError(f"frame[{k!r}]: PNG encoding failed")
                    blobs.append(buf.ravel())
                offsets = np.cumsum([0] + [len(b) for b in blobs]).astype(np.int64)
                arrays[f"png/{k}"] = np.concatenate(blobs)
                arrays[f"png_offsets/{k}"] = offsets
                header["keys"][k] = {"storage": "png", "shape": list(shape), "dtype": dtype}
            else:
                arrays[f"raw/{k}"] = self.stack(k)
                header["keys"][k] = {"storage": "raw", "shape": list(shape), "dtype": dtype}
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        with atomic_write(path) as fh:
            np.savez_compressed(fh, **arrays)
        return Path(path)

    @classmethod
    def load(cls, path):
        """Read a whole recording written by :meth:`save` into memory.

        Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a corrupt,
        truncated, tampered or wrong-version file.
        """
        with cls.open(path) as r:
            rec = cls(r.meta)
            for _, f in r.frames():
                rec.append(f)
        if len(rec) != len(r):
            raise ValueError(f"path: {str(path)!r}: {len(rec)} frames decoded, the header says {len(r)}")
        return rec

    @classmethod
    def open(cls, path):
        """A lazy :class:`RecordingReader` of ``path``: header and small values now, images on demand."""
        return RecordingReader(path)


class RecordingReader:
    """Frame-by-frame reader of a saved :class:`Recording` (format version 1).

    ``len(r)``, ``r.meta``, ``r.keys``; ``r.stack(key)`` gives a non-image key's values (n, ...);
    ``r.frames(start, stop, keys)`` yields ``(index, frame dict)`` one frame in memory at a time;
    ``r[i]`` decodes one frame. Use it as a context manager, or call :meth:`close`.
    """

    def __init__(self, path):
        self.path = check_source(path)
        where = f"path: {str(self.path)!r}"
        try:
            self._zip = zipfile.ZipFile(self.path)
        except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
            raise ValueError(f"{where} is not a readable recording (corrupt or truncated): {exc}") from None
        try:
            self._read_header(where)
        except BaseException:
            self._zip.close()
            raise

    # -- header ---------------------------------------------------------------------------
    def _npy(self, name, where):
        try:
            with self._zip.open(f"{name}.npy") as fh:
                return np.lib.format.read_array(fh, allow_pickle=False)
        except KeyError:
            raise ValueError(f"{where}: array {name!r} is missing") from None
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{where}: array {name!r} is corrupt ({exc})") from None

    def _stream(self, name, where):
        """An open stream of array ``name`` positioned after its .npy header, and the header."""
        try:
            fh = self._zip.open(f"{name}.npy")
        except KeyError:
            raise ValueError(f"{where}: array {name!r} is missing") from None
        try:
            version = np.lib.format.read_magic(fh)
            shape, fortran, dtype = (np.lib.format.read_array_header_1_0(fh) if version == (1, 0)
                                     else np.lib.format.read_array_header_2_0(fh))
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            fh.close()
            raise ValueError(f"{where}: array {name!r} is corrupt ({exc})") from None
        if fortran or dtype.hasobject:
            fh.close()
            raise ValueError(f"{where}: array {name!r} has an unexpected layout")
        return fh, shape, dtype

    def _read_header(self, where):
        raw = self._npy("header", where)
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise ValueError(f"{where} has a corrupt header")
        try:
            header = json.loads(bytes(raw).decode())
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise ValueError(f"{where} has a corrupt header") from None
        if not isinstance(header, dict) or header.get("format") != "polar_sim.recording":
            raise ValueError(f"{where} is not a polar_sim recording")
        version = header.get("version")
        if type(version) is not int or version != FORMAT_VERSION:
            raise ValueError(f"{where} has recording format version {version!r}; this polar_sim reads "
                             f"version {FORMAT_VERSION}")
        n, meta, keys = header.get("n"), header.get("meta"), header.get("keys")
        if type(n) is not int or n < 0 or not isinstance(meta, dict) or not isinstance(keys, dict) or not keys:
            raise ValueError(f"{where}: the header's n, meta or keys are malformed")
        self.meta, self.n, self.info, self.values, self._offsets = meta, n, {}, {}, {}
        for k, inf in keys.items():
            if not isinstance(inf, dict) or inf.get("storage") not in ("png", "raw"):
                raise ValueError(f"{where}: key {k!r} has a malformed header entry")
            shape = inf.get("shape")
            if not isinstance(shape, list) or any(type(s) is not int or s < 0 for s in shape) or len(shape) > 4:
                raise ValueError(f"{where}: key {k!r} has a malformed shape {shape!r}")
            if not isinstance(inf.get("dtype"), str):       # np.dtype(None) would be float64
                raise ValueError(f"{where}: key {k!r} has a malformed dtype {inf.get('dtype')!r}")
            try:
                dtype = np.dtype(inf.get("dtype"))
            except TypeError:
                raise ValueError(f"{where}: key {k!r} has a malformed dtype {inf.get('dtype')!r}") from None
            if dtype.kind not in _ALLOWED_KINDS:
                raise ValueError(f"{where}: key {k!r} has dtype {dtype} (bool, integer or float only)")
            shape = tuple(shape)
            if inf["storage"] == "png":
                if dtype.type not in _PNG_DTYPES or len(shape) not in (2, 3):
                    raise ValueError(f"{where}: key {k!r} cannot be a PNG image with dtype {dtype} and shape {shape}")
                off = self._npy(f"png_offsets/{k}", where)
                fh, bshape, bdtype = self._stream(f"png/{k}", where)
                fh.close()
                if (off.dtype.kind not in "iu" or off.shape != (n + 1,) or off[0] != 0
                        or (np.diff(off) < 0).any() or bdtype != np.uint8 or bshape != (int(off[-1]),)):
                    raise ValueError(f"{where}: the PNG data or offsets of {k!r} are malformed or truncated")
                self._offsets[k] = off.astype(np.int64)
            elif int(np.prod(shape)) * dtype.itemsize <= _SMALL_BYTES:
                col = self._npy(f"raw/{k}", where)
                if col.shape != (n,) + shape or col.dtype != dtype:
                    raise ValueError(f"{where}: key {k!r} has shape {col.shape} {col.dtype}, the header says "
                                     f"{(n,) + shape} {dtype}")
                self.values[k] = col
            else:                                 # large per-frame arrays (depth) are streamed
                fh, cshape, cdtype = self._stream(f"raw/{k}", where)
                fh.close()
                if cshape != (n,) + shape or cdtype != dtype:
                    raise ValueError(f"{where}: key {k!r} has shape {cshape} {cdtype}, the header says "
                                     f"{(n,) + shape} {dtype}")
            self.info[k] = (inf["storage"], shape, dtype)

    # -- access ---------------------------------------------------------------------------
    def __len__(self):
        return self.n

    @property
    def keys(self):
        return tuple(self.info)

    def stack(self, key):
        """The values of ``key`` for every frame, (n, ...): small per-frame values, or any key
        read whole (images decoded) when asked."""
        if key not in self.info:
            raise ValueError(f"key: {key!r} is not recorded; keys: {list(self.keys)}")
        if key in self.values:
            return self.values[key].copy()
        shape, dtype = self.info[key][1:]
        out = np.empty((self.n,) + shape, dtype)
        for i, f in self.frames(keys=(key,)):
            out[i] = f[key]
        return out

    def _reader(self, key):
        """A function ``read(i)`` of frame i's value of ``key``, for increasing i (a stream)."""
        where = f"path: {str(self.path)!r}"
        storage, shape, dtype = self.info[key]
        if key in self.values:
            col = self.values[key]
            read = lambda i: col[i].copy()  # noqa: E731
            read.skip = read.close = lambda *a: None
            return read
        if storage == "png":
            fh, _, _ = self._stream(f"png/{key}", where)
            off = self._offsets[key]

            def read(i):
                buf = np.frombuffer(fh.read(int(off[i + 1] - off[i])), np.uint8)
                return _decode_png(buf, shape, dtype, f"{where}: frame {i} of {key!r}")

            read.skip = lambda i: fh.read(int(off[i + 1] - off[i]))
        else:
            fh, _, file_dtype = self._stream(f"raw/{key}", where)
            nbytes = int(np.prod(shape)) * file_dtype.itemsize

            def read(i):
                data = fh.read(nbytes)
                if len(data) != nbytes:
                    raise ValueError(f"{where}: frame {i} of {key!r} is truncated")
                return np.frombuffer(data, file_dtype).reshape(shape).copy()

            read.skip = lambda i: fh.read(nbytes)
        read.close = fh.close
        return read

    def _keys(self, keys):
        keys = self.keys if keys is None else tuple(keys)
        bad = [k for k in keys if k not in self.info]
        if bad:
            raise ValueError(f"keys: {bad} are not recorded; keys: {list(self.keys)}")
        return keys

    def __getitem__(self, i):
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"index: expected an int, got {type(i).__name__}")
        if not -self.n <= i < self.n:
            raise IndexError(f"index: {i} is out of range for {self.n} frames")
        i = int(i) % self.n
        return next(self.frames(i, i + 1))[1]

    def frames(self, start=0, stop=None, keys=None):
        """Yield ``(index, frame)`` for frames ``start`` .. ``stop - 1`` in order, decoding only
        ``keys``; one frame is in memory at a time (earlier frames are read and skipped)."""
        keys = self._keys(keys)
        stop = self.n if stop is None else min(int(stop), self.n)
        start = max(int(start), 0)
        readers = {k: self._reader(k) for k in keys}
        try:
            for i in range(stop):
                if i < start:
                    for r in readers.values():
                        r.skip(i)
                    continue
                yield i, {k: r(i) for k, r in readers.items()}
        finally:
            for r in readers.values():
                r.close()

    def close(self):
        self._zip.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
