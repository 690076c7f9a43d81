"""Pure pursuit drives a unicycle along a path and measures progress along loops."""

import numpy as np

from polar_sim.control import PurePursuit


# A unicycle steered by pure pursuit round a circle of radius 20 m stays within 0.3 m of it.
def test_follows_circle():
    phi = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    path = np.stack([20 * np.cos(phi), 20 * np.sin(phi)], 1)
    pp = PurePursuit(path, lookahead=3.0, closed=True)
    x, y, th, v, dt = 20.0, 0.0, np.pi / 2, 5.0, 0.05
    worst = 0.0
    for _ in range(800):
        w = pp.steer((x, y, th), v)
        x, y, th = x + v * dt * np.cos(th), y + v * dt * np.sin(th), th + w * dt
        worst = max(worst, abs(np.hypot(x, y) - 20.0))
    assert worst < 0.3
    # 800 steps x 0.25 m = 200 m = 1.59 laps of 125.7 m; progress counts across the lap.
    assert abs(pp.progress((x, y, th)) - 200.0) < 2.0


# Progress and cross-track error on a straight open path.
def test_straight_path():
    pp = PurePursuit([(0, 0), (10, 0)], lookahead=1.0)
    assert abs(pp.progress((4.0, 0.5, 0.0)) - 4.0) < 1e-9
    assert abs(pp.cross_track_error((4.0, 0.5, 0.0)) - 0.5) < 1e-9
    assert pp.steer((4.0, 0.5, 0.0), 1.0) < 0  # steers back toward the path
