"""The stage configs of GroundVO (issue 34): every field validated on construction, sizes bounded
before anything is allocated, nested parameters as ``stage__field``."""

import dataclasses

import numpy as np
import pytest

from polar_sim.ground import (CalibrationConfig, ClassifierConfig, DenseConfig, FilterConfig, GroundModelConfig,
                              GroundVO, MotionConfig, TrackingConfig)
from polar_sim.ground.config import MAX_FEATURES, MAX_RANSAC_ITER
from polar_sim.ground.vo import STAGE_CONFIGS

K = np.array([[100.0, 0, 79.5], [0, 100.0, 59.5], [0, 0, 1.0]])

#: (config, field, bad value): wrong type, out of range, non-finite, too large, unknown choice.
BAD = [
    (TrackingConfig, "max_features", 2**63), (TrackingConfig, "max_features", 9), (TrackingConfig, "max_features", 4.0e2),
    (TrackingConfig, "klt_window", 10**6), (TrackingConfig, "klt_levels", 100), (TrackingConfig, "fb_max", float("nan")),
    (TrackingConfig, "fb_max", -1.0), (TrackingConfig, "ground_warp", "yes"), (TrackingConfig, "track_gates", "code"),
    (MotionConfig, "min_triplets", 2**40), (MotionConfig, "irls_iter", 10**9), (MotionConfig, "irls_iter", -1),
    (MotionConfig, "n_global", 2), (MotionConfig, "n_global", True), (MotionConfig, "ridge", float("inf")),
    (MotionConfig, "estimate_foe", 1), (MotionConfig, "exact_flow", None), (MotionConfig, "depth_q", 0.0),
    (MotionConfig, "slip", float("nan")), (MotionConfig, "slip", 2.0), (MotionConfig, "slip", "car"),
    (MotionConfig, "depth_r", "0.6"), (MotionConfig, "depth_p_reset", -1.0), (MotionConfig, "depth_fusion", None),
    (GroundModelConfig, "n_iter", 0), (GroundModelConfig, "n_iter", 2**63), (GroundModelConfig, "n_iter", 55.0),
    (GroundModelConfig, "lam", -0.1), (GroundModelConfig, "sigma", 0.0), (GroundModelConfig, "weight_exponent", 1e400),
    (GroundModelConfig, "min_inliers", 1), (GroundModelConfig, "horizon_row", -3.0),
    (GroundModelConfig, "ransac_draw", "paper"),
    (FilterConfig, "speed_prior", float("nan")), (FilterConfig, "speed_prior", "0"), (FilterConfig, "speed_q", 0.0),
    (FilterConfig, "yaw_r", -5.0), (FilterConfig, "speed_prior_var", float("inf")), (FilterConfig, "rules", "code"),
    (FilterConfig, "pose_steps", 1),
    (ClassifierConfig, "alpha", 1.5), (ClassifierConfig, "ground_prior", 1.0), (ClassifierConfig, "ground_prior", 0.0),
    (ClassifierConfig, "ng_from_outliers", "no"), (ClassifierConfig, "ng_outlier_sigma", 0.0),
    (ClassifierConfig, "ng_outlier_sigma", float("nan")), (ClassifierConfig, "ng_outlier_history", "yes"),
    (ClassifierConfig, "sky_labels", -1), (ClassifierConfig, "sky_labels", 2.5), (ClassifierConfig, "sky_margin", -0.1),
    (ClassifierConfig, "sky_margin", float("nan")), (ClassifierConfig, "train_depth", "off"), (ClassifierConfig, "decay_samples", -1.0),
    (ClassifierConfig, "hue_wrap", "code"), (ClassifierConfig, "ground_labels", ""),
    (CalibrationConfig, "method", "isotonic"), (CalibrationConfig, "window", 4), (CalibrationConfig, "window", 10**9),
    (CalibrationConfig, "decay", 1.5), (CalibrationConfig, "decay", -0.1), (CalibrationConfig, "prior_weight", -1.0),
    (CalibrationConfig, "prior_weight", "5"),
    (GroundModelConfig, "var_scale", 0.0),
    (DenseConfig, "enabled", 1), (DenseConfig, "model", "homography"), (DenseConfig, "max_depth", 0.0),
    (DenseConfig, "levels", 5), (DenseConfig, "smoothing", 11.0), (DenseConfig, "block", 0),
    (DenseConfig, "max_pixels", 2**63), (DenseConfig, "min_gradient", -1.0), (DenseConfig, "min_pixels", 2),
    (DenseConfig, "max_iter", 10**6), (DenseConfig, "residual_floor", 0.0), (DenseConfig, "gradient_weight", float("nan")),
    (DenseConfig, "prob_floor", 1.5), (DenseConfig, "var_scale", float("inf")), (DenseConfig, "spread_scale", -1.0),
    (DenseConfig, "alias_sigmas", -3.0), (DenseConfig, "alias_margin", "0.2"), (DenseConfig, "alias_var_scale", 0.5),
    (DenseConfig, "gate", 0.0), (DenseConfig, "label_evidence", float("nan")), (DenseConfig, "max_labels", 2**63),
    (DenseConfig, "track_alias_px", 0.0), (DenseConfig, "periodic_ncc", 1.5),
]


