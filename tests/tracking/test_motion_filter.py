"""Constant-velocity motion filter on SE(3) (polar_sim.tracking.motion)."""

import numpy as np
import pytest

from polar_sim.geometry import inv_pose, make_pose, se3_exp, se3_log
from polar_sim.tracking.motion import MotionFilter


@pytest.mark.parametrize("mode", ["ekf", "alpha-beta"])
def test_constant_twist_is_predicted(mode):
    # after a few exact measurements of a constant body twist the prediction is exact
    xi = np.array([0.3, -0.2, 0.5, 0.05, 0.1, -0.02])
    dt = 1 / 30
    T = make_pose(None, [0, 0, 0.7])
    f = MotionFilter(T, mode=mode)
    for _ in range(40):
        T = T @ se3_exp(dt * xi)
        Tb, _ = f.predict(dt)
        f.update(T, np.eye(6) * 1e-10, dt)
    Tb, _ = f.predict(dt)
    err = se3_log(inv_pose(T @ se3_exp(dt * xi)) @ Tb)
    assert np.linalg.norm(err[:3]) < 1e-3 and np.linalg.norm(err[3:]) < 2e-4


def test_none_mode_predicts_last_pose():
    # motion prior off: the prediction is the last registered pose
    f = MotionFilter(np.eye(4), mode="none")
    T = make_pose(None, [0.1, 0, 1])
    f.predict(0.1)
    f.update(T, np.eye(6), 0.1)
    assert np.allclose(f.predict(0.1)[0], T)


def test_covariance_grows_without_measurements_and_is_capped():
    # coasting widens the predicted spread, never beyond the cap
    f = MotionFilter(np.eye(4), sigma_cap=(0.3, 0.04))
    s = []
    for _ in range(50):
        _, P = f.predict(1 / 30)
        f.coast(velocity_decay=0.5)
        s.append(np.sqrt(P[3, 3]))
    assert s[5] > s[0] and max(s) <= 0.04 + 1e-12


def test_measurement_pulls_the_state():
    # the update moves the pose towards a measurement in proportion to the relative confidence
    f = MotionFilter(np.eye(4))
    _, P = f.predict(1 / 30)
    f.update(make_pose(None, [0.01, 0, 0]), np.eye(6) * 1e-8, 1 / 30)
    gain = P[3, 3] / (P[3, 3] + 0.002**2)  # prior variance vs the 2 mm measurement floor
    assert f.T[0, 3] == pytest.approx(0.01 * gain, rel=1e-3)


def test_long_coast_with_inflation_stays_bounded():
    # many x4 inflations (a long occlusion), then a measurement: velocity and pose stay sane
    f = MotionFilter(make_pose(None, [0, 0, 0.7]), sigma_cap=(0.3, 0.04))
    for _ in range(60):
        f.predict(1 / 30)
        f.coast(velocity_decay=0.5, inflate=4.0)
    assert np.all(np.sqrt(np.diag(f.P)) <= np.array([0.3] * 3 + [0.04] * 3 + [3.0] * 3 + [1.0] * 3) + 1e-12)
    Tb, _ = f.predict(1 / 30)
    f.update(Tb @ se3_exp([0.01, 0, 0, 0.003, 0, 0]), np.eye(6) * 1e-8, 1 / 30)
    T2, _ = f.predict(1 / 30)
    assert np.linalg.norm(T2[:3, 3] - Tb[:3, 3]) < 0.05 and np.all(np.abs(f.xi) < 10)
