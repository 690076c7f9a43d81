"""polar_sim.metrics.localisation: position and heading errors of planar poses and their pooled
statistics, on analytic cases."""

import numpy as np
import pytest

from polar_sim.metrics import heading_error_deg, pooled_pose2d_errors, pose2d_errors


# headings wrap: 0.01 rad either side of +-pi are 0.02 rad apart; opposite headings are 180 deg
# apart whatever the turn count; arrays give arrays
def test_heading_error_wraps():
    assert heading_error_deg(np.pi - 0.01, -np.pi + 0.01) == pytest.approx(np.degrees(0.02), abs=1e-9)
    assert heading_error_deg(0.0, np.pi) == pytest.approx(180.0)
    assert heading_error_deg(4 * np.pi + 0.1, -0.1) == pytest.approx(np.degrees(0.2), abs=1e-9)
    out = heading_error_deg(np.array([0.0, 1.0, -1.0]), np.array([0.5, 1.0, 1.0]))
    np.testing.assert_allclose(out, np.degrees([0.5, 0.0, 2.0]), atol=1e-12)
    assert isinstance(heading_error_deg(0.0, 0.5), float)


# a 3-4-5 offset is 5 m off; the heading error is wrapped, whatever the position
def test_pose2d_errors_exact():
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, np.pi - 0.05]])
    est = truth + [[3.0, 4.0, np.radians(10.0)], [-0.6, 0.8, 0.1]]
    np.testing.assert_allclose(pose2d_errors(est, truth), [[5.0, 10.0], [1.0, np.degrees(0.1)]], atol=1e-9)


# the pooled statistics of four steps, worked by hand (numpy's linear percentiles)
def test_pooled_statistics():
    e = np.array([[0.1, 1.0], [0.2, 2.0], [0.9, 3.0], [0.4, 4.0]])
    st = pooled_pose2d_errors(e, 0.5)
    assert st == {"steps": 4, "pos_median_m": pytest.approx(0.3), "pos_p90_m": pytest.approx(0.75),
                  "pos_max_m": 0.9, "head_median_deg": 2.5, "head_p90_deg": pytest.approx(3.7), "fail_steps": 1}
    assert pooled_pose2d_errors(e, 0.95)["fail_steps"] == 0


# bad input names the argument: strings and complex numbers are the wrong kind (TypeError),
# shapes, NaN and negative errors the wrong value (ValueError)
@pytest.mark.parametrize("call, exc, name", [
    (lambda: heading_error_deg("0.1", 0.0), TypeError, "est"),
    (lambda: heading_error_deg(0.0, 1j), TypeError, "truth"),
    (lambda: heading_error_deg([0.0, 1.0], [0.0]), ValueError, "truth"),
    (lambda: heading_error_deg(np.nan, 0.0), ValueError, "est"),
    (lambda: pose2d_errors(np.zeros((2, 2)), np.zeros((2, 2))), ValueError, "est"),
    (lambda: pose2d_errors(np.zeros((2, 3)), np.zeros((3, 3))), ValueError, "truth"),
    (lambda: pose2d_errors(np.zeros((2, 3)), np.full((2, 3), "a")), TypeError, "truth"),
    (lambda: pooled_pose2d_errors(np.zeros((0, 2)), 0.5), ValueError, "errors"),
    (lambda: pooled_pose2d_errors([[-0.1, 0.0]], 0.5), ValueError, "errors"),
    (lambda: pooled_pose2d_errors([[0.1, 0.0]], "0.5"), TypeError, "fail_m"),
])
def test_bad_input(call, exc, name):
    with pytest.raises(exc, match=f"^{name}:"):
        call()
