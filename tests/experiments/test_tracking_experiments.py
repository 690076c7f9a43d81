"""The tracking-chapter experiments at their CI size: 320x240 cuts of ``mug_touch`` (frames 80-125, the
palm comes down and rests on the mug) and ``drill_lift`` (frames 90-140, the drill is grasped and lifted),
recorded into the tabletop cache on first use (about 20 s of rendering, shared by the four experiments,
which also share the memoised tracker runs). Each runs end to end and its headline checks hold. The
full sizes and their recorded results: benchmarks/results/tracking_experiments.md."""

import numpy as np
import pytest

from polar_sim.runner import run_experiment


def _run(name, tmp_path):
    res = run_experiment(name, quick=True, out=tmp_path, progress=False)
    failed = [f"{c.name}: {c.detail}" for c in res.checks if not c.passed]
    assert not res.failures, res.failures[0]["error"]
    assert res.checks and not failed, failed
    return res


def _common():
    from polar_sim.runner.registry import _package

    _package()
    from polar_sim.experiments import _tracking_common as C

    return C


# The best variant tracks the touched mug and the lifted drill: ADD(-S) < 0.1 d and IoU > 0.5 on >= 95 %
# of frames; every variant ran on both cuts, with per-frame arrays and figures written.
@pytest.mark.slow
def test_tracking_variants_quick(tmp_path):
    res = _run("tracking_variants", tmp_path)
    assert len(res.table) == 10 and {r["variant"] for r in res.table} == {"h", "su", "sw", "wu", "ww"}
    assert {r["frames"] for r in res.table} == {45, 50}
    assert all(r["width"] == 320 and r["cpu_ms_median"] > 0 for r in res.table)
    for f in ("tracking_variants_curves.png", "tracking_variants_table.csv", "tracking_variants_speed.csv"):
        assert (tmp_path / f).is_file(), f
    assert len(list((tmp_path / "trials").glob("*/frames.npz"))) == 10


# The best variant's masks reach IoU > 0.5 on >= 95 % of frames and label <= 5 % of the touching
# hand's pixels as target; shape-only (appearance off) is scored beside the variants.
@pytest.mark.slow
def test_tracking_segmentation_quick(tmp_path):
    res = _run("tracking_segmentation", tmp_path)
    assert {r["variant"] for r in res.table} == {"h", "su", "sw", "wu", "ww", "shape-only"}
    assert all(r["touch_frames"] > 10 and r["hand_px_touch"] > 1000 for r in res.table)
    assert (tmp_path / "tracking_segmentation.png").is_file()


# Under occlusion by touch every variant beats plain ICP on all ROI points, on pose and on mask.
@pytest.mark.slow
def test_tracking_ablation_quick(tmp_path):
    res = _run("tracking_ablation", tmp_path)
    assert len(res.table) == 20
    plain = [r for r in res.table if r["config"] == "plain-icp"]
    assert all(r["occl_frames"] > 10 for r in plain)
    assert sum(r["lost"] for r in plain) > 0  # plain ICP loses the object where the hand is


# The picture strip (five panels) of the touched mug is drawn and stacked.
@pytest.mark.slow
def test_tracking_strips_quick(tmp_path):
    import cv2

    res = _run("tracking_strips", tmp_path)
    (row,) = res.table
    assert row["in_contact"] and row["occlusion"] > 0.3 and row["iou"] > 0.5
    img = cv2.imread(str(tmp_path / "tracking_strips.png"))
    assert img is not None and img.shape[1] > 4 * img.shape[0]


# FrameStream reads a recording frame by frame exactly as Recording.load does (bit for bit).
def test_frame_stream_matches_recording(tmp_path):
    from polar_sim.sim.recording import Recording
    from polar_sim.sim.tabletop_sequences import record_sequence

    C = _common()
    path = tmp_path / "cut.npz"
    record_sequence("cube_push", seed=0, n_frames=6, width=64, height=48, out=path)
    rec = Recording.load(path)
    s = C.FrameStream(path, keys=C.FrameStream.IMAGES)
    seen = 0
    for i, fr in s.frames(2, 6):
        ref = rec[i]
        for k, v in fr.items():
            assert v.dtype == ref[k].dtype and np.array_equal(v, ref[k]), (i, k)
        seen += 1
    assert seen == 4 and len(s) == 6
    for k, v in s.values.items():
        assert np.array_equal(v, rec.stack(k)), k


# A tracker run is deterministic in (sequence, seed, configuration): two runs give the same poses,
# masks and scores bit for bit (only the timings differ), which is what makes the memo valid.
@pytest.mark.slow
def test_track_is_deterministic():
    C = _common()
    a1, _ = C.track("drill_lift", 0, "ww", quick=True, memo=False, stop=100)
    a2, _ = C.track("drill_lift", 0, "ww", quick=True, memo=False, stop=100)
    for k in a1:
        if k not in ("cpu_ms", "wall_ms"):
            assert np.array_equal(a1[k], a2[k], equal_nan=True), k
