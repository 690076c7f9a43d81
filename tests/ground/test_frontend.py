import cv2
import numpy as np

from polar_sim.ground.frontend import detect_new, is_static, periodic, straightness_gate, track


def test_straightness_gate_wraps_angles():
    # Directions near ±180° (pure upward flow) are straight; only the published unwrapped gate (B15) rejects them.
    x0 = np.array([[10.0, 20.0]])
    x1 = np.array([[10.1, 15.0]])
    x2 = np.array([[9.9, 10.0]])
    assert straightness_gate(x0, x1, x2, wrap=True)[0]
    assert not straightness_gate(x0, x1, x2, wrap=False)[0]
    # A sharp turn is rejected; a short track is always kept.
    assert not straightness_gate(x0, np.array([[15.0, 20.0]]), np.array([[15.0, 25.0]]))[0]
    assert straightness_gate(x0, x0 + [0.5, 0.0], x0 + [0.5, 1.0])[0]


def test_static_test_axis_rule_differs_from_length_rule():
    # Pure horizontal flow: the published per-axis rule (B28) calls it static, the length rule does not.
    disp = np.tile([[5.0, 0.0]], (50, 1))
    assert is_static(disp, per_axis=True) and not is_static(disp)
    assert is_static(np.zeros((50, 2))) and not is_static(np.zeros((0, 2)))


def test_klt_tracks_a_shifted_texture():
    # KLT with forward-backward check follows a 3.25 px shift of a smooth texture to 0.05 px.
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.random((240, 320)).astype(np.float32), (0, 0), 2.0)
    base = (base - base.min()) / np.ptp(base) * 255
    M = np.float32([[1, 0, 3.25], [0, 1, -1.5]])
    a = base.astype(np.uint8)
    b = cv2.warpAffine(base, M, (320, 240), flags=cv2.INTER_CUBIC).astype(np.uint8)
    pts = detect_new(a, np.zeros((0, 2)), max_new=100, cell=20)
    assert 50 <= len(pts) <= 100
    q, ok = track(a, b, pts, pts)
    inner = ok & (pts[:, 0] > 20) & (pts[:, 0] < 300) & (pts[:, 1] > 20) & (pts[:, 1] < 220)
    assert inner.sum() > 30
    assert np.median(np.abs(q[inner] - pts[inner] - [3.25, -1.5])) < 0.05


def test_detect_new_skips_occupied_cells():
    # New corners only go to cells without a track; at most one per cell.
    rng = np.random.default_rng(1)
    img = (rng.random((120, 160)) * 255).astype(np.uint8)
    first = detect_new(img, np.zeros((0, 2)), max_new=500, cell=16)
    cells = set(map(tuple, (first // 16).astype(int).tolist()))
    assert len(cells) == len(first)
    second = detect_new(img, first, max_new=500, cell=16)
    assert not (set(map(tuple, (second // 16).astype(int).tolist())) & cells)


# The aliasing test of new corners (frontend.periodic) against textures whose answer is known: a
# corner on vertical stripes of period 6 px correlates again one period across (True), on smooth noise
# (correlation falls off and stays low) and on a single step edge (it falls monotonically) it does not,
# and a corner too near the border is not tested. The flags also equal a plain-numpy transcription of
# the rule (every patch normalised, then the products) at 300 corners of a mixed image.
def _periodic_reference(grey, pts, half, radius, min_shift, threshold, rise):
    g = grey.astype(np.float64)
    out = np.zeros(len(pts), bool)
    m = half + radius
    for j, (x, y) in enumerate(np.rint(pts).astype(int)):
        if not (m <= x < g.shape[1] - m and m <= y < g.shape[0] - m):
            continue

        def patch(cx, cy):
            p = g[cy - half:cy + half + 1, cx - half:cx + half + 1].ravel()
            p = p - p.mean()
            return p / max(np.linalg.norm(p), 1e-6)

        base = patch(x, y)
        for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
            low = 1.0
            for r in range(1, radius + 1):
                ncc = max(base @ patch(x + r * dx, y + r * dy), base @ patch(x - r * dx, y - r * dy))
                out[j] |= r >= min_shift and ncc > threshold and ncc - low > rise
                low = min(low, ncc)
    return out


def test_periodic_flags_repeating_texture_only():
    xx = np.arange(120)[None, :].repeat(80, axis=0)
    stripes = (128 + 60 * np.sign(np.sin(2 * np.pi * (xx + 0.5) / 6.0))).astype(np.uint8)
    rng = np.random.default_rng(0)
    smooth = cv2.GaussianBlur(rng.normal(128, 40, (80, 120)), (0, 0), 3.0).clip(0, 255).astype(np.uint8)
    edge = np.where(xx < 60, 60, 200).astype(np.uint8)
    pts = np.array([[50.0, 40.0], [61.0, 30.0], [3.0, 40.0]])  # the last is within half + radius of the border
    assert periodic(stripes, pts).tolist() == [True, True, False]
    assert not periodic(smooth, pts).any()
    assert not periodic(edge, pts).any()
    assert periodic(stripes, np.zeros((0, 2))).shape == (0,)
    mixed = np.concatenate([stripes, smooth], axis=1)
    mixed[:, 100:140] = cv2.GaussianBlur(rng.normal(128, 50, (80, 40)), (0, 0), 1.0).clip(0, 255).astype(np.uint8)
    pts = np.c_[rng.uniform(0, 240, 300), rng.uniform(0, 80, 300)]
    for threshold in (0.5, 0.8):
        got = periodic(mixed, pts, half=4, radius=7, min_shift=2, threshold=threshold, rise=0.2)
        assert np.array_equal(got, _periodic_reference(mixed, pts, 4, 7, 2, threshold, 0.2))
        assert got.any() and not got.all()
