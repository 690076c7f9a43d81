"""GPIS map files (issue 17, "Saved state"): atomic saves that refuse bad destinations, and a
loader that treats the file as untrusted input (tampered files raise ValueError, never crash)."""

import os

import numpy as np
import pytest

from ci_sizes import size
from polar_sim.gpis import GPISMap2D, GPISMap3D

from . import iofaults
from .test_behaviour import _map2d, _map3d

N_KILLS = size(20, 5)           # full size: benchmarks/bench_gpis_io.py


def _bytes(path):
    with open(path, "rb") as f:
        return f.read()


# a save goes through a temporary file in the same folder: none is left behind, before or after
def test_save_atomic_no_stray_files(tmp_path):
    m = _map2d(2)
    p = tmp_path / "m.npz"
    m.save(p)
    m.save(p)
    assert sorted(os.listdir(tmp_path)) == ["m.npz"]
    m2 = GPISMap2D.load(p)
    pts = m.samples()["points"][:20] + 0.01
    for a, b in zip(m.query(pts), m2.query(pts)):
        np.testing.assert_array_equal(a, b)


# a save that fails mid-write leaves the previous file intact and removes its temporary file
def test_save_failure_keeps_old_file(tmp_path, monkeypatch):
    m = _map2d(2)
    p = tmp_path / "m.npz"
    m.save(p)
    old = _bytes(p)

    def boom(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", boom)
    with pytest.raises(OSError, match="disk full"):
        m.save(p)
    monkeypatch.undo()
    assert _bytes(p) == old
    assert sorted(os.listdir(tmp_path)) == ["m.npz"]


# destinations a save must never use: an int (a file descriptor), a directory, a device, a FIFO
def test_save_refuses_bad_destinations(tmp_path):
    m = _map2d(2)
    with pytest.raises(TypeError, match="path"):
        m.save(1)
    with pytest.raises(TypeError, match="path"):
        m.save(None)
    with pytest.raises(ValueError, match="directory"):
        m.save(tmp_path)
    with pytest.raises(ValueError, match="not a regular file"):
        m.save("/dev/null")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="not a regular file"):
        m.save(fifo)
    assert sorted(os.listdir(tmp_path)) == ["fifo"]
    with pytest.raises(TypeError, match="path"):
        GPISMap2D.load(1)
    with pytest.raises(FileNotFoundError, match="path"):
        GPISMap2D.load(tmp_path / "missing.npz")
    with pytest.raises(ValueError, match="path"):
        GPISMap2D.load(fifo)


# a process re-saving a large map is SIGKILLed at random moments: the file always loads intact
@pytest.mark.slow
def test_kill_mid_save(tmp_path):
    ref = tmp_path / "ref.npz"
    _map3d(3).save(ref)
    assert ref.stat().st_size > 4_000_000          # large enough that kills land mid-write
    target = tmp_path / "target.npz"
    res = iofaults.kill_mid_save(ref, target, N_KILLS, dim=3, seed=1)
    assert [r for r in res if not r[1]] == []
    assert sum(r[3] for r in res) >= 1              # at least one kill landed mid-write
    assert sorted(os.listdir(tmp_path)) == ["ref.npz", "target.npz"]


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    d = tmp_path_factory.mktemp("gpis-bases")
    names = iofaults.write_bases(d, n2=3, n3=1)
    return d, names


# every tampered file (valid zip checksums) raises ValueError naming the file; none crashes,
# hangs or is accepted; the cases run in worker subprocesses with a time limit, every one of them
# (1,085 from the same bases as benchmarks/bench_gpis_io.py; a worker takes 60 at a time: about 30 s)
def test_tampered_files(bases):
    d, names = bases
    cases = iofaults.all_cases(d, names)
    assert len(cases) >= 200
    res = iofaults.run_tampered(d, names)
    bad = {f"{cases[i][0]}:{cases[i][1]}": o for i, o in res.items() if o != "clear"}
    assert bad == {}
    assert len(res) == len(cases)


# the tamper harness can fail: the valid base files load, and an untouched copy, a worker that
# segfaults and one that hangs are reported as such, the harness going on after each
def test_tamper_harness_baseline(bases):
    d, names = bases
    for name in names:
        cls = GPISMap3D if name.startswith("3d") else GPISMap2D
        cls.load(d / f"{name}.npz")
    name = names[0]
    assert name.startswith("2d")
    labels = [lab for _, lab, _ in iofaults.all_cases(d, [name], selftest=True)]
    first = iofaults.run_tampered(d, [name], [0, 1, 2], selftest=True)
    # a short limit for the hang; the worker's import and load take a few seconds
    second = iofaults.run_tampered(d, [name], [3, 4], selftest=True, timeout=20.0)
    got = {labels[i]: o for i, o in {**first, **second}.items()}
    assert got == {"selftest:untouched": "accepted", "selftest:segfault": "crash", labels[2]: "clear",
                   "selftest:sleep": "hang", labels[4]: "clear"}


