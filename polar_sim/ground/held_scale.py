"""A monocular VO baseline with held scale (the VISO2-M analogue of the ground chapter's KITTI table).

The same estimator as :class:`polar_sim.ground.GroundVO` (front end, motion solve, filters,
integration), but without a ground model: the metric scale is the true speed of the first frame whose
motion is solved, and afterwards it is held through the tracked structure. Each frame's speed is the
median ratio of the measured scaled inverse depths d̄ = V/Z to the metric inverse depths propagated
from the previous frame, so the scale drifts as a monocular VO's does.
"""

from __future__ import annotations

import numpy as np

from polar_sim.ground.depth import fuse
from polar_sim.ground.vo import GroundVO

__all__ = ["HeldScaleVO"]


class HeldScaleVO(GroundVO):
    """``GroundVO`` with the ground-model scale replaced by scale held through the tracked structure.

    Parameters are those of :class:`GroundVO` plus ``speed_truth`` (n,): true speeds per image index,
    of which the baseline reads one, at the middle frame of the first image whose motion is solved
    (the only ground truth it sees: a monocular VO's scale has to come from somewhere).
    """

    def __init__(self, K, camera_height, *, speed_truth, **kw):
        self.speed_truth = speed_truth
        super().__init__(K, camera_height, **kw)

    @classmethod
    def _param_names(cls):
        return [*GroundVO._param_names(), "speed_truth"]

    def _motion_and_ground(self, fr, tri, t, labels):
        # Steps 8 and 10 of spec §1 as in GroundVO (same selection and motion solve); step 9 (ground
        # model) replaced by the held scale.
        solved = self._solve_motion(tri, t, fr.diag)
        if solved is None:
            fr.status = "few_triplets"
            return
        m, idx = solved[:2]
        c, trk = self.cfg_, self.tracks_
        vf, yf = self.speed_filter_, self.yaw_filter_
        fr.motion_done, fr.rates_raw, fr.yaw_raw = True, m.rates.copy(), float(m.rates[1])
        vi = np.flatnonzero(m.valid)
        ti = idx[vi]
        usable = trk["has"][ti] & (trk["P"][ti] < c.depth_usable) & (trk["d"][ti] > 0)
        vf.predict()
        yf.predict()
        if usable.sum() >= c.ground.min_inliers:
            # The frame's scale is its structure's: the median ratio of the measured d̄ to the propagated
            # metric inverse depths (no speed filter: filtering would re-anchor the depths to a lagging
            # speed every frame, so the scale would lag the truth instead of drifting).
            fr.speed_raw = float(np.median(m.dbar[vi][usable] / trk["d"][ti][usable]))
            vf.reset(fr.speed_raw, 1e-6)
            self.scale_held_ = True
        elif not getattr(self, "scale_held_", False):
            # Start-up, the only ground truth: the true speed of the first solved frame gives the metric
            # scale. (The rover starts from rest, and a static frame on the next images resets speed
            # and depths, so this repeats until the structure has carried the scale once.)
            vf.reset(float(self.speed_truth[self.n_frames_ - 1]), 1e-6)
        yf.update(fr.yaw_raw)
        self.rates_ = np.array([fr.rates_raw[0], yf.x, fr.rates_raw[2]])
        if vf.x > 0:
            d_m = m.dbar[vi] / vf.x
            d_f, P_f = fuse(trk["d"][ti], trk["P"][ti], d_m, usable, c.depth_r, c.depth_p_reset)
            trk["dmeas"][ti], trk["d"][ti], trk["P"][ti] = d_m, d_f, P_f
            trk["has"][ti] = True
        fr.diag["n_inliers"] = int(usable.sum())
        fr.status = "ok"
