"""Shared synthetic data for the ground tests: a rendered corridor sequence with exact truth."""

import pytest
from ground_helpers import DT, HEIGHT, SPEED, YAW_RATE

from polar_sim.ground.synthetic import make_sequence


@pytest.fixture(scope="session")
def corridor():
    """20 frames of the textured corridor (about 3 s to render once per session)."""
    return make_sequence(20, width=640, height=480, speed=SPEED, yaw_rate=YAW_RATE, dt=DT,
                         camera_height=HEIGHT, seed=3)
