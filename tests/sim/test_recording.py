"""Recordings round-trip exactly, and corrupt or wrong-version files raise clear errors."""

import json
import zipfile

import numpy as np
import pytest

from polar_sim.sim import World
from polar_sim.sim.recording import Recording


def _record(n=3):
    rec = Recording(meta={"scene": "office2d", "seed": 0})
    with World("office2d", seed=0) as w:
        for _ in range(n):
            w.step((1.0, 0.1))
            f = w.camera("front", width=96, height=64)
            s = w.lidar("lidar")
            rec.append({"rgb": f.rgb, "depth": f.depth, "labels": f.labels.astype(np.uint8),
                        "mask": f.labels == 1, "T": f.T_world_cam, "t": f.t, "ranges": s.ranges})
    return rec


# Saving and loading gives back every frame bit for bit.
def test_round_trip(tmp_path):
    rec = _record()
    rec.save(tmp_path / "r.npz")
    back = Recording.load(tmp_path / "r.npz")
    assert back.meta == rec.meta and len(back) == len(rec)
    for a, b in zip(rec, back):
        assert a.keys() == b.keys()
        for k in a:
            assert a[k].dtype == b[k].dtype
            np.testing.assert_array_equal(a[k], b[k])


# Corrupt, truncated, wrong-version and missing files raise ValueError / FileNotFoundError.
def test_bad_files(tmp_path):
    rec = _record(1)
    p = rec.save(tmp_path / "r.npz")
    data = p.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="corrupt or truncated"):
        Recording.load(tmp_path / "trunc.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError):
        Recording.load(tmp_path / "junk.npz")
    with zipfile.ZipFile(p) as z:
        header = json.loads(np.load(z.open("header.npy")).tobytes().decode())
    header["version"] = 99
    arrays = dict(np.load(p))
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(tmp_path / "v99.npz", **arrays)
    with pytest.raises(ValueError, match="version 99"):
        Recording.load(tmp_path / "v99.npz")
    with pytest.raises(FileNotFoundError):
        Recording.load(tmp_path / "nope.npz")


# Frames must share keys, shapes and dtypes; metadata must be JSON.
def test_schema_checks():
    rec = Recording()
    rec.append({"a": np.zeros(3)})
    with pytest.raises(ValueError, match="differ"):
        rec.append({"a": np.zeros(4)})
    with pytest.raises(TypeError):
        Recording(meta={"x": object()})
