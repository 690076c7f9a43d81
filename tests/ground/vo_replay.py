"""Replay a recorded drive through a fresh ``GroundVO(K, camera_height)`` and save every output.

Used by ``test_determinism.py`` in the test process and, as a script, in fresh subprocesses:
``python vo_replay.py FRAMES.npz OUT.npz`` (FRAMES holds ``rgb`` (n, H, W, 3) uint8, ``t`` (n,), ``K``
(3, 3) and ``h``).
"""

import sys

import numpy as np


def replay(frames):
    """Per-frame outputs of a default-constructed GroundVO over ``frames`` (a dict of arrays)."""
    from polar_sim.ground import GroundVO

    vo = GroundVO(frames["K"], float(frames["h"]))
    keys = ("speed", "yaw_rate", "speed_raw", "yaw_rate_raw", "rates_raw", "pose", "ground_prob")
    out = {k: [] for k in keys}
    out["n_inliers"], out["candidates"] = [], []
    for rgb, t in zip(frames["rgb"], frames["t"]):
        e = vo.process(rgb, float(t))
        for k in keys:
            out[k].append(np.asarray(getattr(e, k)))
        out["n_inliers"].append(e.diagnostics["n_inliers"])
        out["candidates"].append(np.asarray(e.candidates).ravel())
    res = {k: np.stack(v) for k, v in out.items() if k != "candidates"}
    res["candidates"] = np.concatenate(out["candidates"])
    res["trajectory"] = vo.trajectory()
    return res


if __name__ == "__main__":
    with np.load(sys.argv[1], allow_pickle=False) as z:
        frames = {k: z[k] for k in z.files}
    np.savez(sys.argv[2], **replay(frames))
