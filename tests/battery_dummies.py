"""Deliberately broken entry points: the battery must classify each failure correctly
(tests/test_testing.py). Importable by the battery's worker processes through PYTHONPATH."""

import os
import time

import numpy as np

from polar_sim._validation import as_points
from polar_sim.testing import EntryPoint


class Box:
    """A tiny module with a state (``total_``) and one update method whose behaviour is chosen."""

    def __init__(self, mode):
        self.mode = mode
        self.total_ = np.zeros(2)

    def update(self, points):
        if self.mode == "crash" and np.asarray(points, dtype=object).size == 0:
            os.abort()                                      # kills the interpreter
        if self.mode == "hang" and isinstance(points, str):
            time.sleep(3600)
        if self.mode == "state":
            self.total_ += 1.0                              # changes state before validating
        if self.mode == "silent":
            self.total_ += np.asarray(points, dtype=np.float64).reshape(-1, 2).sum(0)  # no checks
            return self
        if self.mode == "keyerror" and points is None:
            raise KeyError("points")
        p = as_points(points, 2, "points")
        self.total_ += p.sum(0)
        return self


def _entry(mode):
    return EntryPoint(f"dummy-{mode}", setup=lambda tmp: Box(mode), args=lambda t, tmp: {"points": np.ones((3, 2))},
                      call=lambda t, a: t.update(a["points"]), kinds={"points": "points"}, timeout=5.0)


def good():
    return _entry("good")


def crash():
    return _entry("crash")


def hang():
    return _entry("hang")


def state():
    return _entry("state")


def silent():
    return _entry("silent")


def keyerror():
    return _entry("keyerror")
