"""replay(): the per-frame outputs of a VO over frames, for GroundVO and for a minimal plug-in."""

import types

import numpy as np

from polar_sim.ground import GroundVO
from polar_sim.ground.replay import replay


# GroundVO replayed gives exactly what processing the frames by hand gives; the callback sees every frame
# with the previous one (the middle frame of the estimate).
def test_replay_of_groundvo_matches_direct_processing(corridor):
    frames = [{"rgb": r, "t": t, "i": i} for i, (r, t) in enumerate(zip(corridor["rgb"][:6], corridor["times"][:6]))]
    seen = []
    out = replay(GroundVO(corridor["K"], corridor["camera_height"], seed=0), enumerate(frames),
                 on_frame=lambda i, f, e, prev: seen.append((i, f["i"], None if prev is None else prev["i"])))
    vo = GroundVO(corridor["K"], corridor["camera_height"], seed=0)
    es = [vo.process(f["rgb"], f["t"]) for f in frames]
    np.testing.assert_array_equal(out["speed"], [e.speed for e in es])
    np.testing.assert_array_equal(out["rates_raw"], np.array([e.rates_raw for e in es]))
    np.testing.assert_array_equal(out["poses"], vo.trajectory())
    assert list(out["status"]) == [e.status for e in es] and out["cpu_ms"].shape == (6,)
    assert seen == [(i, i, i - 1 if i else None) for i in range(6)]


# A plug-in with only a pose: the missing fields are NaN, the poses are its per-image poses.
def test_replay_of_a_minimal_plugin():
    class StraightVO:
        def __init__(self):
            self.k = 0

        def process(self, rgb, t):
            P = np.eye(4)
            P[2, 3] = self.k
            self.k += 1
            return types.SimpleNamespace(pose=P)

    frames = [{"rgb": np.zeros((16, 16, 3), np.uint8), "t": 0.1 * i} for i in range(4)]
    out = replay(StraightVO(), frames)
    assert np.isnan(out["speed"]).all() and np.isnan(out["rates_raw"]).all()
    np.testing.assert_array_equal(out["poses"][:, 2, 3], [0, 1, 2, 3])
