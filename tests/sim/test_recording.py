"""Recordings round-trip exactly, and corrupt or wrong-version files raise clear errors."""

import json
import zipfile

import numpy as np
import pytest

from polar_sim.sim import World
from polar_sim.sim.recorders.recording import Recording


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
    with pytest.raises(TypeError, match="meta"):
        Recording(meta={"x": object()})


# meta is a dict of JSON values or None: 0, [] or "" used to become {} silently, and a
# non-string key would come back from the file as a string.
@pytest.mark.parametrize("meta", [0, [], "", [("a", 1)], {1: "x"}, {"a": {2: 3}}])
def test_meta_refused(meta):
    with pytest.raises(TypeError, match="meta"):
        Recording(meta=meta)


def test_meta_accepted(tmp_path):
    assert Recording().meta == {} and Recording(None).meta == {}
    src = {"a": [1, 2.5, None, True], "b": {"c": "d"}}
    rec = Recording(meta=src)
    rec.append({"t": 0.0})
    assert rec.meta == src and rec.meta is not src
    assert Recording.load(rec.save(tmp_path / "m.npz")).meta == src


def _synthetic(n=6, big=False):
    rng = np.random.default_rng(0)
    rec = Recording(meta={"kind": "synthetic"})
    for i in range(n):
        rec.append({"rgb": rng.integers(0, 255, (16, 20, 3), dtype=np.uint8),
                    "depth": rng.uniform(0.5, 4.0, (120, 160) if big else (16, 20)).astype(np.float32),
                    "mask": rng.uniform(size=(16, 20)) < 0.5, "T": np.eye(4) * (i + 1), "t": float(i)})
    return rec


# The lazy reader gives the same frames as the in-memory one, for any start/stop and key subset,
# with large per-frame arrays streamed (not read at open).
@pytest.mark.parametrize("big", [False, True])
def test_lazy_reader_matches(tmp_path, big):
    rec = _synthetic(big=big)
    p = rec.save(tmp_path / "r.npz")
    with Recording.open(p) as r:
        assert len(r) == 6 and r.meta == rec.meta and set(r.keys) == set(rec.keys)
        assert ("depth" in r.values) is (not big)
        np.testing.assert_array_equal(r.stack("T"), rec.stack("T"))
        np.testing.assert_array_equal(r.stack("depth"), rec.stack("depth"))
        got = list(r.frames(2, 5, keys=("rgb", "depth", "t")))
        assert [i for i, _ in got] == [2, 3, 4]
        for i, f in got:
            assert set(f) == {"rgb", "depth", "t"}
            for k in f:
                np.testing.assert_array_equal(f[k], rec[i][k])
        for k, v in r[-1].items():
            np.testing.assert_array_equal(v, rec[5][k])
        with pytest.raises(ValueError, match="not recorded"):
            next(r.frames(keys=("nope",)))
        with pytest.raises(IndexError):
            r[6]


def _tamper(src, dst, header_fn=None, arrays_fn=None):
    with zipfile.ZipFile(src) as z:
        header = json.loads(np.load(z.open("header.npy")).tobytes().decode())
    arrays = dict(np.load(src))
    if header_fn:
        header_fn(header)
    if arrays_fn:
        arrays_fn(arrays)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(dst, **arrays)
    return dst


# Tampered headers and arrays (valid zip checksums) raise ValueError, never another error.
@pytest.mark.parametrize("tamper", [
    lambda h: h["keys"]["T"].update(dtype="|O"),
    lambda h: h["keys"]["T"].update(shape=[-4, 4]),
    lambda h: h["keys"]["T"].update(shape="4x4"),
    lambda h: h["keys"]["rgb"].update(shape=[16, 21, 3]),
    lambda h: h["keys"]["rgb"].update(storage="jpeg"),
    lambda h: h["keys"]["rgb"].update(dtype="<f8"),
    lambda h: h.update(version="1"),
    lambda h: h.update(version=1.5),
    lambda h: h.update(n=7),
    lambda h: h.update(n=-1),
    lambda h: h.pop("keys"),
    lambda h: h["keys"].update(ghost={"storage": "raw", "shape": [], "dtype": "<f8"}),
    lambda h: h.update(meta=[1, 2]),
])
def test_tampered_headers(tmp_path, tamper):
    p = _synthetic().save(tmp_path / "r.npz")
    bad = _tamper(p, tmp_path / "bad.npz", header_fn=tamper)
    with pytest.raises(ValueError):
        Recording.load(bad)


@pytest.mark.parametrize("tamper", [
    lambda a: a.update({"png_offsets/rgb": a["png_offsets/rgb"][::-1].copy()}),
    lambda a: a.update({"png_offsets/rgb": a["png_offsets/rgb"] * 2}),
    lambda a: a.update({"png/rgb": a["png/rgb"][:-100]}),
    lambda a: a.update({"png/rgb": np.zeros_like(a["png/rgb"])}),
    lambda a: a.update({"raw/T": a["raw/T"][:3]}),
    lambda a: a.update({"raw/T": a["raw/T"].astype(np.float32)}),
    lambda a: a.pop("raw/t"),
])
def test_tampered_arrays(tmp_path, tamper):
    p = _synthetic().save(tmp_path / "r.npz")
    bad = _tamper(p, tmp_path / "bad.npz", arrays_fn=tamper)
    with pytest.raises(ValueError):
        Recording.load(bad)


# Saves refuse an integer path and anything but a regular file, and leave no temporary file.
def test_safe_saves(tmp_path):
    import os

    rec = _synthetic(2)
    with pytest.raises(TypeError, match="path"):
        rec.save(1)
    (tmp_path / "dir.npz").mkdir()
    with pytest.raises(ValueError, match="directory"):
        rec.save(tmp_path / "dir.npz")
    os.mkfifo(tmp_path / "fifo.npz")
    with pytest.raises(ValueError, match="not a regular file"):
        rec.save(tmp_path / "fifo.npz")
    with pytest.raises(ValueError, match="not a regular file"):
        rec.save("/dev/null")
    p = rec.save(tmp_path / "ok.npz")
    assert sorted(x.name for x in tmp_path.iterdir()) == ["dir.npz", "fifo.npz", "ok.npz"]
    assert len(Recording.load(p)) == 2
    with pytest.raises(TypeError, match="dtype"):
        Recording().append({"a": np.array(["text"])})
