"""Test configuration: headless rendering, and the CI size of slow end-to-end tests."""

import os

# Rendering is headless everywhere (CPU EGL through Mesa); set before anything imports mujoco.
os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

FULL = os.environ.get("POLAR_SIM_FULL", "") == "1"


def size(full, reduced):
    """Problem size for a slow end-to-end test: ``full`` with POLAR_SIM_FULL=1, else ``reduced``.

    CI runs every slow test at its reduced size; nothing is skipped.
    """
    return full if FULL else reduced


@pytest.fixture
def ci_size():
    return size
