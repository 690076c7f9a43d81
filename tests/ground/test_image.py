import numpy as np
import pytest

from polar_sim.ground.image import N_LABELS, grey, hsv216, reduce2x

# Spec §5.1 examples: (rgb, label under compat="code", label under compat="fixed").
EXAMPLES = [((255, 0, 0), 210, 210), ((255, 0, 128), 214, 215), ((0, 255, 0), 212, 212), ((0, 0, 255), 214, 214),
            ((255, 255, 0), 211, 211), ((128, 128, 128), 108, 108), ((255, 255, 255), 180, 180),
            ((90, 100, 80), 79, 79), ((200, 150, 100), 162, 162), ((0, 0, 0), 0, 0)]


@pytest.mark.parametrize("compat,col", [("code", 1), ("fixed", 2)])
def test_hsv216_spec_examples(compat, col):
    # T1: the ten quantisation examples of spec §5.1, in both modes.
    rgb = np.array([[e[0] for e in EXAMPLES]], dtype=np.uint8)
    assert hsv216(rgb, compat).ravel().tolist() == [e[col] for e in EXAMPLES]


def test_hsv216_bin5_only_reachable_when_fixed():
    # B7: the published hue wrap (+5/6) never yields hue bin 5; the fixed wrap (+1) does.
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    code, fixed = hsv216(rgb, "code"), hsv216(rgb, "fixed")
    assert not np.any(code % 6 == 5) and np.any(fixed % 6 == 5)
    assert code.max() < N_LABELS and fixed.max() < N_LABELS
    # Only negative hues (red is the maximum, g < b) differ between the two modes.
    r, g, b = (rgb[..., i].astype(int) for i in range(3))
    neg = (r >= g) & (r >= b) & (g < b)
    assert np.array_equal(code[~neg], fixed[~neg])


def test_reduce2x_keeps_even_pixels_and_grey_rounds():
    # One pyramid level: output pixel i is centred on input pixel 2i; grey is the rounded BT.601 luma.
    a = np.zeros((40, 60, 3), np.uint8)
    a[20, 30] = 255
    b = reduce2x(a).astype(float)[..., 0]
    assert b.shape == (20, 30)
    i, j = np.unravel_index(np.argmax(b), b.shape)
    assert (i, j) == (10, 15)
    px = np.array([[[90, 100, 80]]], np.uint8)
    assert grey(px)[0, 0] == round(0.299 * 90 + 0.587 * 100 + 0.114 * 80)
