"""Recorded lidar drives and RGB-D orbits: seeded, cached, replayed bit for bit, on the geometry."""

import numpy as np
import pytest

from polar_sim.metrics.maps import hit_points
from polar_sim.sim import World
from polar_sim.sim.recorders import drives2d as D


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    return tmp_path


LEGS = [dict(route_seed=4, n_rooms=3, duration=8.0, every_steps=2), dict(route_seed=5, n_rooms=2, duration=4.0, every_m=0.5)]


# A recorded drive equals the same legs driven live, and is replayed from the cache without MuJoCo work.
@pytest.mark.parametrize("scene", ["office2d", "warehouse2d"])
def test_recorded_equals_live_and_replays(scene, cache):
    a = D.recorded_drives(scene, 1, LEGS)
    w = D.lidar_world(scene, 1)
    clear = D.clearance_map(w)
    live = []
    for j, leg in enumerate(LEGS):
        if j:
            w.reset()
        path = D.plan_route(w, leg["route_seed"], n_rooms=leg["n_rooms"], clearance=clear)
        live.append(D.drive(w, path, duration=leg["duration"], every_m=leg.get("every_m"),
                            every_steps=leg.get("every_steps", 1)))
    w.close()
    files = list((cache / "lidar_drive").glob("*.npz"))
    assert len(files) == 1
    b = D.recorded_drives(scene, 1, LEGS)
    for x, y, z in zip(a, b, live):
        for k in ("angles", "poses", "ranges", "clean", "travelled", "base_poses"):
            np.testing.assert_array_equal(getattr(x, k), getattr(z, k), err_msg=k)
            np.testing.assert_array_equal(getattr(x, k), getattr(y, k), err_msg=k)
    assert len(a[0].poses) > 20 and a[1].travelled[-1] > 1.0
    # every 0.5 m of travel (plus the first scan)
    assert np.all(np.diff(a[1].travelled) >= 0.5 - 1e-9)
    # the noise-free twins end on the geometry; the noisy ranges differ from them by about 1 cm
    with World(scene, seed=1) as w:
        P = hit_points(a[0].angles, a[0].poses, a[0].clean)
        assert np.abs(w.sdf(P[::20])).max() < 1e-3
    ok = np.isfinite(a[0].clean)
    assert 0.005 < np.std(a[0].ranges[ok] - a[0].clean[ok]) < 0.015


# Routes stay clear of obstacles and visit the scene's regions; unknown leg keys are refused.
def test_routes_and_bad_legs(cache):
    w = D.lidar_world("warehouse2d", 10_001, noise=False)
    path = D.plan_route(w, 3, n_rooms=6)
    assert w.sdf(path).min() > 0.3
    x0, x1, y0, y1 = w.meta.regions["yard"]
    assert len(D.regions(w)) >= 5
    np.testing.assert_array_equal(D.section_corners(w), w.meta.corners)
    w.close()
    with pytest.raises(ValueError, match="unknown keys"):
        D.recorded_drives("office2d", 0, [dict(route_seed=0, speeed=1.0)])
    with World("office2d", seed=0) as o:
        c = D.section_corners(o)
        assert len(c) > 50 and np.abs(o.sdf(c)).max() < 1e-9        # box vertices lie on box surfaces


# A recorded orbit replays the same frames, and its noise-free points lie on the object.
def test_recorded_orbit(cache):
    from polar_sim.sim.recorders.orbits import ObjectTruth, recorded_orbit

    w = World("object_orbit", seed=2)
    a = recorded_orbit(w, 4, seed=2)
    b = recorded_orbit(World("object_orbit", seed=2), 4, seed=2)
    assert a.render_s > 0 and b.render_s == 0.0
    for x, y in zip(a.depths, b.depths):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.observed, b.observed)
    # the same seed with another option is another world, and another recording
    c = recorded_orbit(World("object_orbit", seed=2, object="mug" if a.name != "mug" else "box"), 4, seed=2)
    assert c.render_s > 0 and c.name != a.name
    wd = World("object_orbit", seed=2, object=a.name)        # same object from the seed, other colours
    assert wd.meta.colours != w.meta.colours
    assert recorded_orbit(wd, 4, seed=2).render_s > 0           # so not the cached recording of ``w``
    with pytest.raises(ValueError, match="freshly"):
        w.step()
        recorded_orbit(w, 4, seed=2)
    assert np.abs(w.sdf(a.observed[::50])).max() < 2e-3
    t = ObjectTruth(w, a)
    E = t.eval_points(500, seed=0)
    assert len(E["P"]) > 50 and np.all(np.abs(E["gt"]) < 0.01)
