import math

import numpy as np
import pytest
from baselines_scene import ANGLES, pose_error, world_pose

from polar_sim.baselines import (
    LikelihoodField,
    OccupancyGrid2D,
    ParticleFilterLocalizer,
    low_variance_resample,
    sample_motion_model_odometry,
)
from polar_sim.errors import NotUpdatedError
from polar_sim.geometry import between2d, compose2d


@pytest.fixture(scope="module")
def field(mapped_grid):
    return LikelihoodField().fit(mapped_grid)


def _drive(room, field, seed, n=40):
    """Track a gentle S-curve from a start 0.36 m / 10 deg off; returns (filter, true final pose)."""
    path = [world_pose(room, 2.0 + 5.0 * k / n, 1.5 + 0.5 * math.sin(k / 8), 0.1 * math.cos(k / 8)) for k in range(n)]
    pf = ParticleFilterLocalizer(seed=seed)
    pf.initialize(field, path[0] + np.array([0.3, -0.2, np.radians(10)]), std=(0.3, 0.3, 0.2))
    odom = np.zeros(3)
    for k, p in enumerate(path):
        if k:
            odom = compose2d(odom, between2d(path[k - 1], p))
        pf.update(ANGLES, room.scan(p, ANGLES), odom)
    return pf, path[-1]


def test_motion_model_without_noise_is_the_odometry_increment():
    # With zero alphas every particle moves by exactly the odometry increment, in its own frame.
    parts = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, np.pi / 2], [-3.0, 0.5, -2.0]])
    o0, o1 = np.array([5.0, 5.0, 0.3]), np.array([5.4, 5.3, 0.8])
    out = sample_motion_model_odometry(parts, o0, o1, (0, 0, 0, 0), np.random.default_rng(0))
    np.testing.assert_allclose(out, compose2d(parts, between2d(o0, o1)), atol=1e-12)


def test_motion_model_noise_has_the_modelled_spread():
    # Pure translation of 1 m with a3 = 0.01: the travelled distance has std sqrt(0.01) = 0.1 m.
    parts = np.zeros((20000, 3))
    out = sample_motion_model_odometry(parts, np.zeros(3), np.array([1.0, 0.0, 0.0]), (0, 0, 0.01, 0),
                                       np.random.default_rng(1))
    assert np.std(out[:, 0]) == pytest.approx(0.1, rel=0.03)
    np.testing.assert_allclose(out[:, 1:], 0.0, atol=1e-12)


def test_low_variance_resampler_is_exact_for_degenerate_and_uniform_weights():
    # All weight on one particle selects it n times; uniform weights keep every particle once, in order.
    rng = np.random.default_rng(2)
    w = np.zeros(7)
    w[3] = 1.0
    np.testing.assert_array_equal(low_variance_resample(w, rng), np.full(7, 3))
    np.testing.assert_array_equal(low_variance_resample(np.full(7, 1 / 7), rng), np.arange(7))


def test_likelihood_field_is_a_gaussian_of_the_wall_distance(mapped_grid, field):
    # At occupied cells the field is log(z_hit N(0) + z_rand/max_range) and it falls off with distance.
    occ = mapped_grid.occupied_mask()
    peak = math.log(0.95 / (math.sqrt(2 * math.pi) * 0.2) + 0.05 / 30.0)
    np.testing.assert_allclose(field.log_field_[occ], peak, rtol=1e-6)
    d = field.distance_[~occ]
    expect = np.log(0.95 * np.exp(-0.5 * (d / 0.2) ** 2) / (math.sqrt(2 * math.pi) * 0.2) + 0.05 / 30.0)
    np.testing.assert_allclose(field.log_field_[~occ], expect, rtol=1e-5, atol=1e-6)
    far = np.array([[mapped_grid.extent[2] + 10.0, 0.0]])
    assert field.log_likelihood(far)[0] == pytest.approx(field.log_field_.min(), rel=1e-5)


