"""polar_sim.runner.localise: the localisation protocols the GPIS experiments share, on analytic
cases (numpy only; exact answers)."""

import numpy as np
import pytest

from polar_sim.geometry import between2d, compose2d
from polar_sim.runner.localise import budget_match, localise_drive, noisy_odometry, perturbed_start, relocalise


class _NoNoise:
    """An rng whose normals are their mean (zero noise)."""

    def normal(self, loc, scale):
        return loc


def _straight(n=11, step=0.5):
    return np.column_stack([np.arange(n) * step, np.zeros(n), np.zeros(n)])


# without noise, scale 1 and no drift the odometry is the drive; with a scale error it stretches the
# travel by exactly that factor; with a yaw drift the heading grows by drift x distance
def test_noisy_odometry_exact_cases():
    truth = _straight()
    np.testing.assert_allclose(noisy_odometry(truth, _NoNoise(), scale=1.0, drift_deg_per_m=0.0), truth, atol=1e-12)
    o = noisy_odometry(truth, _NoNoise(), scale=1.02, drift_deg_per_m=0.0)
    np.testing.assert_allclose(o[:, 0], 1.02 * truth[:, 0], atol=1e-12)
    o = noisy_odometry(truth, _NoNoise(), scale=1.0, drift_deg_per_m=0.5)
    np.testing.assert_allclose(o[:, 2], np.radians(0.5) * truth[:, 0], atol=1e-12)
    # a seeded generator gives the same odometry twice, and draws 3 normals per step
    a = noisy_odometry(truth, np.random.default_rng(3))
    r = np.random.default_rng(3)
    np.testing.assert_array_equal(a, noisy_odometry(truth, r))
    r2 = np.random.default_rng(3)
    r2.normal(size=3 * (len(truth) - 1))
    assert r.uniform() == r2.uniform()
    with pytest.raises(ValueError, match="poses"):
        noisy_odometry(np.zeros((4, 2)), _NoNoise())


def test_perturbed_start():
    rng = np.random.default_rng(7)
    p = perturbed_start([1.0, 2.0, 0.3], rng, offset_m=0.2, offset_deg=3.0)
    assert np.hypot(p[0] - 1.0, p[1] - 2.0) == pytest.approx(0.2, abs=1e-12)
    assert abs(p[2] - 0.3) == pytest.approx(np.radians(3.0), abs=1e-12)
    r = np.random.default_rng(7)                    # a uniform, then a choice: the experiments' order
    b, sgn = r.uniform(-np.pi, np.pi), r.choice([-1.0, 1.0])
    np.testing.assert_allclose(p, [1.0 + 0.2 * np.cos(b), 2.0 + 0.2 * np.sin(b), 0.3 + np.radians(3.0) * sgn], atol=1e-15)


class _Offset:
    """A localiser whose answer is the true pose moved by a fixed offset (in the pose's frame)."""

    def __init__(self, truth, offset):
        self.truth, self.offset, self.calls = truth, np.asarray(offset, float), []

    def reset(self, pose):
        self.start, self.i = np.asarray(pose, float), 0

    def step(self, angles, ranges, delta):
        self.calls.append((float(ranges[0]), np.asarray(delta).copy()))
        out = compose2d(self.truth[min(self.i, len(self.truth) - 1)], self.offset)
        self.i += 1
        return out


# localise_drive hands each step the odometry increment and the scan, and scores the answer
def test_localise_drive_scores_against_truth():
    truth = _straight()
    odom = noisy_odometry(truth, _NoNoise(), scale=1.1, drift_deg_per_m=0.0)
    ranges = np.arange(len(truth), dtype=float)[:, None] * np.ones((1, 5))
    loc = _Offset(truth, [0.03, -0.04, np.radians(2.0)])
    r = localise_drive(loc, np.zeros(5), ranges, truth, odom, truth[0])
    np.testing.assert_allclose(r["err"], np.tile([0.05, 2.0], (len(truth), 1)), atol=1e-9)
    assert [c[0] for c in loc.calls] == list(range(len(truth)))
    np.testing.assert_array_equal(loc.calls[0][1], np.zeros(3))
    for i in range(1, len(truth)):
        np.testing.assert_allclose(loc.calls[i][1], between2d(odom[i - 1], odom[i]), atol=1e-12)
        assert loc.calls[i][1][0] == pytest.approx(0.55)
    assert r["cpu_ms"].shape == r["wall_ms"].shape == (len(truth),)


# each scan is localised from its own perturbed pose and scored against that pose
def test_relocalise():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, -1.0, -2.0]])

    class Snap:                                    # returns the nearest of the known poses
        def reset(self, p):
            self.p = p

        def step(self, angles, ranges, delta):
            return poses[np.argmin(np.hypot(*(poses[:, :2] - self.p[:2]).T))]

    err, cpu = relocalise(Snap(), np.zeros(3), np.ones((3, 3)), poses, np.random.default_rng(0))
    np.testing.assert_allclose(err, 0.0, atol=1e-12)
    assert cpu.shape == (3,)


# a localiser that returns one pose buffer, updated in place, is scored step by step, not by its
# last answer
def test_localise_drive_copies_each_answer():
    truth = _straight(n=4)

    class Buffer:
        def reset(self, pose):
            self.pose_, self.i = np.zeros(3), 0

        def step(self, angles, ranges, delta):
            self.pose_[:] = truth[self.i]
            self.i += 1
            return self.pose_

    r = localise_drive(Buffer(), np.zeros(1), np.ones((4, 1)), truth, truth, truth[0])
    np.testing.assert_array_equal(r["err"], 0.0)


def test_budget_match():
    st = [{"method": "icpg", "cpu_ms_median": 5.0}, {"method": "pf1000", "cpu_ms_median": 2.0},
          {"method": "pf5000", "cpu_ms_median": 6.0}, {"method": "pf10000", "cpu_ms_median": 12.0},
          {"method": "pfx", "cpu_ms_median": 99.0}]
    pf, g = budget_match(st)
    assert pf["method"] == "pf5000" and g == 5.0
    pf, _ = budget_match([st[0], st[1]])
    assert pf["method"] == "pf1000"                 # none reaches the budget: the largest
    assert budget_match([st[0]])[0] is None
