"""GPISMap2D: online GPIS from planar laser scans (quadtree), spec §2.1-§9."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from polar_sim._validation import as_angles, as_pose2d, as_positive_float, as_ranges
from polar_sim.gpis._base import GPISMapBase
from polar_sim.gpis._checks import as_vector2
from polar_sim.gpis.config import (DistanceConfig2D, LocalGPConfig2D, NoiseConfig2D,
                                   ObservationConfig2D, TreeConfig2D)
from polar_sim.gpis._fusion import RangeNoiseModel, fuse
from polar_sim.gpis._linesearch import TOL
from polar_sim.gpis._localgp import GRAD_GATE as _GRAD_GATE
from polar_sim.gpis._obsgp import ObsGP1D
from polar_sim.gpis._scan2d import RUNS, face_runs, line_search, new_samples, occupancy, raw_support
from polar_sim.params import Tags

__all__ = ["GPISMap2D"]

# default-mode sample noise (RangeNoiseModel): the samples' position variances are measurement
# variances (floored at (3 mm)^2 so that fusion never claims more than the range noise supports);
# what the local GP cannot resolve (corners, the rounding of a 15 cm wall) is its own value-noise
# floor, (3.2 cm)^2; kappa is the normal-noise factor calibrated on exact normals
_VFLOOR = 1e-3      # m^2, value-noise floor of the local GPs ((3.2 cm)^2)
_FLOOR_P = 1e-5     # m^2, floor of the samples' (fused) position variances ((3 mm)^2)
_KAPPA = 0.5
# noise.reevaluation="on_returns": a re-evaluation's line search must end within this many range
# sigmas of the chords between the scan's own returns (``_scan2d.raw_support``), or the sample is
# left as it is: where the observation GP smooths across a corner or a range jump its zero level
# leaves the returns, and fusing it moved corner samples 3-12 cm into free space. Chosen on dev
# (office2d and warehouse2d seeds 0-1, and 2 sigma against 3 on seeds 0-4): re-measurements within
# 1 cm of the chords are 0.25-0.4 cm off the true surface on average, 2-3 cm away 2.4 cm, beyond
# 3 cm 3.5-4.6 cm
_SUPPORT = 2.0
# ... and the normal it fuses must lie within this angle (deg) of the normal of that chord
_CHORD_DEG = 45.0


def _median(x):
    """``float(np.median(x))`` of a non-empty finite 1D array, the same float, without
    ``np.median``'s overhead (it is called on every scan): the middle element, or the mean of
    the two middle ones computed as numpy's mean does, their sum over 2."""
    n = len(x)
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2.0)