def test_pf_converges_from_a_perturbed_start(room, field):
    # Tracking 40 scans along a curve, the estimate ends within 2 cm and 0.5 deg of the truth.
    pf, truth = _drive(room, field, seed=0)
    dp, dth = pose_error(pf.pose_, truth)
    assert dp < 0.02 and dth < 0.5
    assert np.all(np.linalg.eigvalsh(pf.cov_) >= -1e-12)
    assert pf.weights_.sum() == pytest.approx(1.0)


def test_pf_is_deterministic_for_a_seed(room, field):
    # Same seed, same particles bit for bit; another seed gives other particles.
    a, _ = _drive(room, field, seed=5, n=8)
    b, _ = _drive(room, field, seed=5, n=8)
    c, _ = _drive(room, field, seed=6, n=8)
    np.testing.assert_array_equal(a.particles_, b.particles_)
    np.testing.assert_array_equal(a.weights_, b.weights_)
    assert not np.array_equal(a.particles_, c.particles_)


def test_resampling_is_adaptive(room, field):
    # A threshold of 0 never resamples; a threshold of 1 resamples on every informative scan.
    p = world_pose(room, 3.0, 2.0, 0.0)
    r = room.scan(p, ANGLES)
    never = ParticleFilterLocalizer(resample_threshold=0.0, seed=0).initialize(field, p, std=(0.2, 0.2, 0.1))
    always = ParticleFilterLocalizer(resample_threshold=1.0, seed=0).initialize(field, p, std=(0.2, 0.2, 0.1))
    never.update(ANGLES, r, np.zeros(3))
    always.update(ANGLES, r, np.zeros(3))
    assert not never.resampled_ and always.resampled_
    np.testing.assert_array_equal(always.weights_, 1.0 / always.n_particles)


def test_scan_without_returns_leaves_the_weights(room, field):
    # A scan with no valid beam carries no information: weights are unchanged.
    pf = ParticleFilterLocalizer(seed=0).initialize(field, world_pose(room, 3.0, 2.0, 0.0))
    w = pf.weights_.copy()
    pf.correct(ANGLES, np.full(ANGLES.shape, np.inf))
    np.testing.assert_array_equal(pf.weights_, w)


def test_update_before_initialize_raises(room):
    # A filter without particles refuses updates.
    with pytest.raises(NotUpdatedError):
        ParticleFilterLocalizer().update(ANGLES, np.ones_like(ANGLES), np.zeros(3))


def test_bad_input_raises_and_leaves_the_filter_unchanged(room, field):
    # Bad scans and poses name the argument, and the particles stay as they were.
    pf = ParticleFilterLocalizer(seed=0).initialize(field, world_pose(room, 3.0, 2.0, 0.0))
    pf.update(ANGLES, room.scan(world_pose(room, 3.0, 2.0, 0.0), ANGLES), np.zeros(3))
    before = pf.particles_.copy()
    with pytest.raises(ValueError, match="ranges"):
        pf.update(ANGLES, np.ones(3), np.array([0.1, 0.0, 0.0]))
    with pytest.raises(ValueError, match="odom_pose2d"):
        pf.update(ANGLES, np.ones_like(ANGLES), np.array([np.nan, 0.0, 0.0]))
    np.testing.assert_array_equal(pf.particles_, before)


@pytest.mark.parametrize(
    "params, name",
    [
        ({"n_particles": 0}, "n_particles"),
        ({"alphas": (0.1, 0.1)}, "alphas"),
        ({"resample_threshold": 2.0}, "resample_threshold"),
    ],
)
def test_bad_parameters_raise(field, params, name):
    # Parameters are checked at initialize, naming the parameter.
    with pytest.raises(ValueError, match=name):
        ParticleFilterLocalizer(**params).initialize(field, np.zeros(3))


def test_likelihood_field_needs_occupied_cells():
    # A grid with only free cells has no likelihood field.
    g = OccupancyGrid2D(cell_size=0.1, no_return_range=1.0).update(np.zeros(1), np.array([np.inf]), (0, 0, 0))
    with pytest.raises(ValueError, match="grid"):
        LikelihoodField().fit(g)
