"""Fixtures of the baseline tests (the scene itself is in baselines_scene.py)."""

import pytest
from baselines_scene import build_grid, make_room


@pytest.fixture(scope="session")
def room():
    return make_room()


@pytest.fixture(scope="session")
def mapped_grid(room):
    """A 5 cm grid built from five exact scans spread over the room (do not mutate)."""
    return build_grid(room)
