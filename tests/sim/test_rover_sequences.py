"""Rover route recordings: truth consistency and determinism (a CI-sized cut of a route)."""

import numpy as np
import pytest

from polar_sim.sim.recorders.rover_sequences import (DEV_FAMILIES, DEV_ONLY_FAMILIES, ROUTES, SPLITS, TEST_ONLY_FAMILIES, TEST_ROUTES, load_route,
                                           record_route, reduce2x)


@pytest.fixture(scope="module")
def flat():
    return record_route("flat_00", max_frames=25, progress=False)


# Ten routes of 500-2000 m at 5-12 m/s, on both rover scenes.
def test_route_table():
    assert len(ROUTES) >= 10
    assert {r.scene for r in ROUTES.values()} == {"rover_terrain", "rover_flat"}
    assert all(5.0 <= r.v_min < r.v_max <= 12.0 for r in ROUTES.values())


# The held-out protocol: test seeds are >= 10,000 and disjoint from dev; every family appears in the
# test split, the test-only families never in dev; dev uses only the dev families.
def test_splits():
    assert set(SPLITS["dev"]) == set(ROUTES) and set(SPLITS["test"]) == set(TEST_ROUTES)
    assert all(r.seed >= 10_000 for r in TEST_ROUTES.values()) and all(r.seed < 10_000 for r in ROUTES.values())
    dev_looks = {r.appearance for r in ROUTES.values()} - {None}
    assert dev_looks == set(DEV_FAMILIES) and not dev_looks & set(TEST_ONLY_FAMILIES)
    assert {r.appearance for r in TEST_ROUTES.values()} >= (set(DEV_FAMILIES) - set(DEV_ONLY_FAMILIES)) | set(TEST_ONLY_FAMILIES)
    assert not {r.appearance for r in TEST_ROUTES.values()} & set(DEV_ONLY_FAMILIES)
    assert len(TEST_ONLY_FAMILIES) >= 2


# Frames are the 2x-reduced KITTI-like image with K halved about pixel centres.
def test_frames_and_intrinsics(flat):
    f = flat[0]
    assert f["rgb"].shape == (188, 621, 3) and f["rgb"].dtype == np.uint8
    assert f["ground_mask"].shape == (188, 621) and f["ground_mask"].dtype == bool
    K = np.array(flat.meta["K"])
    assert K[0, 0] == pytest.approx(718.856 / 2, rel=1e-3)
    assert K[0, 2] == pytest.approx((1242 - 1) / 4) and K[1, 2] == pytest.approx((376 - 1) / 4)
    assert reduce2x(np.zeros((376, 1242, 3), np.uint8)).shape == (188, 621, 3)


# On flat ground the camera height along its down axis is the mounting height, the fitted ground
# surface is the plane y = h (other coefficients ~0), and the speed is the norm of v_cam.
def test_flat_truth(flat):
    h = flat.stack("h_y")
    assert np.all(np.abs(h - 1.65) < 0.02)
    c = flat.stack("surface_coeffs")[-1]
    assert abs(c[5] - 1.65) < 0.03 and np.all(np.abs(c[:5]) < 0.01)
    np.testing.assert_allclose(flat.stack("speed"), np.linalg.norm(flat.stack("v_cam"), axis=1))
    # The camera moves along its optical axis (nonholonomic): sideways speed is tiny.
    v = flat.stack("v_cam")
    assert np.all(np.abs(v[:, 0]) <= 0.01 * np.abs(v[:, 2]) + 1e-3)
    # The first frame starts at rest and is flagged static.
    assert flat[0]["static"]


# The recorded camera poses advance by the recorded speed times dt.
def test_speed_matches_poses(flat):
    T = flat.stack("T_world_cam")
    step = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    v = flat.stack("speed")
    dt = flat.meta["dt"]
    np.testing.assert_allclose(step[5:], 0.5 * (v[5:-1] + v[6:]) * dt, rtol=0.05, atol=2e-3)


# The same route records bit for bit; the cache returns what was recorded; bad names raise.
def test_determinism_and_cache(flat, tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    again = load_route("flat_00", max_frames=25)
    assert len(again) == 25 and again.path.is_relative_to(tmp_path)
    for (_, a), b in zip(again.frames(), flat):
        for k in b:
            np.testing.assert_array_equal(a[k], b[k])
    cached = load_route("flat_00", max_frames=25)
    assert cached.path == again.path
    np.testing.assert_array_equal(cached[24]["rgb"], flat[24]["rgb"])
    with pytest.raises(ValueError, match="valid"):
        record_route("moon_00")
    with pytest.raises(ValueError, match="max_frames"):
        record_route("flat_00", max_frames=0)


# A test route records its appearance: the resolved spec and the zone families are in the meta, and the
# ground mask still covers the lower image.
def test_test_route_with_an_appearance():
    rec = record_route("test_checker", max_frames=3, progress=False)
    assert rec.meta["zones"] == ["checker"] * 4 and rec.meta["appearance"]["ground"][0]["family"] == "checker"
    m = rec[2]["ground_mask"]
    assert m[-20:].mean() > 0.95 and m[:40].mean() < 0.05
