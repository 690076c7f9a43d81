"""GPISMap2D: online GPIS from planar laser scans (quadtree), spec §2.1-§9."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from polar_sim._validation import as_angles, as_pose2d, as_ranges
from polar_sim.gpis._base import GPISMapBase
from polar_sim.gpis._checks import check_params
from polar_sim.gpis._fusion import RangeNoiseModel, fuse
from polar_sim.gpis._linesearch import TOL
from polar_sim.gpis._localgp import GRAD_GATE as _GRAD_GATE
from polar_sim.gpis._obsgp import ObsGP1D
from polar_sim.gpis._scan2d import line_search, new_samples, occupancy
from polar_sim.params import Tags

__all__ = ["GPISMap2D"]

# default-mode sample noise (RangeNoiseModel): the samples' position variances are measurement
# variances (floored at (3 mm)^2 so that fusion never claims more than the range noise supports);
# what the local GP cannot resolve (corners, the rounding of a 15 cm wall) is its own value-noise
# floor, (3.2 cm)^2; kappa is the normal-noise factor calibrated on exact normals
_VFLOOR = 1e-3      # m^2, value-noise floor of the local GPs ((3.2 cm)^2)
_FLOOR_P = 1e-5     # m^2, floor of the samples' (fused) position variances ((3 mm)^2)
_KAPPA = 0.5


class GPISMap2D(GPISMapBase):
    """Online Gaussian-process implicit surface in the plane (GPisMap, quadtree).

    Parameters
    ----------
    map_scale : float, default=1.2
        Matérn-3/2 length scale of the local GPs, metres; the query search half-width is 4x this.
    fbias : float, default=0.2
        Value target of every surface sample is -fbias; the published SDF is f + fbias.
    obs_var_thre : float, default=0.1
        Observation-GP variance above which a direction counts as unobservable.
    delx : float, default=0.01
        Finite-difference step and initial line-search step, metres.
    min_position_noise, min_grad_noise, map_noise : float, default=0.01
        Noise floors (variances) of the sample model (spec §1).
    sensor_offset : (2,) array_like, default=(0.0, 0.0)
        Laser position in the frame of the pose given to :meth:`update`, metres. The default
        takes the *sensor* pose, as the contract says (``World.lidar(...).T_world_sensor``).
        To feed robot *base* poses, give the laser's mounting here: the published demo's
        turtlebot (and the ``gazebo1`` log) use (0.08, 0), which is
        ``load_gazebo1()["sensor_offset"]``. ``legacy=True`` does not change it.
    angle_obs_limit : (2,) array_like, default=(-3/4 pi, 3/4 pi)
        Field of view of the laser, rad: beams outside are ignored and samples outside are not
        re-evaluated.
    min_range, max_range : float, default=0.2, 30.0
        Valid return window, metres.
    init_half, cluster_half, min_half, max_half : float, default=12.8, 0.8, 0.2, 102.4
        Quadtree root half-length, cluster-cell half-length, minimum sample spacing and root
        growth limit, metres.
    obs_scale, obs_noise : float, default=0.5, 0.01
        Observation GP (Ornstein-Uhlenbeck) length scale in rad and noise variance.
    blend_near, blend_far : float, default=0.05, 0.25
        Default mode: the query is the GPIS within ``blend_near`` of the nearest surfel, the
        surfel distance beyond ``blend_far``, and a smoothstep blend in between, metres. The
        GPIS weight is further scaled by ``clip(1 - var_f / 0.4, 0, 1)``: where the local GP is
        uninformative (no gradient observations) the surfel distance is used. (On office2d the
        GP's extrapolation past the end of a face, 0.1-0.4 m beyond a corner or into a door,
        is the larger error there; the surfel distance to the end of the face is exact.)
    surfel_radius : float or None, default=None
        Radius of the disc each sample stands for in the far-field distance; None = min_half / 2.
    free_res : float or None, default=None
        Cell size of the observed-free-space grid (sign and variance far away); None = 0.05 m.
        The grid sets the sign only beyond one cell diagonal of the nearest surfel; a coarser
        one leaves the shadow of every corner to the surfel's side, negative.
    retrain_tol : float or None, default=None
        Default mode: a re-evaluated sample triggers retraining of the GPs that use it only once
        it has moved more than this (or its normal turned > 0.05 rad, or a noise changed > 2x)
        since they were trained; None = 0.005 m; 0 = retrain on every change (as published).
    train_cap : int or None, default=32
        Default mode: each local GP trains on at most this many samples, the nearest its
        cluster's centre among those within the training radius (4 h_c = 3.2 m); None = all of
        them. The published retraining (``retrain="box"``) has no cap. Training costs O(m^3) in
        the m samples: in cluttered rooms (the Intel Lab: a median of 244, up to 450) the cap
        bounds the update time and memory. 32 was chosen on office2d's dev seeds, where it
        leaves every accuracy figure unchanged (benchmarks/RESULTS.md).
    sample_spacing : float or None, default=None
        Default mode: minimum distance between samples, enforced across cell borders (the
        published code checks only the cell chain, giving about half the intended spacing);
        None = min_half. It applies between samples of the same face only: a sample whose
        trusted normal (gradient noise within the GP gate 0.1001) points away from the new
        one's (dot < -0.5) is the other face of a thin wall and does not block it (the tree gets
        leaves of half-length min_half / 2 so that both faces fit).
    range_noise : float, default=0.01
        Default mode: standard deviation of the laser's range noise, metres. It sets the sample
        noise (spec §5/§6 replaced by ``_fusion.RangeNoiseModel``): position variance
        ``range_noise^2 cos^2(incidence)`` m^2 (re-evaluation adds the line-search residual and
        the between-beam term ``(r dtheta sin(incidence))^2``; fused values are floored at
        1e-5 m^2, and the local GPs add 1e-3 m^2 to every value noise) and normal variance
        ``(0.5 range_noise cos^2(incidence) / (r dtheta))^2`` rad^2 (``dtheta`` the beam spacing),
        so far and grazing returns keep their normals. Re-evaluation fuses only line searches
        that reached the observed surface within 3 sigma (at least 5 cm) with a normal facing the
        sensor, and drops samples whose doubled noises pass the drop gate. Returns without a
        trusted normal keep their position (value noise = position noise, not 2.0) with the
        normal facing the sensor. Legacy mode uses the spec's model (0.01 r^2 and the view-angle
        terms).
    spacing_rule : {"strict", "chain"}, default="strict"
        "strict": ``sample_spacing`` enforced across cell borders (in 2D only between samples of
        the same face); "chain": the published chain-only test (about half the spacing).
    retrain : {"changed", "box"}, default="changed"
        "changed": retrain exactly the clusters whose training set changed by more than
        ``retrain_tol``; "box": the published box around the active clusters, every change,
        with its |U| <= 1 carry-over (spec §8.1).
    gp_noise : {"model", "published"}, default="model"
        Value noise of the local GPs: the default model (samples without a gradient keep their
        position noise, plus a value floor) or the published one (2.0, no floor, the 2D
        x-gradient noise quirk).
    fusion : {"fixed", "published"}, default="fixed"
        Re-evaluation: the fixed line search and slerp normal fusion (weight
        sg_old / (sg_old + sg_new)), or the published ones (3D line search that re-projects the
        original point, inverted weight, unnormalised 3D rotation axis).
    query_mode : {"faithful", "published"}, default="faithful"
        "faithful": GPIS near surfaces blended into the surfel distance; "published": the
        published SDF ``f + fbias`` of the nearest clusters' GPs only (and ``surface()`` keeps
        the published variance cut).
    scan_model : {"range", "published"}, default="range"
        2D scans: the range-sigma noise model, the field of view applied to new samples and
        re-evaluation around the laser; or the published ones (spec noise model, limits for
        re-evaluation only, re-evaluation around the base).
    legacy : bool, default=False
        Shorthand for every behaviour parameter above at its published value: the published
        implementation, quirks and bugs included (spec [quirk]/[bug]); the query is then the
        published SDF f + fbias. ``GPISMap2D.published()`` is the same map built from those
        parameters (``PUBLISHED``) with ``legacy=False``. The published demo's laser offset is a
        parameter, not part of this switch: pass ``sensor_offset=(0.08, 0)`` with base poses.

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
    PUBLISHED = {**GPISMapBase.PUBLISHED, "scan_model": "published"}
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
    _PARAMS = ("map_scale", "fbias", "obs_var_thre", "delx", "min_position_noise",
               "min_grad_noise", "map_noise", "sensor_offset", "angle_obs_limit", "min_range",
               "max_range", "init_half", "cluster_half", "min_half", "max_half", "obs_scale",
               "obs_noise", "blend_near", "blend_far", "surfel_radius", "free_res", "retrain_tol", "train_cap", "sample_spacing", "range_noise", "spacing_rule", "retrain", "gp_noise", "fusion",
               "query_mode", "scan_model", "legacy")

    def __init__(self, *, map_scale=1.2, fbias=0.2, obs_var_thre=0.1, delx=0.01,
                 min_position_noise=0.01, min_grad_noise=0.01, map_noise=0.01,
                 sensor_offset=(0.0, 0.0), angle_obs_limit=(-2.35619449, 2.35619449),
                 min_range=0.2, max_range=30.0, init_half=12.8, cluster_half=0.8, min_half=0.2,
                 max_half=102.4, obs_scale=0.5, obs_noise=0.01, blend_near=0.05, blend_far=0.25,
                 surfel_radius=None, free_res=None, retrain_tol=None, train_cap=32, sample_spacing=None,
                 range_noise=0.01, spacing_rule="strict", retrain="changed", gp_noise="model",
                 fusion="fixed", query_mode="faithful", scan_model="range", legacy=False):
        self.map_scale = map_scale
        self.fbias = fbias
        self.obs_var_thre = obs_var_thre
        self.delx = delx
        self.min_position_noise = min_position_noise
        self.min_grad_noise = min_grad_noise
        self.map_noise = map_noise
        self.sensor_offset = sensor_offset
        self.angle_obs_limit = angle_obs_limit
        self.min_range = min_range
        self.max_range = max_range
        self.init_half = init_half
        self.cluster_half = cluster_half
        self.min_half = min_half
        self.max_half = max_half
        self.obs_scale = obs_scale
        self.obs_noise = obs_noise
        self.blend_near = blend_near
        self.blend_far = blend_far
        self.surfel_radius = surfel_radius
        self.free_res = free_res
        self.retrain_tol = retrain_tol
        self.train_cap = train_cap
        self.sample_spacing = sample_spacing
        self.range_noise = range_noise
        self.spacing_rule = spacing_rule
        self.retrain = retrain
        self.gp_noise = gp_noise
        self.fusion = fusion
        self.query_mode = query_mode
        self.scan_model = scan_model
        self.legacy = legacy

    def _checked_params(self):
        return check_params(self, vec2=("sensor_offset", "angle_obs_limit"))

    def _free_res(self):
        return 0.05 if self.free_res is None else float(self.free_res)

    def _surfel_radius(self):
        return 0.5 * self.min_half if self.surfel_radius is None else float(self.surfel_radius)

    def _spacing(self):
        return float(self.min_half) if self.sample_spacing is None else float(self.sample_spacing)

    def _retrain_tol(self):
        return 0.005 if self.retrain_tol is None else float(self.retrain_tol)

    def _blend_band(self):
        return float(self.blend_near), float(self.blend_far)

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
            dth = float(np.median(np.diff(phi))) if len(phi) > 1 else 1e-3
            model = RangeNoiseModel(p["range_noise"], max(dth, 1e-6), _FLOOR_P, kappa=_KAPPA)
        # re-evaluation searches around the base in the published code (spec §2.1); the default
        # searches around the laser, so that a sensor pose and a base pose with the mounting as
        # sensor_offset give the same map
        origin = t if pub else R @ o + t
        return SimpleNamespace(phi=phi, r=r, R=R, t=t, o=o, gp=gp, origin=origin, rmax=float(r.max()),
                               sensor_pts=sp, hits=hits, origin_sensor=R @ o + t, pose_name="pose2d",
                               lim=np.asarray(p["angle_obs_limit"], float), model=model)

    # -- sensor model ---------------------------------------------------------------------------
    def _oc(self, q, gp):
        """Occupancy test (spec §3) at sensor-frame points q (..., 2): (oc, observable, r_hat)."""
        return occupancy(gp, q, self.obs_var_thre)

    def _fd(self, q, gp):
        """Finite differences at sensor points q (n, 2): oc (n, 4), observable (n,), r_hat (n, 4)."""
        dx = float(self.delx)
        E = np.array([[dx, 0], [-dx, 0], [0, dx], [0, -dx]])
        oc, obs, rhat = self._oc(q[:, None, :] + E[None], gp)
        return oc, obs.all(1), rhat

    def _child_visible(self, cent, scan):
        p = (cent - scan.t) @ scan.R - scan.o
        b = np.arctan2(p[:, 1], p[:, 0])
        return (b > scan.lim[0]) & (b < scan.lim[1])

    def _new_samples(self, scan):
        ok, n, sp, sg, bad = new_samples(scan.gp, scan.sensor_pts, scan.phi, scan.r,
                                         self.obs_var_thre, self.delx, scan.R,
                                         self.min_position_noise, self.min_grad_noise,
                                         scan.model, _GRAD_GATE)
        return scan.hits, ok, bad, n, sp, sg

    def _reeval(self, cand, scan):
        tr = self.tree_
        P, N = tr.pos[cand], tr.nrm[cand]
        p = (P - scan.t) @ scan.R - scan.o
        n = N @ scan.R
        def search(p, n):
            return line_search(scan.gp, p, n, self.obs_var_thre, self.delx, TOL, self._OC_SKIP)

        return fuse(self, p, n, P, N, tr.sp[cand], tr.sg[cand], scan, search, self._fd, scan.R,
                    scan.R @ scan.o + scan.t, model=scan.model)
