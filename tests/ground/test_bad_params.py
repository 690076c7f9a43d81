"""Bad GroundVO parameters the hostile battery (polar_sim.testing, issue 17) found unclear: each now
raises ValueError/TypeError naming the argument."""

import numpy as np
import pytest

from polar_sim.ground import GroundVO

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
