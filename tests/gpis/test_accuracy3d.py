"""Default-mode GPISMap3D against an analytic sphere seen by a depth camera and a 3D lidar."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from polar_sim.gpis import GPISMap3D

from polar_sim.gpis._distance import FreeSpace, far_field

from .scenes import (BOX_HALF, SPHERE_C, SPHERE_R, box_sdf, intrinsics, look_at, orbit_poses,
                     render_box, render_sphere, sphere_sdf)


@pytest.fixture(scope="module")
def sphere_map():
    K = intrinsics()
    m = GPISMap3D()
    for T in orbit_poses(8):
        m.update(render_sphere(T, K), K, T)
    return m


def _shell(n, lo, hi, zmin=-0.015, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    P = SPHERE_C + d * (SPHERE_R + rng.uniform(lo, hi, (n, 1)))
    return P[P[:, 2] > zmin]          # the orbit sees the sphere from above (elevation 14 deg)


# SDF RMSE <= 2 mm within 1 cm of the observed surface (issue 3)
def test_sphere_sdf_rmse(sphere_map):
    P = _shell(3000, -0.01, 0.01)
    d, g, v = sphere_map.query(P)
    assert np.sqrt(np.mean((d - sphere_sdf(P)) ** 2)) <= 0.002
    n = (P - SPHERE_C) / np.linalg.norm(P - SPHERE_C, axis=1)[:, None]
    cos = (g * n).sum(1) / np.linalg.norm(g, axis=1)
    assert np.median(np.degrees(np.arccos(np.clip(cos, -1, 1)))) <= 5.0


# faithful distance away from the sphere (2-10 cm), positive outside
def test_sphere_far_field(sphere_map):
    P = _shell(2000, 0.02, 0.10)
    d, _, _ = sphere_map.query(P)
    assert np.abs(d - sphere_sdf(P)).mean() <= 0.003
    assert (d > 0).all()


# surface(): marching-cubes mesh within a Chamfer distance of 3 mm of the true sphere
def test_sphere_mesh_chamfer(sphere_map):
    mesh = sphere_map.surface()
    V = np.asarray(mesh.vertices)
    assert len(mesh.faces) > 1000
    to_sphere = np.abs(sphere_sdf(V)).mean()
    rng = np.random.default_rng(2)
    gt = rng.normal(size=(20000, 3))
    gt = SPHERE_C + gt / np.linalg.norm(gt, axis=1)[:, None] * SPHERE_R
    gt = gt[gt[:, 2] > -0.015]
    to_mesh = cKDTree(V).query(gt)[0].mean()
    assert 0.5 * (to_sphere + to_mesh) <= 0.003


# update_lidar: a 3D lidar (directions + ranges) maps the same sphere
def test_lidar_update():
    m = GPISMap3D()
    el = np.deg2rad(np.linspace(-20, 20, 120))
    az = np.deg2rad(np.linspace(-30, 30, 180))
    E, A = np.meshgrid(el, az, indexing="ij")
    dirs = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    for k in range(6):
        a = 2 * np.pi * k / 6
        eye = SPHERE_C + 0.6 * np.array([np.cos(a), np.sin(a), 0.0])
        R = np.array([[-np.cos(a), np.sin(a), 0], [-np.sin(a), -np.cos(a), 0], [0, 0, 1.0]])
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, eye
        dw = dirs @ R.T
        o = eye - SPHERE_C
        b = dw @ o
        disc = b * b - (o @ o - SPHERE_R**2)
        r = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
        m.update_lidar(dirs, r, T)
    s = m.samples()["points"]
    assert len(s) > 200
    assert np.abs(sphere_sdf(s)).max() < 0.002
    P = _shell(1000, -0.005, 0.005, zmin=-0.03)
    P = P[np.abs(P[:, 2] - SPHERE_C[2]) < 0.03]
    d, _, _ = m.query(P)
    assert np.sqrt(np.mean((d - sphere_sdf(P)) ** 2)) <= 0.002


# -- the 4.5 cm cube of object_orbit, rendered exactly: its edges -------------------------------
@pytest.fixture(scope="module")
def cube_map():
    K = intrinsics()
    m = GPISMap3D()
    el = np.radians(30.0)
    for k in range(12):                      # one orbit at 0.7 m, 30 deg above the cube
        a = 2 * np.pi * k / 12 + 0.3
        eye = 0.7 * np.array([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)])
        T = look_at(eye, np.zeros(3))
        m.update(render_box(T, K), K, T)
    return m


def _cube_band(n=20000, seed=0):
    """Points within 1 cm of the cube's surface whose nearest face was seen (not the bottom)."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-0.0325, 0.0325, (n, 3))
    g = box_sdf(P)
    sel = (np.abs(g) < 0.01) & (P[:, 2] > -BOX_HALF[2] + 0.01)
    return P[sel], g[sel]


# SDF RMSE <= 2 mm within 1 cm of a small cube, and the right side of its faces next to the
# edges (the far field's sign: 2.7 mm and 8 % of the points 2-10 mm outside on the wrong side
# when the closest surfel alone decided it)
def test_cube_sdf_at_edges(cube_map):
    P, g = _cube_band()
    d, _, _ = cube_map.query(P)
    assert np.sqrt(np.mean((d - g) ** 2)) <= 0.002
    out = g > 0.002
    assert np.mean(d[out] < 0) <= 0.04


# the implicit-MLS sign of the far field at a box edge sampled every centimetre: in front of the
# top face, 3 mm from the edge, the closest disc is a side-face surfel whose plane the point lies
# behind; the surfels' centre-weighted side says outside
def test_far_field_sign_at_edge():
    from scipy.spatial import cKDTree

    ys = (-0.01, 0.0, 0.01)
    top = [(x, y, 0.0) for x in (-0.005, -0.015, -0.025) for y in ys]        # z = 0, normal +z
    side = [(0.0, y, z) for z in (-0.004, -0.014, -0.024) for y in ys]      # x = 0, normal +x
    pos = np.array(top + side)
    nrm = np.array([(0.0, 0.0, 1.0)] * len(top) + [(1.0, 0.0, 0.0)] * len(side))
    sp = np.full(len(pos), 1e-5)
    sg = np.full(len(pos), 0.01)
    P = np.array([[-0.003, 0.0, 0.008]])                     # exact distance +8 mm (above the top)
    gi = cKDTree(pos).query(P, k=4)[1]
    args = (P, gi, pos, nrm, sp, sg, 0.0047, FreeSpace(3, 0.025),
            1.005)
    d_disc, _, _ = far_field(*args)
    d_imls, g_imls, _ = far_field(*args, sign_h=0.008)
    assert d_disc[0] < 0                                      # the closest disc's side: wrong
    assert d_imls[0] == pytest.approx(-d_disc[0])             # same distance, the right side
    assert 0.007 < d_imls[0] < 0.009
    assert g_imls[0] @ np.array([0.0, 0.0, 1.0]) > 0.5
