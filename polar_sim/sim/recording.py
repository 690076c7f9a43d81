"""Recordings: a sequence of frames (sensor data plus truth) saved to one ``.npz`` and loaded back
exactly, so modules and experiments can replay it without running the simulator.

Every frame is a dict with the same keys, shapes and dtypes. uint8/bool/uint16 images are stored
PNG-compressed (lossless); everything else is stacked into arrays and stored with zip
compression. Scalars and small arrays (poses, timestamps) come back with their dtype. The file
holds a JSON header with a format version and the recording's metadata. No pickle anywhere.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import cv2
import numpy as np

__all__ = ["Recording", "FORMAT_VERSION"]

FORMAT_VERSION = 1
_PNG_DTYPES = (np.uint8, np.uint16, np.bool_)


def _is_image(a):
    a = np.asarray(a)
    return (a.dtype.type in _PNG_DTYPES and a.ndim in (2, 3) and a.shape[0] >= 8 and a.shape[1] >= 8
            and (a.ndim == 2 or a.shape[2] in (1, 3, 4)))


class Recording:
    """An in-memory sequence of frames with JSON-able metadata.

    >>> rec = Recording(meta={"scene": "rover_flat", "seed": 0})
    >>> rec.append({"rgb": frame.rgb, "T_world_cam": frame.T_world_cam, "t": frame.t})
    >>> rec.save("run.npz"); rec2 = Recording.load("run.npz")
    >>> rec2[0]["rgb"]; rec2.stack("T_world_cam")      # (n, 4, 4)
    """

    def __init__(self, meta=None):
        self.meta = dict(meta or {})
        json.dumps(self.meta)  # fail early on metadata that cannot be saved
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
            if not isinstance(k, str) or "/" in k:
                raise ValueError(f"frame: keys must be strings without '/', got {k!r}")
            a = np.array(v)  # a copy: the recording must not alias the caller's buffers
            if a.dtype == object:
                raise TypeError(f"frame[{k!r}]: object arrays cannot be recorded")
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
        """Write the recording to ``path`` (``.npz``)."""
        path = Path(path)
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
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".part")
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        tmp.replace(path)  # atomic: an interrupted save never leaves a truncated recording
        return path

    @classmethod
    def load(cls, path):
        """Read a recording written by :meth:`save`.

        Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a corrupt,
        truncated or wrong-version file.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"path: recording {str(path)!r} does not exist")
        try:
            with np.load(path, allow_pickle=False) as z:
                files = {k: z[k] for k in z.files}
        except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
            raise ValueError(f"path: {str(path)!r} is not a readable recording (corrupt or truncated): {exc}") from exc
        if "header" not in files:
            raise ValueError(f"path: {str(path)!r} has no recording header")
        try:
            header = json.loads(bytes(files["header"]).decode())
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"path: {str(path)!r} has a corrupt header") from exc
        if header.get("format") != "polar_sim.recording":
            raise ValueError(f"path: {str(path)!r} is not a polar_sim recording")
        if header.get("version") != FORMAT_VERSION:
            raise ValueError(f"path: {str(path)!r} has recording format version {header.get('version')}; "
                             f"this polar_sim reads version {FORMAT_VERSION}")
        rec = cls(header["meta"])
        n = header["n"]
        columns = {}
        for k, info in header["keys"].items():
            shape, dtype = tuple(info["shape"]), np.dtype(info["dtype"])
            if info["storage"] == "raw":
                col = files.get(f"raw/{k}")
                if col is None or col.shape != (n,) + shape:
                    raise ValueError(f"path: {str(path)!r}: key {k!r} is missing or has the wrong shape")
                columns[k] = [col[i] for i in range(n)]
            else:
                blob, off = files.get(f"png/{k}"), files.get(f"png_offsets/{k}")
                if blob is None or off is None or len(off) != n + 1 or off[-1] != len(blob):
                    raise ValueError(f"path: {str(path)!r}: PNG data of {k!r} is missing or truncated")
                imgs = []
                for i in range(n):
                    flag = cv2.IMREAD_UNCHANGED
                    img = cv2.imdecode(blob[off[i] : off[i + 1]], flag)
                    if img is None:
                        raise ValueError(f"path: {str(path)!r}: frame {i} of {k!r} is corrupt")
                    if img.ndim == 3 and img.shape[2] == 3:
                        img = img[..., ::-1]
                    img = img.reshape(shape).astype(dtype)
                    imgs.append(np.ascontiguousarray(img))
                columns[k] = imgs
        for i in range(n):
            rec.append({k: columns[k][i] for k in columns})
        return rec
