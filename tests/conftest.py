"""Test configuration: headless rendering, and the CI size of slow end-to-end tests."""

import os

# Rendering is headless everywhere (CPU EGL through Mesa); set before anything imports mujoco.
os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from ci_sizes import FULL, size  # noqa: E402,F401


@pytest.fixture
def ci_size():
    return size