# the messages name the file and the array
def test_load_messages_name_file_and_array(tmp_path):
    m = _map2d(2)
    good = tmp_path / "good.npz"
    m.save(good)
    with np.load(good, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    ns = data["tree/node_sample"].copy()
    ns[0, 0] = np.iinfo(np.int32).max
    np.savez(tmp_path / "a.npz", **{**data, "tree/node_sample": ns})
    with pytest.raises(ValueError, match=r"a\.npz.*'tree/node_sample'"):
        GPISMap2D.load(tmp_path / "a.npz")
    for v in (np.array("1"), np.array(1.5), np.array(True)):
        np.savez(tmp_path / "v.npz", **{**data, "version": v})
        with pytest.raises(ValueError, match=r"v\.npz.*'version'"):
            GPISMap2D.load(tmp_path / "v.npz")
    X = data["gp/X"].copy()
    X[0, 0] = np.nan
    np.savez(tmp_path / "x.npz", **{**data, "gp/X": X})
    with pytest.raises(ValueError, match=r"'gp/X' contains NaN"):
        GPISMap2D.load(tmp_path / "x.npz")
    g = data["free/gshape"].copy()
    g[0] = -g[0]
    np.savez(tmp_path / "g.npz", **{**data, "free/gshape": g})
    with pytest.raises(ValueError, match=r"'free/gshape'"):
        GPISMap2D.load(tmp_path / "g.npz")


# A file written before NoiseConfig2D.reevaluation existed holds a map built with the gates alone:
# it loads with "gated" and goes on as it was built, not with today's default
def test_a_file_without_the_reevaluation_field_loads_gated(tmp_path):
    import json

    m = _map2d()
    m.save(tmp_path / "new.npz")
    assert GPISMap2D.load(tmp_path / "new.npz").get_params()["noise"].reevaluation == "on_returns"
    with np.load(tmp_path / "new.npz") as z:
        arrs = dict(z)
    params = json.loads(str(arrs["params"]))
    del params["noise"]["reevaluation"]
    arrs["params"] = np.array(json.dumps(params))
    np.savez(tmp_path / "old.npz", **arrs)
    old = GPISMap2D.load(tmp_path / "old.npz")
    assert old.get_params()["noise"].reevaluation == "gated"
    assert old.get_params()["noise"].range_noise == m.get_params()["noise"].range_noise
    np.testing.assert_array_equal(old.samples()["points"], m.samples()["points"])


# Format version 3 stores how far each sample's face was seen to run on (tree/run); a version-2 file
# has none, and loads with every face running on: the surface gate it was built with
def test_a_version_2_file_loads_with_every_face_running_on(tmp_path):
    from polar_sim.gpis import _io, _surface

    m = _map2d()
    m.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as z:
        arrs = dict(z)
    assert int(arrs["version"]) == _io.VERSION == 3
    again = GPISMap2D.load(tmp_path / "new.npz")
    np.testing.assert_array_equal(again.tree_.run, m.tree_.run)
    assert (m.tree_.run[m.tree_.alive()] > 0).any()
    old = {k: v for k, v in arrs.items() if k != "tree/run"}
    np.savez(tmp_path / "v2.npz", **{**old, "version": np.array(2)})
    v2 = GPISMap2D.load(tmp_path / "v2.npz")
    assert np.isinf(v2.tree_.run).all()
    assert v2.surface(face_end_bare=_surface.FACE_END_BARE) is not None
    v2.save(tmp_path / "v2-resaved.npz")                 # inf runs are valid in a version-3 file
    assert np.isinf(GPISMap2D.load(tmp_path / "v2-resaved.npz").tree_.run).all()
    # a version-2 file with runs, or a version-3 file without, is refused naming the array
    np.savez(tmp_path / "bad2.npz", **{**arrs, "version": np.array(2)})
    with pytest.raises(ValueError, match=r"'tree/run' is not part of the format"):
        GPISMap2D.load(tmp_path / "bad2.npz")
    np.savez(tmp_path / "bad3.npz", **old)
    with pytest.raises(ValueError, match=r"'tree/run' is missing"):
        GPISMap2D.load(tmp_path / "bad3.npz")
