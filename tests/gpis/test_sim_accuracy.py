"""Issue 3's accuracy bounds for GPIS in default mode, against the simulator's exact ground truth.

office2d: a seeded 60 s drive through the rooms with the 2D lidar (sigma 1 cm); object_orbit:
an RGB-D orbit with Kinect-like noise. The definitions ("observed", the evaluation sets) are
those of ``experiments/gpis_accuracy.py`` (``polar_sim.metrics.maps``, drives from
``polar_sim.sim.recorders.drives2d``, orbits from ``polar_sim.sim.recorders.orbits``); this is its CI size
(a scan every 3rd step, 20 RGB-D frames; ``POLAR_SIM_FULL=1``: every step, 40 frames).

Bounds that the current GPISMap2D/3D miss are marked ``xfail(strict=True)`` with the measured
figure: they still run and assert the issue's bound, and they turn into failures the day the bound
is met (so the recorded results get updated). See benchmarks/RESULTS.md.
"""

import os

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D, GPISMap3D
from polar_sim.metrics import maps as M

pytestmark = pytest.mark.slow
FULL = os.environ.get("POLAR_SIM_FULL", "") == "1"


def size(full, reduced):
    """The full size with POLAR_SIM_FULL=1, else the CI size (as ``tests/conftest.py``)."""
    return full if FULL else reduced

SEED = 0


@pytest.fixture(scope="module")
def office():
    from polar_sim.sim.recorders.drives2d import lidar_world, recorded_drives

    every = size(1, 3)
    d, = recorded_drives("office2d", SEED, [dict(route_seed=SEED, n_rooms=5, duration=60.0, speed=1.0, every_steps=every)])
    w = lidar_world("office2d", SEED, noise=False)
    m = GPISMap2D(sensor_offset=(0.0, 0.0))
    leg = GPISMap2D.published()
    for p, r in zip(d.poses, d.ranges):
        m.update(d.angles, r, p)
        leg.update(d.angles, r, p)
    obs = M.ObservedArea(d.angles, d.poses, d.clean)
    E = M.sample_eval_points(obs, w.sdf, size(60_000, 30_000), SEED)
    s, _ = M.sdf_map_scores(*m.query(E["P"])[:2], E)
    sl, _ = M.sdf_map_scores(*leg.query(E["P"])[:2], E)
    surf, _ = M.surface_scores_2d(M.polyline_points(m.surface()), w.sdf, obs)
    yield dict(w=w, d=d, m=m, obs=obs, E=E, s=s, legacy=sl, surf=surf)
    w.close()


@pytest.fixture(scope="module")
def orbit():
    from polar_sim.sim import World
    from polar_sim.sim.recorders.orbits import ObjectTruth, recorded_orbit

    w = World("object_orbit", seed=SEED)
    orb = recorded_orbit(w, size(40, 20), SEED)
    m = GPISMap3D()
    for z, K, T in zip(orb.depths, orb.Ks, orb.poses):
        m.update(z, K, T)
    truth = ObjectTruth(w, orb)
    E = truth.eval_points(size(4000, 2000), SEED)
    S = m.surface()
    V, F = np.asarray(S.vertices), np.asarray(S.faces)
    c = truth.compare_mesh(V, F, E["samples"][E["seen"]])
    v = c["visible"]
    res = M.object_map_scores(m.query(E["P"])[0], E["gt"], dist=c["dist"], visible=v, to_surface=c["to_surface"],
                              vertex_grad=m.query(V[v])[1], true_normals=c["true_normals"][v])
    yield res
    w.close()


# the evaluation sets are non-trivial and consistent with the exact SDF
def test_office_evaluation_sets(office):
    E, d = office["E"], office["d"]
    assert d.travelled[-1] > 40.0 and len(d.poses) >= 150
    assert E["near"].sum() > 2000 and E["far"].sum() > 5000
    assert np.all(np.abs(E["gt"][E["near"]]) < 0.3)
    assert np.all((E["gt"][E["far"]] > 0.3) & (E["gt"][E["far"]] < 2.0))
    # the noise-free beam end points are on the true surface (World.sdf is exact)
    assert np.abs(office["w"].sdf(office["obs"].hits[::50])).max() < 1e-3


# SDF RMSE <= 2 cm within 0.3 m of the observed walls (issue 3)
@pytest.mark.xfail(strict=True, reason="missed: measured 2.5 cm at CI size (3.1 cm before the association gate on "
                                      "replaced samples and the 5 cm free-space grid, 4.8 cm with the spec's sample "
                                      "noise); the rest is corners (~50 % of the squared error within 30 cm of one) "
                                      "and surfaces glimpsed by fewer than 10 scans (~30 %)")
def test_office_near_rmse(office):
    assert office["s"]["near_rmse_m"] <= 0.02


# median gradient angle error <= 5 deg, near surfaces and in observed free space
def test_office_gradient(office):
    assert office["s"]["grad_near_median_deg"] <= 5.0
    assert office["s"]["grad_far_median_deg"] <= 5.0


# Hausdorff distance between surface() and the observed true walls <= 10 cm
@pytest.mark.xfail(strict=True, reason="missed: measured 0.24 m at CI size (0.37 m before this session's corner "
                                      "work, 0.61 m with the spec's sample noise): observed walls 0.24 m from "
                                      "surface() where a glimpsed wall's few samples have no trusted normal, and "
                                      "surface() up to 0.19 m off the truth at corners and wall ends")
def test_office_hausdorff(office):
    assert office["surf"]["hausdorff_m"] <= 0.10


# mean absolute error <= 5 cm in observed free space 0.3-2 m from the nearest wall
def test_office_far_field(office):
    assert office["s"]["far_mae_m"] <= 0.05


# the published (legacy) method cannot reach it: its SDF drifts back to the 0.2 bias
def test_office_far_field_legacy_cannot(office):
    assert office["legacy"]["far_mae_m"] > 0.05
    assert office["legacy"]["far_mae_m"] > 5 * office["s"]["far_mae_m"]


# object_orbit: SDF RMSE <= 2 mm within 1 cm of the observed surface (seed 0's 4.8 cm cube: 1.24 mm
# at CI size; 2.3 mm before the far field's sign came from the implicit-MLS surface)
def test_orbit_sdf_rmse(orbit):
    assert orbit["n_sdf_points"] > 500
    assert orbit["sdf_rmse_m"] <= 0.002


# object_orbit: Chamfer distance between surface() and the true mesh <= 3 mm
def test_orbit_chamfer(orbit):
    assert orbit["n_vertices"] > 1000
    assert orbit["chamfer_m"] <= 0.003
    assert orbit["surface_to_mesh_m"] <= 0.003
