"""ICP on SE(3): known transforms, Jacobian, weights, covariance (polar_sim.tracking.icp)."""

import numpy as np
import pytest

from polar_sim.geometry import make_pose, se3_exp, so3_exp
from polar_sim.tracking.icp import weighted_icp
from polar_sim.tracking.model import ShapeModel
from polar_sim.tracking.synthetic import intrinsics, make_object, render, sample_model

K = intrinsics(640, 480)
SHAPE = (480, 640)


def _scene(name, T_cam_obj):
    part = make_object(name)
    P, N = sample_model(part, 3000, seed=1)
    model = ShapeModel(P, N)
    _, depth, labels = render([part], [T_cam_obj], K, SHAPE)
    v, u = np.nonzero(labels == 1)
    z = depth[v, u].astype(float)
    X = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)
    C = make_pose(None, model.centroid)
    return model, X, T_cam_obj @ C


def _view(yaw=0.4):
    return make_pose(so3_exp([-2.2, 0.0, yaw]), [0.01, 0.02, 0.6])


def _run(model, X, T0, w0=None, **kw):
    n = len(X)
    sd = np.full(n, 0.0015)
    return weighted_icp(X, np.ones(n) if w0 is None else w0, model, T0, K, SHAPE, sigma_d=sd,
                        delta1=np.full(n, 0.006), gate0=0.03, gate_floor=model.spacing, **kw)


@pytest.mark.parametrize("name", ["box", "mug"])
@pytest.mark.parametrize("exact", [False, True])
def test_icp_recovers_known_transform(name, exact):
    # a 3 deg / 1 cm perturbation of the true pose is undone to sub-millimetre, sub-0.1-degree accuracy
    model, X, T_true = _scene(name, _view())
    T0 = T_true @ se3_exp([0.03, -0.04, 0.02, 0.008, -0.006, 0.005])
    res = _run(model, X, T0, exact=exact)
    assert res.ok
    dR = T_true[:3, :3].T @ res.T[:3, :3]
    ang = np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))
    assert np.linalg.norm(res.T[:3, 3] - T_true[:3, 3]) < 5e-4
    assert np.rad2deg(ang) < 0.2
    assert res.fitness > 0.95 and res.rmse < 2e-3


def test_icp_identity_stays():
    # starting at the truth, ICP stays there (no bias from the point-to-plane model)
    model, X, T_true = _scene("box", _view(0.6))
    res = _run(model, X, T_true)
    assert np.linalg.norm(res.T[:3, 3] - T_true[:3, 3]) < 3e-4


def test_icp_zero_weight_points_are_ignored():
    # outliers carrying prior weight 0 (e.g. a hand in front) do not move the registration
    model, X, T_true = _scene("box", _view())
    rng = np.random.default_rng(0)
    out = X[rng.choice(len(X), len(X) // 2)] - np.array([0.0, 0.0, 0.012])
    Xa = np.concatenate([X, out])
    w0 = np.concatenate([np.ones(len(X)), np.zeros(len(out))])
    T0 = T_true @ se3_exp([0.0, 0.02, 0.0, 0.005, 0.0, 0.0])
    res = _run(model, Xa, T0, w0=w0)
    assert np.linalg.norm(res.T[:3, 3] - T_true[:3, 3]) < 5e-4


def test_icp_jacobian_matches_finite_differences():
    # the residual Jacobian [(m x n)^T, n^T] of the right perturbation agrees with finite differences
    rng = np.random.default_rng(3)
    T = make_pose(so3_exp(rng.normal(size=3)), rng.normal(size=3))
    m, n = rng.normal(size=3), rng.normal(size=3)
    n /= np.linalg.norm(n)
    x = T[:3, :3] @ m + T[:3, 3]  # on the plane: the rotating normal's term is second order there

    def resid(d):
        Tp = T @ se3_exp(d)
        return (Tp[:3, :3] @ n) @ (Tp[:3, :3] @ m + Tp[:3, 3] - x)

    J = np.concatenate([np.cross(m, n), n])
    num = np.array([(resid(e * 1e-6) - resid(-e * 1e-6)) / 2e-6 for e in np.eye(6)])
    assert np.allclose(num, J, atol=1e-6)


def test_icp_covariance_is_symmetric_positive_definite():
    # the Hessian-based covariance is a valid covariance and tiny for a well-constrained box
    model, X, T_true = _scene("box", _view())
    res = _run(model, X, T_true @ se3_exp([0.01, 0, 0, 0.003, 0, 0]))
    assert np.allclose(res.cov, res.cov.T)
    ev = np.linalg.eigvalsh(res.cov)
    assert ev.min() > 0 and np.sqrt(ev.max()) < 0.01


def test_icp_too_few_points_fails_cleanly():
    # with almost no observations ICP reports failure and returns the initial pose
    model, X, T_true = _scene("box", _view())
    res = _run(model, X[:3], T_true)
    assert not res.ok and np.array_equal(res.T, T_true)


def test_normal_equations_kernel_matches_brute_force():
    # the numba accumulation (point-to-plane + tangential term) equals an explicit 3x6-Jacobian sum
    from polar_sim.tracking._kernels import icp_normal_equations
    from polar_sim.tracking.icp import _normal_equations

    rng = np.random.default_rng(0)
    n_ = 60
    P = rng.normal(size=(n_, 3))
    N = rng.normal(size=(n_, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    T = make_pose(so3_exp(rng.normal(size=3) * 0.3), rng.normal(size=3))
    Y = P + rng.normal(size=(n_, 3)) * 0.05
    X = Y @ T[:3, :3].T + T[:3, 3]
    idx = np.arange(n_)
    res = np.einsum("ij,ij->i", N, P - Y)
    w = rng.random(n_)
    H, g = np.zeros((6, 6)), np.zeros(6)
    icp_normal_equations(X, T[:3, :3].copy(), T[:3, 3].copy(), P, N, idx, res, w, 0.09, H, g)
    Hb = np.zeros((6, 6))
    gb = np.zeros(6)
    for i in range(n_):
        m, nn = P[i], N[i]
        Jpl = np.concatenate([np.cross(m, nn), nn])
        hat = np.array([[0, -m[2], m[1]], [m[2], 0, -m[0]], [-m[1], m[0], 0]])
        Jp = np.concatenate([-hat, np.eye(3)], 1)
        Pi = np.eye(3) - np.outer(nn, nn)
        Hb += w[i] * (np.outer(Jpl, Jpl) + 0.09 * Jp.T @ Pi @ Jp)
        gb += w[i] * (Jpl * res[i] + 0.09 * Jp.T @ Pi @ (m - Y[i]))
    Hn, gn = _normal_equations(np.stack([np.concatenate([np.cross(P[i], N[i]), N[i]]) for i in range(n_)]),
                               res, w, P, N, Y, 0.3)
    assert np.allclose(H, Hb, atol=1e-10) and np.allclose(g, gb, atol=1e-10)
    assert np.allclose(Hn, Hb, atol=1e-10) and np.allclose(gn, gb, atol=1e-10)
