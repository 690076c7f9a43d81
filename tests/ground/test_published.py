"""GroundVO.published(): the published code's behaviour as a preset of parameters (issue 17, item 1).

The preset must be bit-identical to the ``compat="code"`` shortcut (whose behaviour the existing tests
pin), every stage switch must be a real parameter (get/set, validated by name), and the preset must
differ from the default where the stages differ.
"""

import numpy as np
import pytest

from ground_helpers import run
from polar_sim.ground import GroundVO
from polar_sim.ground.vo import STAGES

KEYS = ("speed", "yaw_rate", "speed_raw", "yaw_rate_raw", "rates_raw", "pose", "ground_prob", "candidates",
        "inlier_mask")


def _same(ea, eb):
    assert len(ea) == len(eb)
    for a, b in zip(ea, eb):
        assert a.status == b.status
        for k in KEYS:
            x, y = np.asarray(getattr(a, k)), np.asarray(getattr(b, k))
            assert x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), k


@pytest.mark.parametrize("kw", [{}, dict(model="2param"), dict(integration="3d", sampling="uniform")])
def test_published_preset_is_bit_identical_to_compat_code(corridor, kw):
    K, h = corridor["K"], corridor["camera_height"]
    frames = range(12)
    _same(run(GroundVO.published(K, h, seed=0, **kw), corridor, frames),
          run(GroundVO(K, h, compat="code", seed=0, **kw), corridor, frames))


def test_published_preset_is_parameters_not_a_mode(corridor):
    vo = GroundVO.published(corridor["K"], corridor["camera_height"])
    p = vo.get_params()
    assert p["compat"] == "fixed"  # no mode flag: the behaviour is carried by the parameters
    assert all(p[s] == "published" for s in STAGES)
    assert p["n_iter"] == 99 and p["weight_exponent"] == 2.0 and p["irls_iter"] == 0
    assert p["speed_prior_var"] == pytest.approx(2 * p["speed_q"])
    assert p["calibration"] == "none" and p["train_depth"] == "off" and p["decay_samples"] == "off"
    # Dependent values follow the overrides: a 2-parameter model keeps its own iteration default.
    assert GroundVO.published(corridor["K"], 1.0, model="2param").get_params()["n_iter"] == 16
    assert GroundVO.published(corridor["K"], 1.0, speed_q=0.5).get_params()["speed_prior_var"] == 1.0


def test_published_differs_from_the_default(corridor):
    K, h = corridor["K"], corridor["camera_height"]
    a = run(GroundVO.published(K, h), corridor, range(8))
    b = run(GroundVO(K, h), corridor, range(8))
    assert any(not np.array_equal(x.ground_prob, y.ground_prob) for x, y in zip(a, b))


@pytest.mark.parametrize("stage", STAGES)
def test_a_bad_stage_value_names_the_parameter_and_set_params_leaves_the_object(corridor, stage):
    with pytest.raises(ValueError, match=stage):
        GroundVO(corridor["K"], 1.0, **{stage: "code"})
    vo = GroundVO(corridor["K"], 1.0)
    with pytest.raises(ValueError, match=stage):
        vo.set_params(**{stage: 1})
    assert getattr(vo, stage) == "fixed"
    vo.set_params(**{stage: "published"})
    assert getattr(vo, stage) == "published"


def test_published_rejects_an_unknown_override(corridor):
    with pytest.raises(ValueError, match="bogus"):
        GroundVO.published(corridor["K"], 1.0, bogus=1)
