"""Online appearance models: colour Naive Bayes and the multi-scale feature heads."""

import cv2
import numpy as np
import pytest

from polar_sim.tracking.appearance import ColourNB, FeatureHead
from polar_sim.tracking.features import gather, level_features, upsample


def _two_region_image(rng, size=96):
    img = np.zeros((size, size, 3), np.uint8)
    img[:, : size // 2] = (200, 40, 40)
    img[:, size // 2 :] = (40, 60, 190)
    img = np.clip(img + rng.normal(0, 4, img.shape), 0, 255).astype(np.uint8)
    lab = np.zeros((size, size), np.int8)
    lab[:, : size // 2] = 1
    return img, lab


def test_colour_nb_learns_target_colour():
    # the HSV Naive Bayes gives a positive log ratio on the target colour and negative elsewhere
    rng = np.random.default_rng(0)
    img, lab = _two_region_image(rng)
    nb = ColourNB()
    bins = nb.prepare(img)
    ys, xs = np.nonzero(lab >= 0)
    nb.update(bins, ys, xs, lab[ys, xs], np.ones(len(ys)), rng)
    lr = nb.log_ratio(bins)
    assert (lr[lab == 1] > 0).mean() > 0.99 and (lr[lab == 0] < 0).mean() > 0.99


def test_colour_nb_fades_old_evidence():
    # with decay 0.7 the histograms follow a colour swap within a few updates
    rng = np.random.default_rng(1)
    img, lab = _two_region_image(rng)
    nb = ColourNB(decay=0.7)
    bins = nb.prepare(img)
    ys, xs = np.nonzero(lab >= 0)
    for _ in range(3):
        nb.update(bins, ys, xs, lab[ys, xs], np.ones(len(ys)), rng)
    for _ in range(6):
        nb.update(bins, ys, xs, 1 - lab[ys, xs], np.ones(len(ys)), rng)
    assert (nb.log_ratio(bins)[lab == 0] > 0).mean() > 0.99


@pytest.mark.parametrize("variant", ["Su", "Sw", "Wu", "Ww"])
def test_feature_heads_separate_colours(variant):
    # each S/W x u/w head learns the two-region task from sampled labels
    rng = np.random.default_rng(2)
    img, lab = _two_region_image(rng)
    head = FeatureHead(variant[0], variant[1])
    feats = head.prepare(img)
    for _ in range(5):
        ys, xs = rng.integers(0, 96, 400), rng.integers(0, 96, 400)
        head.update(feats, ys, xs, lab[ys, xs], rng.uniform(0.2, 1, 400), rng)
    z = head.log_ratio(feats)
    inner = np.zeros_like(lab, bool)
    inner[:, 8:40] = True
    inner[:, 56:88] = True
    assert ((z > 0) == (lab == 1))[inner].mean() > 0.98


def test_gather_matches_opencv_upsampling():
    # features sampled at full resolution equal the bilinearly upsampled maps (same convention)
    rng = np.random.default_rng(3)
    img = rng.integers(0, 255, (61, 77, 3), dtype=np.uint8)
    feats = level_features(img)
    ys, xs = rng.integers(0, 61, 300), rng.integers(0, 77, 300)
    g = gather(feats, ys, xs, (61, 77))
    for s, F in enumerate(feats):
        up = cv2.resize(F, (77, 61), interpolation=cv2.INTER_LINEAR) if s else F
        assert np.allclose(g[:, 12 * s : 12 * s + 12], up[ys, xs], atol=1e-4)
    assert upsample(feats[0][..., 0], (61, 77)).shape == (61, 77)


def test_head_map_equals_head_on_gathered_features():
    # classify-per-scale-then-upsample equals classify-the-upsampled-stack for the linear heads
    rng = np.random.default_rng(4)
    img, lab = _two_region_image(rng, 80)
    for head_type in ("S", "W"):
        head = FeatureHead(head_type, "u")
        feats = head.prepare(img)
        ys, xs = rng.integers(0, 80, 300), rng.integers(0, 80, 300)
        head.update(feats, ys, xs, lab[ys, xs], np.ones(300), rng)
        z = head.log_ratio(feats)
        X = (gather(feats, ys, xs, (80, 80)) - head.mean) / head._std()
        if head_type == "S":
            zz = X @ head.params[0] + head.params[1][0]
        else:
            W, b, alpha, c = head.params
            zz = (np.einsum("nsc,sc->ns", X.reshape(-1, 4, 12), W) + b) @ alpha + c[0]
        assert np.allclose(z[ys, xs], zz, atol=1e-3)