class GPISMap2D(GPISMapBase):
    """Online Gaussian-process implicit surface in the plane (GPisMap, quadtree).

    The configs' fields are in :mod:`polar_sim.gpis.config`; ``GPISMap2D.published()`` sets
    every stage's behaviour switch to the published C++'s.

    Parameters
    ----------
    sensor_offset : (2,) array_like, default=(0.0, 0.0)
        Laser position in the frame of the pose given to :meth:`update`, metres. The default
        takes the *sensor* pose, as the contract says (``World.lidar(...).T_world_sensor``).
        To feed robot *base* poses, give the laser's mounting here: the published demo's
        turtlebot (and the ``gazebo1`` log) use (0.08, 0), which is
        ``load_gazebo1()["sensor_offset"]``. ``published()`` does not change it.
    angle_obs_limit : (2,) array_like, default=(-3/4 pi, 3/4 pi)
        Field of view of the laser, rad: beams outside are ignored and samples outside are not
        re-evaluated.
    min_range, max_range : float, default=0.2, 30.0
        Valid return window, metres.
    observation : ObservationConfig2D
        Observation GP and occupancy test (spec §3-4).
    noise : NoiseConfig2D
        Sample noise, the laser's range noise and re-evaluation (spec §5-6).
    tree : TreeConfig2D
        Quadtree and sample spacing (spec §7).
    local_gp : LocalGPConfig2D
        Local GPs and their retraining (spec §8; ``train_cap`` 32 by default).
    distance : DistanceConfig2D
        Query and the faithful distance (spec §9). In 2D the GPIS weight is further scaled by
        ``clip(1 - var_f / 0.4, 0, 1)``: where the local GP is uninformative (no gradient
        observations) the surfel distance is used.

    Attributes
    ----------
    tree_ : Tree
        Quadtree and surface samples.
    gps_ : GPStore
        Trained local GPs, by cluster.
    n_updates_ : int
        Number of scans fused (scans with fewer than 2 valid returns are not counted).
    """

    dim = 2
    TAGS = Tags(update="update", query="query", saves=True, data="polar_sim.gpis.synthetic:check_data_2d")
    _STAGES = {"observation": ObservationConfig2D, "noise": NoiseConfig2D, "tree": TreeConfig2D,
               "local_gp": LocalGPConfig2D, "distance": DistanceConfig2D}
    # the two faces of a wall thinner than the sample spacing (office walls are 15 cm) both
    # need samples: spacing is enforced only between samples whose normals agree (dot >= -0.5)
    _FACE_COS = -0.5
    # where the local GP is uninformative (var_f near the 0.4 query threshold: samples without a
    # gradient observation), its value has no zero level; the surfel distance takes over
    _VAR_BLEND = True
    # a surfel whose normal fails the GP's gradient gate does not override observed free space
    _SIGN_GATE = _GRAD_GATE
    # a sample without a trusted normal still has a trusted position (the range noise along its
    # ray): its value observation keeps its own position noise instead of the spec's 2.0
    _NOGRAD_NOISE = 0.0
    # the samples' position variances shrink with fusion (a well-seen sample resists being
    # dragged off an edge); the local GP adds its own model-error floor to every value noise
    _VALUE_FLOOR = _VFLOOR
    # the far-field sign where free space is silent: the implicit-MLS side of the nearest
    # surfels (width 0.5 x the 0.2 m spacing), not the closest disc's, which next to a corner is
    # often the adjacent face's
    _IMLS_WIDTH = 0.5
    # the GPIS interpolates across gaps between the samples of a face, which the discs of the
    # surfel distance leave (a wall seen at grazing incidence): the same band on both sides
    _BEHIND = 1.0

    def __init__(self, *, sensor_offset=(0.0, 0.0), angle_obs_limit=(-2.35619449, 2.35619449),
                 min_range=0.2, max_range=30.0, observation=ObservationConfig2D(),
                 noise=NoiseConfig2D(), tree=TreeConfig2D(), local_gp=LocalGPConfig2D(),
                 distance=DistanceConfig2D()):
        self.sensor_offset = sensor_offset
        self.angle_obs_limit = angle_obs_limit
        self.min_range = min_range
        self.max_range = max_range
        self.observation = observation
        self.noise = noise
        self.tree = tree
        self.local_gp = local_gp
        self.distance = distance
        self._check_params()  # fail early; kept until a parameter is bound again (set_params)

    def _check_sensor(self):
        out = {k: as_vector2(getattr(self, k), k) for k in ("sensor_offset", "angle_obs_limit")}
        if not out["angle_obs_limit"][0] < out["angle_obs_limit"][1]:
            raise ValueError("angle_obs_limit: expected (low, high) with low < high")
        out["min_range"] = as_positive_float(self.min_range, "min_range", allow_zero=True)
        out["max_range"] = as_positive_float(self.max_range, "max_range")
        if not out["min_range"] < out["max_range"]:
            raise ValueError(f"min_range/max_range: expected min_range < max_range, got "
                             f"{out['min_range']} and {out['max_range']}")
        return out

    def _free_res(self):
        free_res = self.distance.free_res
        return 0.05 if free_res is None else float(free_res)

    def _surfel_radius(self):
        r = self.distance.surfel_radius
        return 0.5 * self.tree.min_half if r is None else float(r)

    def _spacing(self):
        s = self.tree.sample_spacing
        return float(self.tree.min_half) if s is None else float(s)

    def _retrain_tol(self):
        tol = self.local_gp.retrain_tol
        return 0.005 if tol is None else float(tol)

    def _blend_band(self):
        return float(self.distance.blend_near), float(self.distance.blend_far)

    # -- input ----------------------------------------------------------------------------------
    def update(self, angles, ranges, pose2d):
        """Fuse one laser scan.

        Parameters
        ----------
        angles : array_like of shape (n,)
            Beam angles in the sensor frame, rad.
        ranges : array_like of shape (n,)
            Ranges, metres; NaN/inf (and values outside [min_range, max_range]) = no return.
        pose2d : array_like of shape (3,)
            Pose (x, y, theta) in the world, m and rad: the sensor's own pose with the default
            ``sensor_offset=(0, 0)``; otherwise the frame in which the laser sits at
            ``sensor_offset`` (a robot base).

        Returns
        -------
        self
        """
        angles = as_angles(angles, "angles")
        ranges = as_ranges(ranges, "ranges", n=len(angles))
        pose = as_pose2d(pose2d, "pose2d")
        p = self._checked_params()
        lim = np.asarray(p["angle_obs_limit"], float)
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(ranges) & (ranges > p["min_range"]) & (ranges < p["max_range"])
        pub = self._pub("scan_model")
        if not pub:                # the published code uses the limits for re-evaluation only
            valid &= (angles >= lim[0] - 1e-6) & (angles <= lim[1] + 1e-6)
        if valid.sum() < 2:
            return self
        phi, r = angles[valid], ranges[valid]
        if np.any(np.diff(phi) <= 0):
            order = np.argsort(phi, kind="stable")
            phi, r = phi[order], r[order]
        self._run_update(self._prepare(phi, r, pose, p, pub))
        return self

    def _prepare(self, phi, r, pose, p, pub):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        R = np.array([[c, -s], [s, c]])
        t = pose[:2].copy()
        o = np.asarray(p["sensor_offset"], float)
        gp = ObsGP1D(phi, r ** -0.5, scale=p["obs_scale"], noise=p["obs_noise"])
        sp = np.stack([r * np.cos(phi), r * np.sin(phi)], 1)
        hits = (sp + o) @ R.T + t
        model = None
        if not pub:
            dth = _median(np.diff(phi)) if len(phi) > 1 else 1e-3
            model = RangeNoiseModel(p["range_noise"], max(dth, 1e-6), _FLOOR_P, kappa=_KAPPA)
        # re-evaluation searches around the base in the published code (spec §2.1); the default
        # searches around the laser, so that a sensor pose and a base pose with the mounting as
        # sensor_offset give the same map
        origin = t if pub else R @ o + t
        return SimpleNamespace(phi=phi, r=r, R=R, t=t, o=o, gp=gp, origin=origin, rmax=float(r.max()),
                               sensor_pts=sp, hits=hits, origin_sensor=R @ o + t, pose_name="pose2d",
                               lim=np.asarray(p["angle_obs_limit"], float), model=model,
                               on_returns=model is not None and p["reevaluation"] == "on_returns")

    # -- sensor model ---------------------------------------------------------------------------
    def _oc(self, q, gp):
        """Occupancy test (spec §3) at sensor-frame points q (..., 2): (oc, observable, r_hat)."""
        return occupancy(gp, q, self.observation.obs_var_thre)

    def _fd(self, q, gp):
        """Finite differences at sensor points q (n, 2): oc (n, 4), observable (n,), r_hat (n, 4)."""
        dx = float(self.observation.delx)
        E = np.array([[dx, 0], [-dx, 0], [0, dx], [0, -dx]])
        oc, obs, rhat = self._oc(q[:, None, :] + E[None], gp)
        return oc, obs.all(1), rhat

    def _child_visible(self, cent, scan):
        p = (cent - scan.t) @ scan.R - scan.o
        b = np.arctan2(p[:, 1], p[:, 0])
        return (b > scan.lim[0]) & (b < scan.lim[1])

    def _new_samples(self, scan):
        ok, n, sp, sg, bad = new_samples(scan.gp, scan.sensor_pts, scan.phi, scan.r,
                                         self.observation.obs_var_thre, self.observation.delx, scan.R,
                                         self.noise.min_position_noise, self.noise.min_grad_noise,
                                         scan.model, _GRAD_GATE)
        return scan.hits, ok, bad, n, sp, sg

    def _observe_runs(self, scan, idx):
        # the surface gate's face end (``_surface.gate_2d``): how far past each sample its face
        # was seen to go on; the published scan model has no gates to feed
        if scan.model is None or not len(idx):
            return
        tr = self.tree_
        N = tr.nrm[idx] @ scan.R
        N /= np.maximum(np.linalg.norm(N, axis=1), 1e-12)[:, None]
        run = face_runs((tr.pos[idx] - scan.t) @ scan.R - scan.o, N, scan.phi, scan.r,
                        scan.model.dtheta, **RUNS)
        tr.run[idx] = np.maximum(tr.run[idx], run)

    def _singletons(self, scan):
        # a sample alone in its cluster (a wall's sample just across a cluster border) kept the
        # untrusted normal it was born with, and the surface gate left the wall around it out
        return scan.on_returns

    def _reeval(self, cand, scan):
        tr = self.tree_
        P, N = tr.pos[cand], tr.nrm[cand]
        p = (P - scan.t) @ scan.R - scan.o
        n = N @ scan.R
        tan = np.zeros((len(cand), 2))          # the returns' chord at each line search's end

        def search(p, n):
            live, q, A, rnew, found = line_search(scan.gp, p, n, self.observation.obs_var_thre,
                                                  self.observation.delx, TOL, self._OC_SKIP)
            if scan.on_returns:             # the level must lie on the scan's returns
                li = np.nonzero(live & found)[0]
                d, tan[li] = raw_support(q[li], scan.phi, scan.r, scan.model.dtheta)
                found[li] = d <= _SUPPORT * max(scan.model.sigma_r, np.sqrt(_FLOOR_P))
            return live, q, A, rnew, found

        out = fuse(self, p, n, P, N, tr.sp[cand], tr.sg[cand], scan, search, self._fd, scan.R,
                   scan.R @ scan.o + scan.t, model=scan.model, keep_position=scan.on_returns)
        if scan.on_returns:
            # the fused normal must be a normal of the returns' chord there: where the observation
            # GP smooths across a corner seen from afar, its normal is a blend of both faces that
            # the range model still calls certain (a room corner at 7 m: 69 deg off, sigma 0.13 rad)
            action, _, Nn = out[:3]
            t = tan @ scan.R.T                  # world frame
            chorded = np.any(t != 0.0, axis=1)
            off = np.abs(np.einsum("ij,ij->i", Nn, t)) > np.sin(np.radians(_CHORD_DEG))
            action[(action == 2) & chorded & off] = 0
        return out
