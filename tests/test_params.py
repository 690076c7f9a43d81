"""The module contract's mixin: parameters stored as given, checked set_params, reset, presets."""

import dataclasses

import numpy as np
import pytest

from polar_sim.params import Parameterised


class Toy(Parameterised):
    PUBLISHED = {"alpha": 0.5, "mode": "code"}

    def __init__(self, K=None, *, alpha=1.0, mode="fixed"):
        self.K = K
        self.alpha = alpha
        self.mode = mode

    def _check_params(self):
        if not (isinstance(self.alpha, float) and self.alpha > 0):
            raise ValueError(f"alpha: expected a positive float, got {self.alpha!r}")
        if self.mode not in ("fixed", "code"):
            raise ValueError(f"mode: expected 'fixed' or 'code', got {self.mode!r}")
        return {"alpha": self.alpha, "mode": self.mode}

    def update(self, x):
        self._check_params()
        self.total_ = getattr(self, "total_", 0.0) + self.alpha * x
        return self


# get_params returns what the constructor stored; set_params changes it only when valid.
def test_get_and_set_params():
    t = Toy(np.eye(3), alpha=2.0)
    assert set(t.get_params()) == {"K", "alpha", "mode"} and t.get_params()["alpha"] == 2.0
    t.set_params(alpha=3.0)
    assert t.alpha == 3.0
    with pytest.raises(ValueError, match="alpha"):
        t.set_params(alpha=-1.0, mode="code")
    assert t.alpha == 3.0 and t.mode == "fixed"          # nothing changed
    with pytest.raises(ValueError, match="beta: unknown parameter .* valid: K, alpha, mode"):
        t.set_params(beta=1)


# reset removes the learned state only; published() builds the preset with overrides.
def test_reset_and_published():
    t = Toy().update(2.0)
    assert t.total_ == 2.0
    t.reset()
    assert not hasattr(t, "total_") and t.alpha == 1.0
    p = Toy.published(np.eye(3), alpha=0.25)
    assert p.mode == "code" and p.alpha == 0.25 and p.K.shape == (3, 3)
    assert "mode='code'" in repr(p) and "K=" not in repr(Toy())
    with pytest.raises(ValueError, match="gamma"):
        Toy.published(gamma=1)


@dataclasses.dataclass(frozen=True)
class Stage:
    gain: float = 1.0
    mode: str = "a"

    def __post_init__(self):
        if not self.gain > 0:
            raise ValueError(f"gain: expected > 0, got {self.gain!r}")


class Staged(Parameterised):
    def __init__(self, *, alpha=1.0, stage=Stage()):
        self.alpha = alpha
        self.stage = stage


# a dataclass-valued parameter is a stage: get_params(deep=True) lists its fields as stage__field, and
# set_params changes one through dataclasses.replace (checked by the stage), all or nothing
def test_nested_stage_params():
    t = Staged()
    assert t.get_params(deep=False) == {"alpha": 1.0, "stage": Stage()}
    assert t.get_params() == {"alpha": 1.0, "stage": Stage(), "stage__gain": 1.0, "stage__mode": "a"}
    t.set_params(stage__gain=2.0, alpha=3.0)
    assert t.stage == Stage(gain=2.0) and t.alpha == 3.0
    for bad, match in ((dict(alpha=5.0, stage__gain=-1.0), "stage__gain: expected > 0"),
                       (dict(stage__rate=1), "stage__rate: unknown field of Stage; valid: gain, mode"),
                       (dict(alpha__x=1), "alpha__x: alpha is not a stage config"),
                       (dict(other__x=1), "other__x: unknown parameter")):
        with pytest.raises(ValueError, match=match):
            t.set_params(**bad)
        assert t.stage == Stage(gain=2.0) and t.alpha == 3.0     # nothing changed


# A stage config parameter (a frozen dataclass) is reached as stage__field by get_params(deep=True) and
# set_params, as scikit-learn's nested estimators are; errors name stage__field; nothing changes on error.
def test_nested_stage_configs():
    import dataclasses

    @dataclasses.dataclass(frozen=True)
    class Stage:
        width: int = 3

        def __post_init__(self):
            if not (isinstance(self.width, int) and self.width > 0):
                raise ValueError(f"width: expected a positive int, got {self.width!r}")

    class Nested(Parameterised):
        def __init__(self, *, alpha=1.0, stage=Stage()):
            self.alpha = alpha
            self.stage = stage

    n = Nested()
    assert n.get_params() == {"alpha": 1.0, "stage": Stage(), "stage__width": 3}
    assert n.get_params(deep=False) == {"alpha": 1.0, "stage": Stage()}
    n.set_params(stage__width=5, alpha=2.0)
    assert n.stage == Stage(5) and n.alpha == 2.0
    for bad, match in (({"stage__width": 0}, "stage__width: expected"), ({"stage__depth": 1}, "stage__depth: unknown"),
                       ({"alpha": 3.0, "other__x": 1}, "other__x: unknown")):
        with pytest.raises(ValueError, match=match):
            n.set_params(**bad)
        assert n.stage == Stage(5) and n.alpha == 2.0
