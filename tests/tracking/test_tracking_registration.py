"""ICP on SE(3): known transforms, Jacobian, weights, covariance (polar_sim.tracking.icp)."""

import numpy as np
import pytest

from polar_sim.geometry import make_pose, se3_exp, so3_exp
from polar_sim.tracking.icp import weighted_icp
from polar_sim.tracking.model import ShapeModel
from polar_sim.geometry import pinhole_intrinsics
from polar_sim.tracking.synthetic import make_object, render, sample_model

K = pinhole_intrinsics(640, 480, 45.0)
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


def _random_problem(seed, n):
    # a random point-to-plane problem: model points P with unit normals N, their correspondences Y (P plus
    # 5 cm noise) seen as X = T Y, the point-to-plane residuals and random IRLS weights
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3))
    N = rng.normal(size=(n, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    T = make_pose(so3_exp(rng.normal(size=3) * 0.3), rng.normal(size=3))
    Y = P + rng.normal(size=(n, 3)) * 0.05
    X = Y @ T[:3, :3].T + T[:3, 3]
    res = np.einsum("ij,ij->i", N, P - Y)
    return P, N, T, Y, X, res, rng.random(n)


def test_normal_equations_kernel_matches_brute_force():
    # the numba accumulation (point-to-plane + tangential term) equals an explicit 3x6-Jacobian sum
    from polar_sim.tracking._kernels import icp_normal_equations
    from polar_sim.tracking.icp import _normal_equations

    n_ = 60
    P, N, T, Y, X, res, w = _random_problem(0, n_)
    idx = np.arange(n_)
    H, g = np.zeros((6, 6)), np.zeros(6)
    icp_normal_equations(X, T[:3, :3].copy(), T[:3, 3].copy(), P, N, idx, res, w, 0.09, np.zeros(len(P)), H, g)
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


def _front(model, T):
    # model points facing a camera at the origin under T (T_cam_cen)
    Pc = model.P @ T[:3, :3].T + T[:3, 3]
    return np.flatnonzero(np.einsum("ij,ij->i", model.N @ T[:3, :3].T, Pc) < 0)


def test_unobserved_directions_of_a_cylinder_and_a_box():
    # probing with a broad covariance: a revolved object's only unobserved direction is the turn about its
    # axis (scaled twist +-e_z rotation); a box with several faces and their edges in view has none
    from polar_sim.tracking.icp import unobserved_directions

    T = make_pose(so3_exp([-2.2, 0.0, 0.4]), [0.0, 0.0, 0.6])
    cov = np.diag(np.array([0.05, 0.049, 0.048, 0.012, 0.011, 0.010]) ** 2)  # distinct: canonical eigenvectors
    P, N = sample_model(make_object("cylinder"), 3000, seed=1)
    cyl = ShapeModel(P, N)
    U, rho = unobserved_directions(cyl, _front(cyl, T), cov, n_probe=6)
    axis = np.linalg.svd(cyl.P - cyl.P.mean(0))[2][0]  # the longest extent: the cylinder's axis
    assert U.shape == (6, 1) and abs(abs(U[:3, 0] @ axis) - 1) < 0.02 and np.abs(U[3:, 0]).max() < 0.02
    P, N = sample_model(make_object("box"), 3000, seed=1)
    box = ShapeModel(P, N)
    U, _ = unobserved_directions(box, _front(box, T), cov, n_probe=6)
    assert U.shape == (6, 0)


def test_unobserved_directions_of_a_face_without_its_edges():
    # only the middle of one face supported (its edges hidden): the slides along it and the turn about its
    # normal are unobserved, the motion along the normal and the tilts are not
    from polar_sim.tracking.icp import unobserved_directions

    P, N = sample_model(make_object("box"), 3000, seed=1)
    box = ShapeModel(P, N)
    n0 = np.array([1.0, 0.0, 0.0])
    face = np.flatnonzero(box.N @ n0 > 0.99)
    c = box.P[face]
    mid = face[np.max(np.abs(c[:, 1:] - c[:, 1:].mean(0)), axis=1) < 0.015]
    cov = np.diag(np.array([0.05, 0.049, 0.048, 0.012, 0.011, 0.010]) ** 2)
    U, rho = unobserved_directions(box, mid, cov, n_probe=6)
    # the unobserved set is exactly {turn about x, slide along y, slide along z}
    expect = np.zeros((6, 3))
    expect[0, 0] = expect[4, 1] = expect[5, 2] = 1.0
    assert U.shape == (6, 3)
    assert np.allclose(np.abs(U.T @ expect).sum(axis=0), 1.0, atol=0.02)


def test_icp_weights_are_the_registration_package_tukey_bit_for_bit():
    # one home for robust weights (issue 34): the ICP's IRLS weights come from
    # polar_sim.registration.robust_weight("tukey"); they equal, bit for bit, the biweight the ICP had
    # of its own, (1 - u^2)^2 for |u| < 1 else 0 with u = r / (4.685 sigma), at every residual
    # including the cut-off itself, both signs, zero and far outliers
    from polar_sim.registration import robust_weight

    rng = np.random.default_rng(0)
    sigma = 0.0017
    c = 4.685 * sigma
    r = np.concatenate([rng.normal(0.0, 2 * c, 200_000), np.linspace(-2 * c, 2 * c, 10_001), [c, -c, 0.0, -0.0, 1e3]])
    u = r / c
    a = 1.0 - u * u
    old = np.where(a > 0.0, a * a, 0.0)
    assert np.array_equal(robust_weight(r, "tukey", c), old)
    assert old[-5] == 0.0 and old[-3] == 1.0 and (old >= 0).all()


def test_normal_equations_kernel_with_a_tangential_dead_zone():
    # with a dead zone dz per model point, a point whose tangential offset is within dz keeps its
    # point-to-plane term only, and one beyond it adds the tangential term with the offset shortened by
    # dz (explicit 3x6-Jacobian sums); dz = 0 is the plain tangential term
    from polar_sim.tracking._kernels import icp_normal_equations

    n_ = 80
    P, N, T, Y, X, res, w = _random_problem(1, n_)
    et = (P - Y) - N * res[:, None]
    dz = np.full(n_, np.median(np.linalg.norm(et, axis=1)))   # about half the points in the dead zone
    H, g = np.zeros((6, 6)), np.zeros(6)
    icp_normal_equations(X, T[:3, :3].copy(), T[:3, 3].copy(), P, N, np.arange(n_), res, w, 0.09, dz, H, g)
    Hb, gb, active = np.zeros((6, 6)), np.zeros(6), 0
    for i in range(n_):
        m, nn = P[i], N[i]
        Jpl = np.concatenate([np.cross(m, nn), nn])
        Hb += w[i] * np.outer(Jpl, Jpl)
        gb += w[i] * Jpl * res[i]
        a = np.linalg.norm(et[i])
        if a > dz[i]:
            active += 1
            hat = np.array([[0, -m[2], m[1]], [m[2], 0, -m[0]], [-m[1], m[0], 0]])
            Jp = np.concatenate([-hat, np.eye(3)], 1)
            Pi = np.eye(3) - np.outer(nn, nn)
            Hb += w[i] * 0.09 * Jp.T @ Pi @ Jp
            gb += w[i] * 0.09 * Jp.T @ (et[i] * (1.0 - dz[i] / a))
    assert 0.3 * n_ < active < 0.7 * n_
    assert np.allclose(H, Hb, atol=1e-10) and np.allclose(g, gb, atol=1e-10)
