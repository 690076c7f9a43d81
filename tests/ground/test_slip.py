"""The camera's sideways slip (``MotionConfig.slip``) in GroundVO, against the exact synthetic drive."""

import functools

import numpy as np
import pytest

from polar_sim.ground import GroundVO, MotionConfig
from polar_sim.ground.synthetic import make_sequence

W, H, V, YAW, DT, SLIP = 320, 240, 6.0, 0.2, 0.1, -0.1


@functools.cache
def _seq():
    # a camera 0.6 m ahead of a car's rear axle at 6 m/s: its velocity points t1 = 0.02 to the side
    return make_sequence(30, width=W, height=H, speed=V, yaw_rate=YAW, dt=DT, ground="noise", seed=2, slip=SLIP)


def test_make_sequence_slip_points_the_velocity_off_the_axis():
    # truth generator: between two images the camera moves along its chord turned by the slip's angle
    P = _seq()["poses"]
    d = (np.linalg.inv(P[1]) @ P[2])[:3, 3]
    assert d[0] / d[2] == pytest.approx(np.tan(np.arctan(-SLIP * YAW) + YAW * DT / 2), rel=1e-9)
    assert np.linalg.norm(d) == pytest.approx(2 * V / YAW * np.sin(YAW * DT / 2), rel=1e-9)


@functools.cache
def _yaw_errors(slip):
    seq = _seq()
    vo = GroundVO(seq["K"], 1.0, downsample=1, seed=0, motion=MotionConfig(slip=slip))
    es = [vo.process(r, t) for r, t in zip(seq["rgb"], seq["times"])]
    d = [dict(e.diagnostics, yaw_tracks=e.yaw_rate_raw) for e in es[4:] if "yaw_measured" in e.diagnostics]
    assert len(d) >= 20
    return {z: float(np.mean([x[z] for x in d]) - YAW) for z in ("yaw_tracks", "yaw_dense", "yaw_measured")}


# Given the slip, the tracks' and the dense fit's yaw rates, and the fused one, are within 1 % of the true
# yaw rate on average. Without it (the camera assumed to move along its optical axis) the sideways flow
# of the ground is read as yaw: both sources over-read the turn by more than 5 % (9 % and 20 % here).
@pytest.mark.parametrize("source", ["yaw_tracks", "yaw_dense", "yaw_measured"])
def test_the_slip_removes_the_yaw_bias_of_a_slipping_camera(source):
    assert abs(_yaw_errors(SLIP)[source]) < 0.01 * YAW
    if source != "yaw_measured":
        assert _yaw_errors(0.0)[source] > 0.05 * YAW
