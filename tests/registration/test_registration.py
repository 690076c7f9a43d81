"""polar_sim.registration: closed-form alignment, robust kernels, scan handling, and its place in
the layers (imported by gpis and baselines, importing neither)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from polar_sim.geometry import se3_exp
from polar_sim.registration import (
    arc_length_subsample,
    beam_points,
    kabsch,
    register_sdf,
    robust_cost,
    robust_weight,
    transform2d,
)

ROOT = Path(__file__).resolve().parents[2]


# Kabsch recovers an exact rigid motion of noise-free pairs, 2D and 3D
@pytest.mark.parametrize("dim", [2, 3])
def test_kabsch_exact(dim):
    rng = np.random.default_rng(0)
    P = rng.normal(size=(50, dim))
    if dim == 2:
        a = 0.7
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    else:
        R = se3_exp(np.array([0.3, -0.5, 0.9, 0, 0, 0]))[:3, :3]
    t = rng.normal(size=dim)
    T = kabsch(P, P @ R.T + t)
    np.testing.assert_allclose(T[:dim, :dim], R, atol=1e-12)
    np.testing.assert_allclose(T[:dim, dim], t, atol=1e-12)


# mirrored targets: the best *rotation* (det +1) is returned, never a reflection (Umeyama's fix)
def test_kabsch_never_reflects():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(30, 3))
    T = kabsch(P, P * [1, 1, -1])
    assert np.isclose(np.linalg.det(T[:3, :3]), 1.0)


# IRLS weights are rho'(r) / r of the costs (numerical derivative), for every kernel
@pytest.mark.parametrize("kind,scale", [("huber", 0.1), ("tukey", 0.5), ("none", np.inf)])
def test_robust_weight_is_cost_derivative(kind, scale):
    r = np.concatenate([np.linspace(-1.0, -0.01, 50), np.linspace(0.01, 1.0, 50)])
    h = 1e-7
    d = (robust_cost(r + h, kind, scale) - robust_cost(r - h, kind, scale)) / (2 * h)
    np.testing.assert_allclose(robust_weight(r, kind, scale), d / r, rtol=1e-5, atol=1e-6)


# arc-length subsampling spreads points evenly along a straight scan, ends included
def test_arc_length_subsample_even():
    pts = np.column_stack([np.linspace(0, 10, 1001) ** 2 / 10, np.zeros(1001)])   # crowded at 0
    idx = arc_length_subsample(pts, 11)
    np.testing.assert_allclose(pts[idx, 0], np.linspace(0, 10, 11), atol=0.1)


# beam end points with a mounting offset, then to the world: the exact geometry
def test_beam_points_and_transform():
    p = beam_points(np.array([0.0, np.pi / 2]), np.array([2.0, 1.0]), np.array([0.1, 0.0, 0.0]))
    np.testing.assert_allclose(p, [[2.1, 0.0], [0.1, 1.0]], atol=1e-15)
    w = transform2d(np.array([1.0, 2.0, np.pi / 2]), p)
    np.testing.assert_allclose(w, [[1.0, 4.1], [0.0, 2.1]], atol=1e-12)


# ICP-G is this solver, and ICP-D calls it: one Gauss-Newton on an SDF
def test_one_solver():
    from polar_sim.gpis.localize import localize

    assert localize is register_sdf


# the layers: registration imports neither gpis nor baselines; gpis does not import baselines
# (the old cycle gpis.localize <-> baselines), and neither imports the other's private modules
def test_no_cycle():
    code = ("import sys, polar_sim.registration; "
            "print(sorted(m for m in sys.modules if m.startswith(('polar_sim.gpis', 'polar_sim.baselines'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
    for pkg, other in (("gpis", "baselines"), ("baselines", "gpis"), ("registration", "gpis"),
                       ("registration", "baselines")):
        for p in (ROOT / "polar_sim" / pkg).glob("*.py"):
            text = p.read_text()
            assert f"from polar_sim.{other}" not in text and f"import polar_sim.{other}" not in text, p
