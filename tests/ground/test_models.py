import numpy as np
import pytest

from polar_sim.ground.models import default_iterations, fit_ground, normalise, ransac_iterations, sample_weighted


def test_ransac_iteration_counts_t2():
    # T2: 3p 69 (95 %, 65 % outliers, sample 3); 2p with the same formula 23; the commented 6p formula 1032.
    assert ransac_iterations(0.95, 0.65, 3) == 69
    assert ransac_iterations(0.95, 0.65, 2) == 23
    assert ransac_iterations(0.85, 0.65, 6) == 1032
    assert default_iterations("6param", "code") == 99 and default_iterations("6param") == 55
    assert default_iterations("2param") == 16 and default_iterations("3param") == 69


def _scene(rng, V=6.0, h=1.5, n_ground=150, n_out=100, plane=(0.0, 0.0)):
    """Exact d̄ of ground points on y = h + a x + b z (camera frame) plus random outliers."""
    a, b = plane
    u = rng.uniform(-0.6, 0.6, n_ground)
    v = rng.uniform(0.02, 0.35, n_ground)
    # Ray (u, v, 1) z meets the plane y = h + a x + b z: v z = h + a u z + b z.
    z = h / (v - a * u - b)
    dbar = V / z
    uo = rng.uniform(-0.6, 0.6, n_out)
    vo = rng.uniform(0.02, 0.35, n_out)
    # Outliers (e.g. a wall in front of the ground): 1.5 to 3 times nearer than the ground at their pixel.
    do = V / (h / (vo - a * uo - b)) * rng.uniform(1.5, 3.0, n_out)
    return np.r_[u, uo], np.r_[v, vo], np.r_[dbar, do], np.r_[np.ones(n_ground, bool), np.zeros(n_out, bool)]


@pytest.mark.parametrize("model", ["2param", "3param", "plane3", "6param"])
def test_models_recover_speed_on_level_ground(model):
    # Every model reads V = 2 s m_yδ exactly from clean level ground, and to 1 % among 40 % outliers (the
    # algebraic residual is weak near the horizon, so a few outliers there join the inliers).
    rng = np.random.default_rng(1)
    u, v, d, g = _scene(rng)
    fit = fit_ground(u[g], v[g], d[g], 1.5, model=model, rng=np.random.default_rng(0), n_iter=20)
    assert fit.ok and abs(fit.speed - 6.0) < 1e-9 and fit.inliers.all()
    fit = fit_ground(u, v, d, 1.5, model=model, rng=np.random.default_rng(0), n_iter=200)
    assert fit.ok and abs(fit.speed - 6.0) < 0.01 * 6.0
    assert fit.inliers[g].mean() > 0.95 and fit.inliers[~g].mean() < 0.2


def test_plane3_and_6param_follow_a_tilted_plane_2param_does_not():
    # A plane tilted sideways (y = h + 0.05 x): plane3/6param keep V, the level-ground 2param model cannot.
    rng = np.random.default_rng(2)
    u, v, d, g = _scene(rng, plane=(0.05, 0.0), n_out=0)
    for model in ("plane3", "6param"):
        fit = fit_ground(u, v, d, 1.5, model=model, rng=np.random.default_rng(0), n_iter=100)
        assert abs(fit.speed - 6.0) < 0.02 * 6.0, model
    fit2 = fit_ground(u, v, d, 1.5, model="2param", rng=np.random.default_rng(0), n_iter=100)
    assert fit2.inliers.mean() < 0.9


def test_normalisation_makes_slope_the_scale():
    # §4.3: δ² = V/(2s) yδ on level ground, with x = 2u/h, y = 2v/h, s = 3 median(d̄).
    v = np.linspace(0.05, 0.3, 20)
    d = 7.0 * v / 1.2
    x, y, delta, s = normalise(np.zeros(20), v, d, 1.2)
    np.testing.assert_allclose(delta**2, 7.0 / (2 * s) * y * delta)


def test_weighted_sampling_follows_the_weights():
    # Single draws land on index i with probability w_i / Σw (4-sigma binomial bound).
    rng = np.random.default_rng(0)
    w = np.array([0.05, 0.1, 0.15, 0.3, 0.4])
    idx = sample_weighted(rng, w, 40000, 1).ravel()
    freq = np.bincount(idx, minlength=5) / len(idx)
    p = w / w.sum()
    assert np.all(np.abs(freq - p) < 4 * np.sqrt(p * (1 - p) / len(idx)))
    many = sample_weighted(rng, w, 100, 3)
    assert all(len(set(r)) == 3 for r in many.tolist())


def test_weighted_ransac_prefers_high_weight_points():
    # With few iterations, weights that favour the ground raise the inlier recall (the paper's effect).
    rng = np.random.default_rng(3)
    u, v, d, g = _scene(rng, n_ground=40, n_out=160)
    w = np.where(g, 0.9, 0.1)
    rec = {"uniform": [], "weighted": []}
    for seed in range(40):
        for name, ww in (("uniform", None), ("weighted", w)):
            fit = fit_ground(u, v, d, 1.5, model="2param", weights=ww, n_iter=2, rng=np.random.default_rng(seed))
            rec[name].append(fit.inliers[g].mean() if fit.ok else 0.0)
    assert np.mean(rec["weighted"]) > np.mean(rec["uniform"]) + 0.2


def test_code_sampling_and_failures():
    # The published cumulative draw gives distinct indices; too few candidates or no model give ok=False, V=0.
    rng = np.random.default_rng(4)
    u, v, d, g = _scene(rng)
    fit = fit_ground(u, v, d, 1.5, model="6param", weights=np.where(g, 1.0, 0.2), compat="code",
                     rng=np.random.default_rng(0))
    assert fit.ok and fit.iterations == 99 and abs(fit.speed - 6.0) < 0.01 * 6.0
    few = fit_ground(u[:3], v[:3], d[:3], 1.5, model="6param", rng=np.random.default_rng(0))
    assert not few.ok and few.speed == 0.0 and not few.inliers.any()
