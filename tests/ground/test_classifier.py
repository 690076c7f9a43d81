import numpy as np

from polar_sim.ground.classifier import GroundColourModel, window_labels


def test_window_labels_counts_3x3_and_skips_outside():
    # A 3x3 window around an interior point gives 9 labels; at a corner only the 4 inside pixels count.
    lab = np.arange(25, dtype=np.uint8).reshape(5, 5)
    assert sorted(window_labels(lab, np.array([[2.0, 2.0]])).tolist()) == [6, 7, 8, 11, 12, 13, 16, 17, 18]
    assert sorted(window_labels(lab, np.array([[0.0, 0.0]])).tolist()) == [0, 1, 5, 6]


def test_histograms_decay_and_posterior():
    # H <- 0.7 H + H_new; posterior with pseudo-counts and the 0.2 prior (spec §5.2, §5.4).
    lab = np.zeros((10, 10), np.uint8)
    lab[:, 5:] = 7
    m = GroundColourModel(alpha=0.7, prior=0.2, pseudo_ground=0.5, pseudo_nonground=1.0)
    m.update(lab, np.array([[2.0, 5.0]]), np.array([[7.0, 5.0]]))
    m.update(lab, np.array([[2.0, 5.0]]), np.zeros((0, 2)))
    assert m.hist_ground[0] == 9 * 0.7 + 9 and m.hist_nonground[7] == 9 * 0.7
    lg = (m.hist_ground + 0.5) / (m.hist_ground.sum() + 108)
    lng = (m.hist_nonground + 1) / (m.hist_nonground.sum() + 216)
    post = lg * 0.2 / (lg * 0.2 + lng * 0.8)
    np.testing.assert_allclose(m.posterior_table(), post)
    p = m.predict(lab)
    assert p.dtype == np.float32 and p[0, 0] > 0.8 and p[0, 9] < 0.1


def test_untrained_posterior_is_the_prior():
    # Empty histograms: every label has P(G) = prior.
    m = GroundColourModel()
    np.testing.assert_allclose(m.posterior_table(), 0.2)
