"""Deliberately broken entry points: the battery must classify each failure correctly
(tests/test_testing.py). Importable by the battery's worker processes through PYTHONPATH."""

import os
import time

import numpy as np

from polar_sim._validation import as_points
from polar_sim.errors import NotUpdatedError
from polar_sim.params import Parameterised, Tags
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


# --- a tiny module for the module contract: sound, or with one flaw that one check must catch ---------
def sum_data():
    """The check data of :class:`Sum`: four frames of one (3,) array each; a query without arguments."""
    from polar_sim.params import CheckData

    return CheckData(frames=tuple((np.array([1.0, 2.0, 3.0]) * k,) for k in range(1, 5)))


class Sum(Parameterised):
    """``update(x)`` adds ``scale * x`` to a running sum and returns the sum so far (a new array);
    ``value()`` returns it; ``save``/``load`` keep it in an .npz. ``flaw`` breaks one promise."""

    TAGS = Tags(update="update", query="value", random_state="seed", saves=True, data="battery_dummies:sum_data")

    def __init__(self, scale=1.0, seed=0, flaw=None):
        self.scale, self.seed, self.flaw = scale, seed, flaw

    def get_params(self, deep=True):
        p = super().get_params(deep)
        return {**p, "scale": 0.0} if self.flaw == "params" else p

    def update(self, x):
        if not hasattr(self, "total_"):
            self.total_ = np.zeros(3)
        noise = {"seed": np.random.default_rng().random(), "process": float(hash("polar"))}.get(self.flaw, 0.0)
        self.total_ += self.scale * x + noise
        return x if self.flaw == "alias" else self.total_.copy()

    def value(self):
        if not hasattr(self, "total_"):
            if self.flaw == "query_before":
                return np.zeros(3)
            raise NotUpdatedError("update first")
        if self.flaw == "impure":
            self.total_ += 1.0
        return self.total_.copy()

    def reset(self):
        if self.flaw != "reset":
            super().reset()
        return self

    def save(self, path):
        arrays = {"total": self.total_}
        if self.flaw == "pickle":
            arrays["meta"] = np.array([{"scale": self.scale}], dtype=object)
        np.savez(path, **arrays)

    @classmethod
    def load(cls, path):
        with np.load(path, allow_pickle=True) as z:
            m = cls()
            m.total_ = z["total"].copy()
        return m

    def __deepcopy__(self, memo):
        if self.flaw == "copy":  # a "copy" that shares its state with the original
            return self
        new = type(self)(self.scale, self.seed, self.flaw)
        if hasattr(self, "total_"):
            new.total_ = self.total_.copy()
        return new


class EagerSum(Sum):
    """Learned state before any update."""

    def __init__(self, scale=1.0, seed=0, flaw=None):
        super().__init__(scale, seed, flaw)
        self.total_ = np.zeros(3)
