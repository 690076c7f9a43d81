"""Pure pursuit drives a unicycle along a path and measures progress along loops."""

import numpy as np
import pytest

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


# curvature(x, y) is the arc from the origin (heading +x) through (x, y): the circle of radius 1/k
# centred at (0, 1/k) passes through the point.
def test_curvature_is_the_arc_through_the_point():
    rng = np.random.default_rng(0)
    for x, y in rng.uniform(-5, 5, (50, 2)):
        k = PurePursuit.curvature(x, y)
        assert abs(x * x + (y - 1 / k) ** 2 - 1 / k**2) < 1e-9 * max(1.0, 1 / k**2)
    assert PurePursuit.curvature(3.0, 0.0) == 0.0


# Waypoint targets with the speed profile: an L-shaped path is followed to its end (done), the
# rover staying near the path; behind it, the command turns on the spot at the yaw-rate limit.
def test_waypoint_target_follows_a_corner_and_turns_on_the_spot():
    path = np.r_[np.c_[np.arange(0, 10.01, 0.1), np.zeros(101)], np.c_[np.full(100, 10.0), np.arange(0.1, 10.01, 0.1)]]
    pp = PurePursuit(path, 0.5, target="waypoint", max_yaw_rate=2.0, turn_in_place=np.pi / 3, min_speed=0.05)
    x, y, th, dt = 0.0, 0.0, 0.0, 0.05
    worst = 0.0
    for _ in range(2000):
        v, w = pp.command((x, y, th), 1.0)
        assert 0.05 <= v <= 1.0 and abs(w) <= 2.0
        x, y, th = x + v * dt * np.cos(th), y + v * dt * np.sin(th), th + w * dt
        worst = max(worst, np.min(np.hypot(*(path - (x, y)).T)))
        if pp.done:
            break
    assert pp.done and np.hypot(x - 10, y - 10) < 0.6 and worst < 0.3
    pp.reset()
    assert not pp.done
    v, w = pp.command((0.0, 0.0, np.pi), 1.0)       # the target straight behind
    assert v == 0.05 and abs(w) == 2.0


# On the path, heading along it: full speed, no turn (arc target).
def test_command_on_a_straight_path():
    pp = PurePursuit([(0, 0), (10, 0)], lookahead=1.0)
    assert pp.command((2.0, 0.0, 0.0), 1.5) == (1.5, 0.0)
    assert not pp.done
    pp.progress((10.0, 0.0, 0.0))
    assert pp.done


@pytest.mark.parametrize("kwargs, err, name", [
    ({"lookahead": 0.0}, ValueError, "lookahead"), ({"lookahead": "1"}, TypeError, "lookahead"),
    ({"lookahead_time": -1.0}, ValueError, "lookahead_time"), ({"target": "nearest"}, ValueError, "target"),
    ({"target": "waypoint", "closed": True}, ValueError, "closed"), ({"closed": 1}, TypeError, "closed"),
    ({"max_yaw_rate": 0.0}, ValueError, "max_yaw_rate"), ({"turn_in_place": 4.0}, ValueError, "turn_in_place"),
    ({"min_speed": -0.1}, ValueError, "min_speed"), ({"path": [(0, 0)]}, ValueError, "path"),
    ({"path": [(0, 0), (np.nan, 1)]}, ValueError, "path")])
def test_bad_parameters_name_the_argument(kwargs, err, name):
    kwargs = {"path": [(0, 0), (10, 0)], **kwargs}
    with pytest.raises(err, match=f"^{name}:"):
        PurePursuit(**kwargs)
