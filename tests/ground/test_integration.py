"""Pose integration: closed forms of the unicycle arc and the 3-D step, and agreement with GroundVO's own poses."""

import numpy as np
import pytest
from ground_helpers import run

from polar_sim.ground import GroundVO
from polar_sim.ground.integration import integrate, motion_step


# A unicycle arc at V, ω over dt ends on the circle of radius V/ω, turned by ω dt; zero rates go straight.
def test_planar_step_is_the_exact_arc():
    V, w, dt = 5.0, 0.4, 0.1
    S = motion_step(V, np.array([0.0, w, 0.0]), dt, "planar")
    a = w * dt
    np.testing.assert_allclose(S[:3, 3], [V / w * (1 - np.cos(a)), 0.0, V / w * np.sin(a)], atol=1e-15)
    np.testing.assert_allclose(S[:3, :3] @ S[:3, :3].T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(motion_step(V, np.zeros(3), dt, "planar")[:3, 3], [0, 0, V * dt])
    # 3-D with the yaw rate only: the chord of the same arc (midpoint rotation), same end rotation.
    S3 = motion_step(V, np.array([0.0, w, 0.0]), dt, "3d")
    np.testing.assert_allclose(S3[:3, :3], S[:3, :3], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(S3[:3, 3]), V * dt)


# Integrating a constant turn for one full period returns to the start.
def test_full_circle_closes():
    n, w = 101, 0.5
    t = np.linspace(0, 2 * np.pi / w, n)
    P = integrate(t, np.full(n, 3.0), np.tile([0.0, w, 0.0], (n, 1)), "planar")
    np.testing.assert_allclose(P[-1], np.eye(4), atol=1e-9)


# Re-integrating GroundVO's reported speeds and yaw rates reproduces its trajectory bit for bit.
@pytest.mark.parametrize("mode", ["planar", "3d"])
def test_reintegration_equals_the_estimator(corridor, mode):
    vo = GroundVO(corridor["K"], corridor["camera_height"], seed=0, integration=mode)
    es = run(vo, corridor, range(8))
    rates = np.array([np.where(np.isfinite(e.rates_raw), e.rates_raw, 0.0) if e.status == "ok" else np.zeros(3)
                      for e in es])
    rates[:, 1] = [e.yaw_rate for e in es]
    if mode == "planar":
        rates[:, [0, 2]] = 0.0
    P = integrate(vo.timestamps(), np.array([e.speed for e in es]), rates, mode)
    np.testing.assert_array_equal(P, vo.trajectory())


def test_bad_input():
    with pytest.raises(ValueError, match="shapes"):
        integrate(np.zeros(3), np.zeros(3), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN"):
        integrate(np.arange(3.0), np.array([0, np.nan, 0]), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="mode"):
        integrate(np.arange(3.0), np.zeros(3), np.zeros((3, 3)), "spiral")
