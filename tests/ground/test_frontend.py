import numpy as np

from polar_sim.ground.frontend import detect_new, is_static, straightness_gate, track


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
    import cv2

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
