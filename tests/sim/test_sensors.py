"""Sensor noise models, intrinsics and the lidar/camera outputs' shapes and units."""

import numpy as np
import pytest

from polar_sim.sim import DepthNoise, RangeNoise, World


@pytest.fixture(scope="module")
def office():
    w = World("office2d", seed=1)
    w.step((0.5, 0.0))
    yield w
    w.close()


# Noise is off by default: two renders and two scans of the same state are identical.
def test_noise_off_by_default(office):
    a, b = office.lidar("lidar"), office.lidar("lidar")
    np.testing.assert_array_equal(a.ranges, b.ranges)
    f1, f2 = office.camera("front", width=160, height=120), office.camera("front", width=160, height=120)
    np.testing.assert_array_equal(f1.depth, f2.depth)


# Range noise has the requested spread and dropout rate, and is reproducible from the seed.
def test_range_noise_statistics():
    def scans(seed):
        w = World("office2d", seed=1, noise={"lidar": RangeNoise(sigma=0.01, dropout=0.05)})
        clean = World("office2d", seed=1)
        w.reset(seed=seed)
        out = [w.lidar("lidar").ranges for _ in range(20)]
        return np.array(out), clean.lidar("lidar").ranges
    noisy, clean = scans(7)
    noisy2, _ = scans(7)
    np.testing.assert_array_equal(noisy, noisy2)
    hit = np.isfinite(clean)
    err = (noisy[:, hit] - clean[hit])[np.isfinite(noisy[:, hit])]
    assert abs(err.std() - 0.01) < 0.001 and abs(err.mean()) < 0.001
    drop = np.mean(~np.isfinite(noisy[:, hit]))
    assert 0.04 < drop < 0.06


# Kinect-like depth noise grows with depth and quantises in disparity; switchable off again.
def test_depth_noise(office):
    office.set_noise("front", DepthNoise(dropout=0.0, edge_px=0))
    noisy = office.camera("front", width=320, height=240)
    office.set_noise("front", None)
    clean = office.camera("front", width=320, height=240)
    ok = np.isfinite(clean.depth) & np.isfinite(noisy.depth)
    err = noisy.depth[ok] - clean.depth[ok]
    z = clean.depth[ok]
    near, far = (z < 2), (z > 5)
    assert np.abs(err[near]).std() < np.abs(err[far]).std()
    # Quantisation: far depths take few distinct values (steps grow as z^2).
    assert len(np.unique(noisy.depth[ok][far])) < len(np.unique(clean.depth[ok][far]))
    with pytest.raises(TypeError):
        office.set_noise("front", RangeNoise())
    with pytest.raises(ValueError, match="unknown sensor"):
        office.set_noise("rear", None)


# Outputs have the documented dtypes, shapes and units.
def test_output_types(office):
    f = office.camera("front", width=320, height=240)
    assert f.rgb.dtype == np.uint8 and f.rgb.shape == (240, 320, 3)
    assert f.depth.dtype == np.float32 and f.labels.shape == (240, 320)
    assert f.K[0, 0] == pytest.approx(120 / np.tan(np.radians(30)))
    s = office.lidar("lidar")
    assert s.angles.shape == (1081,) and s.ranges.shape == (1081,)
    assert s.angles[0] == pytest.approx(-np.radians(135)) and s.angles[-1] == pytest.approx(np.radians(135))
    assert np.all(~np.isfinite(s.ranges) | ((s.ranges >= 0.1) & (s.ranges <= 30)))
    s3 = office.lidar("lidar3d")
    assert s3.directions.shape == (32 * 1024, 3)
    np.testing.assert_allclose(np.linalg.norm(s3.directions, axis=1), 1.0)
