"""Non-ground self-labels above the level horizon (``ClassifierConfig.sky_labels``)."""

import numpy as np
import pytest

from polar_sim.ground import ClassifierConfig, GroundModelConfig, GroundVO
from polar_sim.ground.synthetic import make_sequence

DARK_TILE = (95, 95, 100)   # the checker ground's dark tiles (``synthetic._ground_texture``)


@pytest.fixture(scope="module")
def dark_sky():
    """30 frames of the checker corridor under a plain sky of the dark tiles' colour."""
    return make_sequence(30, width=320, height=240, speed=3.0, yaw_rate=0.05, ground="checker", sky_rgb=DARK_TILE,
                         seed=1)


def _sky_probability(seq, **classifier):
    """Mean P(ground) on the true sky and on the true ground of the last image the run scored."""
    vo = GroundVO(seq["K"], seq["camera_height"], seed=0, downsample=1, classifier=ClassifierConfig(**classifier))
    for i in range(len(seq["rgb"])):
        e = vo.process(seq["rgb"][i], seq["times"][i])
    j = len(seq["rgb"]) - 2                  # the estimate of image i describes image i - 1
    sky = np.isinf(seq["depth"][j])
    return float(e.ground_prob[sky].mean()), float(e.ground_prob[seq["ground_mask"][j]].mean())


# A plain sky has no tracks, so it never gets a label of its own: with the colour of the dark tiles,
# which learn ground, it is taken for ground (this run fails without the sky labels). With them it is
# non-ground. The ground stays ground: its light tiles and joints (half of it) are its own colours, so
# even with the dark half at even odds its mean P(ground) is at least 0.75.
def test_sky_labels_teach_a_plain_sky_of_the_grounds_colour(dark_sky):
    p_sky, p_ground = _sky_probability(dark_sky)
    assert p_sky < 0.5 and p_ground > 0.75
    p_sky0, _ = _sky_probability(dark_sky, sky_labels=0)
    assert p_sky0 > 0.5


# The labels lie where no level ground can be: each pixel's ray, from the intrinsics and the camera's
# pitch (exact geometry, not the camera model GroundVO uses), rises more than sky_margin above the
# level; there are at most sky_labels of them, and they span the image's width. A given horizon row
# (here 40 px above the level horizon) holds them above it by the margin too.
@pytest.mark.parametrize("pitch, horizon_row", [(0.0, None), (0.08, None), (0.0, 80.0)])
def test_sky_labels_lie_above_the_horizon_by_the_margin(pitch, horizon_row):
    seq = make_sequence(2, width=320, height=240, pitch=pitch, seed=2)
    cl = ClassifierConfig()
    vo = GroundVO(seq["K"], seq["camera_height"], seed=0, downsample=1, camera_pitch=pitch,
                  ground=GroundModelConfig(horizon_row=horizon_row))
    vo.process(seq["rgb"][0], 0.0)
    xy = vo.sky_labels_
    assert 0 < len(xy) <= cl.sky_labels
    rays = np.linalg.solve(seq["K"], np.c_[xy, np.ones(len(xy))].T)       # camera frame, y down
    c, s = np.cos(pitch), np.sin(pitch)
    up = -(c * rays[1] + s * rays[2])                                        # level frame, up
    fwd = -s * rays[1] + c * rays[2]
    assert np.all(np.arctan2(up, fwd) > cl.sky_margin)
    if horizon_row is not None:
        assert np.all(np.arctan((horizon_row - xy[:, 1]) / seq["K"][1, 1]) > cl.sky_margin - 1e-9)
    assert np.ptp(xy[:, 0]) > 0.9 * 320 - 8


def test_no_sky_labels_in_the_published_preset_or_when_off():
    seq = make_sequence(2, width=160, height=120, seed=2)
    for vo in (GroundVO.published(seq["K"], seq["camera_height"]),
               GroundVO(seq["K"], seq["camera_height"], classifier=ClassifierConfig(sky_labels=0))):
        vo.process(seq["rgb"][0], 0.0)
        assert vo.sky_labels_.shape == (0, 2)
