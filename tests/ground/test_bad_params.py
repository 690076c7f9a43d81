"""Bad GroundVO parameters the hostile battery (polar_sim.testing, issue 17) found unclear: each now
raises ValueError/TypeError naming the argument. (The stage configs' fields: ``test_config.py``.)"""

import numpy as np
import pytest

from polar_sim.ground import CalibrationConfig, GroundVO

K = np.array([[100.0, 0, 79.5], [0, 100.0, 59.5], [0, 0, 1.0]])


@pytest.mark.parametrize("h", [1e-300, 5e-324, 1e-4, 1e5, 1e300])
def test_a_camera_height_outside_1mm_to_10km_names_camera_height(h):
    # (1.68 / h)^2 scales the default noise: 1e-300 overflowed (OverflowError), 1e300 underflowed to 0.
    with pytest.raises(ValueError, match="camera_height"):
        GroundVO(K, h)


@pytest.mark.parametrize("h", [1e-3, 1.65, 1e4])
def test_the_bounds_themselves_are_accepted(h):
    assert GroundVO(K, h).camera_height == h


@pytest.mark.parametrize("model", [["6param"], {"a": 1}, 6, None])
def test_a_model_that_is_not_a_string_names_model(model):
    with pytest.raises((TypeError, ValueError), match="model"):
        GroundVO(K, 1.0, model=model)


@pytest.mark.parametrize("kw, name", [(dict(seed=-1), "seed"), (dict(seed="0"), "seed"), (dict(camera_pitch=2.0), "camera_pitch"),
                                      (dict(camera_pitch=True), "camera_pitch"), (dict(sampling=None), "sampling"),
                                      (dict(camera_pitch=1e30), "camera_pitch"), (dict(downsample=2.0), "downsample"),
                                      (dict(downsample=np.array([2, 2])), "downsample")])
def test_bad_top_level_parameters_name_the_argument(kw, name):
    with pytest.raises((TypeError, ValueError), match=name):
        GroundVO(K, 1.0, **kw)


def test_the_calibration_settings_reach_the_calibrator():
    vo = GroundVO(K, 1.0, calibration=CalibrationConfig(decay=0.5, prior_weight=7.0))
    vo.process(np.zeros((120, 160, 3), np.uint8), 0.0)
    assert vo.calibrator_.decay == 0.5 and vo.calibrator_.prior_weight == 7.0
    vo = GroundVO(K, 1.0)
    vo.process(np.zeros((120, 160, 3), np.uint8), 0.0)
    assert vo.calibrator_.decay == 0.99 and vo.calibrator_.prior_weight == 5.0  # the defaults (dev sweep)