# Every bad field value raises ValueError/TypeError naming the field (the probe: max_features=2**63
# raised cv2.error/std::bad_alloc; now the limit is named).
@pytest.mark.parametrize("cls, name, value", BAD, ids=[f"{c.__name__}.{n}={v!r}" for c, n, v in BAD])
def test_a_bad_field_names_the_field(cls, name, value):
    with pytest.raises((ValueError, TypeError), match=name):
        cls(**{name: value})


def test_size_limits_are_named_in_the_message():
    with pytest.raises(ValueError, match=f"max_features: expected an integer <= {MAX_FEATURES}"):
        TrackingConfig(max_features=2**63)
    with pytest.raises(ValueError, match=f"n_iter: expected an integer <= {MAX_RANSAC_ITER}"):
        GroundModelConfig(n_iter=2**63)
    with pytest.raises(ValueError, match=f"max_pixels: expected an integer <= {MAX_FEATURES}"):
        DenseConfig(max_pixels=2**63)
    # Within each bound, their product is bounded too: the RANSAC residuals of one frame.
    with pytest.raises(ValueError, match="ground__n_iter.*tracking__max_features"):
        GroundVO(K, 1.0, tracking=TrackingConfig(max_features=MAX_FEATURES), ground=GroundModelConfig(n_iter=10**4))


# The defaults are valid, frozen, and each config's published() changes only what the spec lists.
@pytest.mark.parametrize("cls", list(STAGE_CONFIGS.values()))
def test_defaults_are_frozen_and_published_is_a_config(cls):
    c = cls()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.__setattr__(dataclasses.fields(c)[0].name, 1)
    assert isinstance(cls.published(), cls) and cls.published() != c
    assert c.replace() == c


# GroundVO takes at most 15 arguments; a stage parameter must be its config (not a dict).
def test_groundvo_has_at_most_15_parameters_and_checks_config_types():
    assert len(GroundVO._param_names()) <= 15
    for name in STAGE_CONFIGS:
        with pytest.raises(TypeError, match=name):
            GroundVO(K, 1.0, **{name: {}})


# get_params(deep=True) lists every stage field as stage__field; set_params reaches them, checks them,
# names them in errors and leaves the object unchanged on a bad value; a round trip is the identity.
def test_nested_parameters():
    vo = GroundVO(K, 1.0)
    p = vo.get_params(deep=True)
    for name, cls in STAGE_CONFIGS.items():
        assert p[name] == cls()
        assert all(p[f"{name}__{f.name}"] == getattr(cls(), f.name) for f in dataclasses.fields(cls))
    assert set(vo.get_params(deep=False)) == set(GroundVO._param_names())
    vo.set_params(tracking__max_features=600, calibration__window=3, model="2param")
    assert vo.tracking.max_features == 600 and vo.calibration.window == 3 and vo.model == "2param"
    assert vo.tracking.klt_window == 11  # the other fields of the stage are kept
    before = vo.get_params()
    for bad, match in ((dict(tracking__max_features=2**63), "tracking__max_features"),
                       (dict(tracking__bogus=1), "tracking__bogus"), (dict(nostage__x=1), "nostage__x"),
                       (dict(model="6param", classifier__alpha=2.0), "classifier__alpha")):
        with pytest.raises(ValueError, match=match):
            vo.set_params(**bad)
        assert vo.get_params() == before
    fresh = GroundVO(K, 1.0).set_params(**{k: v for k, v in before.items() if "__" in k})
    assert all(getattr(fresh, s) == getattr(vo, s) for s in STAGE_CONFIGS)


# A parameter changed after the first image takes effect at the next sequence (reset), as before.
def test_set_params_after_processing_applies_after_reset():
    vo = GroundVO(K, 1.0)
    vo.process(np.zeros((120, 160, 3), np.uint8), 0.0)
    vo.set_params(calibration__decay=0.5)
    assert vo.calibrator_.decay == 0.99
    vo.reset().process(np.zeros((120, 160, 3), np.uint8), 0.0)
    assert vo.calibrator_.decay == 0.5
