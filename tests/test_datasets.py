"""The shipped data: loaders, shapes against the documented layout, and clear errors on bad files."""

import json

import numpy as np
import pytest

from polar_sim import datasets


# gazebo1 loads from the copy inside the package, with its documented layout and offset
def test_gazebo1_layout(monkeypatch):
    monkeypatch.delenv("POLAR_SIM_DATA", raising=False)
    g = datasets.load_gazebo1()
    assert g["ranges"].shape == (2879, 270) and g["ranges"].dtype == np.float64
    assert g["poses"].shape == (2879, 3) and g["thetas"].shape == (270,)
    np.testing.assert_array_equal(g["sensor_offset"], [0.08, 0.0])
    np.testing.assert_array_equal(g["demo_frames"], np.arange(100, 2801, 100))
    # spec §2.1: all ranges finite and inside [1.09, 20.30] m, beams -135..+134 deg at 1 deg
    assert np.isfinite(g["ranges"]).all() and 1.0 < g["ranges"].min() and g["ranges"].max() < 20.4
    np.testing.assert_allclose(np.degrees(g["thetas"][[0, -1]]), [-135.0, 134.0], atol=1e-3)   # float32 angles
    assert "simulation" in g["provenance"]["dataset"].lower()


# the Intel Lab log: 910 scans of 180 beams; consecutive corrected scans overlap (a real log)
def test_intel_lab_layout(monkeypatch):
    monkeypatch.delenv("POLAR_SIM_DATA", raising=False)
    d = datasets.load_intel_lab()
    assert d["ranges"].shape == (910, 180) and d["poses"].shape == (910, 3)
    np.testing.assert_allclose(np.degrees(d["angles"][[0, -1]]), [-90.0, 89.0], atol=1e-6)
    r = d["ranges"]
    assert np.isinf(r).mean() < 0.05 and r[np.isfinite(r)].max() < 26.0
    assert d["benchmark_relations"].shape == (2984, 5)
    assert "Haehnel" in d["provenance"]["recorded_by"] or "Hähnel" in d["provenance"]["recorded_by"]
    # the relations cover the whole log: their time stamps span this log's
    rel = d["benchmark_relations"]
    assert rel[:, 0].min() <= d["t_abs"].min() + 60 and rel[:, 1].max() >= d["t_abs"].max() - 60


def _write(tmp_path, name, **arrays):
    np.savez(tmp_path / name, **arrays)


# a file without a needed array names the file and the array
def test_missing_array_is_named(tmp_path, monkeypatch):
    good = dict(np.load(datasets.data_path("intel_lab.npz")))
    monkeypatch.setenv("POLAR_SIM_DATA", str(tmp_path))
    good.pop("odom")
    _write(tmp_path, "intel_lab.npz", **good)
    with pytest.raises(ValueError, match=r"intel_lab\.npz.*odom"):
        datasets.load_intel_lab()


# a truncated file, NaN poses and a pickled object array are refused with the file's name
def test_corrupt_files_are_refused(tmp_path, monkeypatch):
    src = datasets.data_path("gazebo1.npz").read_bytes()
    monkeypatch.setenv("POLAR_SIM_DATA", str(tmp_path))
    (tmp_path / "gazebo1.npz").write_bytes(src[: len(src) // 2])
    with pytest.raises(ValueError, match="gazebo1.npz"):
        datasets.load_gazebo1()
    g = dict(np.load(datasets._SHIPPED / "gazebo1.npz"))
    g["poses"] = g["poses"].copy()
    g["poses"][3, 1] = np.nan
    _write(tmp_path, "gazebo1.npz", **g)
    with pytest.raises(ValueError, match="poses"):
        datasets.load_gazebo1()
    g = dict(np.load(datasets._SHIPPED / "gazebo1.npz"))
    g["demo_frames"] = np.array([None, 1], dtype=object)
    _write(tmp_path, "gazebo1.npz", **g)
    with pytest.raises(ValueError, match="gazebo1.npz"):
        datasets.load_gazebo1()


# POLAR_SIM_DATA that is not a folder, a missing file, and a name escaping the folder
def test_override_and_names(tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_SIM_DATA", str(tmp_path / "nope"))
    with pytest.raises(FileNotFoundError, match="POLAR_SIM_DATA"):
        datasets.load_gazebo1()
    monkeypatch.setenv("POLAR_SIM_DATA", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="gazebo1.npz"):
        datasets.load_gazebo1()
    with pytest.raises(ValueError, match="escapes"):
        datasets.data_path("../../etc/passwd")


# the shipped README names every shipped file, and each provenance is JSON with a format version
def test_shipped_files_documented():
    readme = (datasets._SHIPPED / "README.md").read_text()
    for p in datasets._SHIPPED.rglob("*.npz"):
        assert f"`{p.relative_to(datasets._SHIPPED).as_posix()}`" in readme, p
    for name in ("gazebo1.npz", "intel_lab.npz"):
        with np.load(datasets._SHIPPED / name, allow_pickle=False) as z:
            assert json.loads(str(z["provenance"]))["format_version"] == 1
