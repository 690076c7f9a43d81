"""GPISMap3D: online GPIS from depth images and 3D lidar (octree), spec §2.2-§9."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from polar_sim._validation import as_depth, as_intrinsics, as_pose, as_ranges
from polar_sim.gpis._base import GPISMapBase
from polar_sim.gpis._checks import as_directions, check_params
from polar_sim.gpis._fusion import fuse, normal_noise
from polar_sim.gpis._native import K
from polar_sim.gpis._linesearch import line_search
from polar_sim.gpis._obsgp import ObsGP2D
from polar_sim.params import Tags

__all__ = ["GPISMap3D"]


class GPISMap3D(GPISMapBase):
    """Online Gaussian-process implicit surface in 3D (GPisMap3, octree).

    Parameters
    ----------
    map_scale : float, default=0.04
        Matérn-3/2 length scale of the local GPs, metres.
    fbias : float, default=0.2
        Value target of every surface sample is -fbias; the published SDF is f + fbias.
    obs_var_thre : float, default=0.04
        Observation-GP variance above which a pixel direction counts as unobservable.
    delx : float, default=0.001
        Finite-difference step and initial line-search step, metres.
    min_position_noise : float, default=0.001
    min_grad_noise : float, default=0.01
    map_noise : float, default=0.005
        Noise floors (variances) of the sample model (spec §1).
    obs_skip : int, default=2
        Use every obs_skip-th pixel in each image direction.
    min_depth, max_depth : float, default=0.4, 4.0
        Valid depth (or lidar range) window, metres.
    init_half, cluster_half, min_half, max_half : float, default=0.4, 0.025, 0.00625, 1.6
        Octree root half-length, cluster-cell half-length, minimum sample spacing and root
        growth limit, metres (the map spans at most 6.4 m; raise these for room scale).
    obs_scale, obs_noise : float, default=0.5, 0.01
        Observation GP length scale (normalised image units / rad) and noise variance.
    blend_near, blend_far : float, default=0.002, 0.006
        Default mode: GPIS within blend_near of the nearest surfel, surfel distance beyond
        blend_far, smoothstep in between, metres.
    surfel_radius : float or None, default=None
        Disc radius of each sample in the far-field distance; None = the sample spacing / sqrt(3)
        (5.8 mm), so that the discs of a face sampled at that spacing leave no holes.
    free_res : float or None, default=None
        Cell size of the observed-free-space grid; None = cluster_half.
    retrain_tol : float or None, default=None
        Default mode: a re-evaluated sample triggers retraining of the GPs that use it only once
        it has moved more than this (or its normal turned > 0.05 rad, or a noise changed > 2x)
        since they were trained; None = 0.0005 m; 0 = retrain on every change (as published).
    train_cap : int or None, default=None
        Default mode: each local GP trains on at most this many samples, the nearest its
        cluster's centre among those within the training radius (4 h_c); None = all of them. The
        published retraining (``retrain="box"``) has no cap. Training costs O(m^3) in the m
        samples: the cap bounds the update time and memory where surfaces crowd a cluster.
    sample_spacing : float or None, default=None
        Default mode: minimum distance between samples, enforced across cell borders (the
        published code checks only the cell chain, giving about half the intended spacing);
        None = 0.01 m.
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
    legacy : bool, default=False
        Shorthand for every behaviour parameter above at its published value
        (``GPISMap3D.published()`` builds the same map from those parameters). Reproduce the published implementation (3D line search that re-projects the original
        point, inverted normal-fusion weight, unnormalised rotation axis, chain-only spacing).

    Attributes
    ----------
    tree_ : Tree
        Octree and surface samples.
    gps_ : GPStore
        Trained local GPs, by cluster.
    n_updates_ : int
        Number of frames fused.
    """

    dim = 3
    TAGS = Tags(update="update", query="query", saves=True, data="polar_sim.gpis.synthetic:check_data_3d")
    _T_BLEND = 0.5
    _OC_SKIP = -0.02
    _TRAIN_R = 2.0
    _UPDATE_R = 2.0
    _SURF_RES, _SURF_BAND, _SURF_VAR = 0.002, 0.01, 0.1
    # the far field's sign from the implicit-MLS surface of the nearest surfels (_distance), over
    # about one sample spacing: the closest disc alone gets the side wrong next to the edges of
    # a small box
    _IMLS_WIDTH = 1.0
    _PARAMS = ("map_scale", "fbias", "obs_var_thre", "delx", "min_position_noise",
               "min_grad_noise", "map_noise", "obs_skip", "min_depth", "max_depth", "init_half",
               "cluster_half", "min_half", "max_half", "obs_scale", "obs_noise", "blend_near",
               "blend_far", "surfel_radius", "free_res", "retrain_tol", "train_cap", "sample_spacing", "spacing_rule", "retrain",
               "gp_noise", "fusion", "query_mode", "legacy")

    def __init__(self, *, map_scale=0.04, fbias=0.2, obs_var_thre=0.04, delx=0.001,
                 min_position_noise=0.001, min_grad_noise=0.01, map_noise=0.005, obs_skip=2,
                 min_depth=0.4, max_depth=4.0, init_half=0.4, cluster_half=0.025,
                 min_half=0.00625, max_half=1.6, obs_scale=0.5, obs_noise=0.01,
                 blend_near=0.002, blend_far=0.006, surfel_radius=None, free_res=None,
                 retrain_tol=None, train_cap=None, sample_spacing=None, spacing_rule="strict", retrain="changed",
                 gp_noise="model", fusion="fixed", query_mode="faithful", legacy=False):
        self.map_scale = map_scale
        self.fbias = fbias
        self.obs_var_thre = obs_var_thre
        self.delx = delx
        self.min_position_noise = min_position_noise
        self.min_grad_noise = min_grad_noise
        self.map_noise = map_noise
        self.obs_skip = obs_skip
        self.min_depth = min_depth
        self.max_depth = max_depth
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
        self.spacing_rule = spacing_rule
        self.retrain = retrain
        self.gp_noise = gp_noise
        self.fusion = fusion
        self.query_mode = query_mode
        self.legacy = legacy

    @property
    def _QUERY_W(self):
        return 3.0 * float(self.cluster_half)

    def _checked_params(self):
        return check_params(self)

    def _free_res(self):
        return float(self.cluster_half) if self.free_res is None else float(self.free_res)

    def _surfel_radius(self):
        if self.surfel_radius is None:
            return self._spacing() / np.sqrt(3.0)
        return float(self.surfel_radius)

    def _spacing(self):
        return 0.01 if self.sample_spacing is None else float(self.sample_spacing)

    def _retrain_tol(self):
        return 0.0005 if self.retrain_tol is None else float(self.retrain_tol)

    def _blend_band(self):
        return float(self.blend_near), float(self.blend_far)

    # -- input ----------------------------------------------------------------------------------
    def update(self, depth, K, T_world_cam):
        """Fuse one depth image.

        Parameters
        ----------
        depth : ndarray of shape (H, W)
            Metric depth along the optical axis, metres; 0, NaN or inf = no return.
        K : array_like of shape (3, 3)
            Pinhole intrinsics (fx, fy > 0), pixels.
        T_world_cam : array_like of shape (4, 4)
            Camera-to-world pose, OpenCV camera axes (x right, y down, z forward).

        Returns
        -------
        self
        """
        depth = as_depth(depth, "depth")
        K = as_intrinsics(K, "K")
        T = as_pose(T_world_cam, "T_world_cam")
        p = self._checked_params()
        H, W = depth.shape
        s = p["obs_skip"]
        rows, cols = np.arange(0, H, s), np.arange(0, W, s)
        v = (rows - K[1, 2]) / K[1, 1]
        u = (cols - K[0, 2]) / K[0, 0]
        z = depth[np.ix_(rows, cols)]
        self._update_grid(v, u, z, T, p, spherical=False)
        return self

    def update_lidar(self, directions, ranges, T_world_sensor):
        """Fuse one 3D lidar sweep.

        Parameters
        ----------
        directions : array_like of shape (n, 3)
            Ray directions in the sensor frame (normalised here).
        ranges : array_like of shape (n,)
            Ranges along the rays, metres; NaN/inf = no return.
        T_world_sensor : array_like of shape (4, 4)
            Sensor-to-world pose.

        Notes
        -----
        The rays are binned on their (elevation, azimuth) grid, which plays the role of the
        image grid of a depth camera: the observation GP regresses 1/range on (elevation,
        azimuth), and "depth" in the noise model is the range.
        """
        ranges = as_ranges(ranges, "ranges")
        dirs = as_directions(directions, "directions", n=len(ranges))
        T = as_pose(T_world_sensor, "T_world_sensor")
        p = self._checked_params()
        el = np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0))
        az = np.arctan2(dirs[:, 1], dirs[:, 0])
        ev, ei = _axis(el)
        av, ai = _axis(az)
        z = np.full((len(ev), len(av)), np.nan)
        # later rays overwrite earlier ones in the same bin: deterministic
        z[ei, ai] = ranges
        self._update_grid(ev, av, z, T, p, spherical=True)
        return self

    def _update_grid(self, v, u, z, T, p, spherical):
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(z) & (z > p["min_depth"]) & (z < p["max_depth"])
        if valid.sum() < 2:
            return
        rho = np.where(valid, 1.0 / np.where(valid, z, 1.0), -1.0)
        gp = ObsGP2D(v, u, rho, scale=p["obs_scale"], noise=p["obs_noise"])
        # valid pixels in column-major order, row index fastest (spec §5)
        jj, ii = np.nonzero(valid.T)
        zz = z[ii, jj]
        if spherical:
            ce = np.cos(v[ii])
            sp = np.stack([ce * np.cos(u[jj]), ce * np.sin(u[jj]), np.sin(v[ii])], 1) * zz[:, None]
        else:
            sp = np.stack([u[jj] * zz, v[ii] * zz, zz], 1)
        R, t = T[:3, :3], T[:3, 3]
        hits = sp @ R.T + t
        scan = SimpleNamespace(gp=gp, R=R, t=t, origin=t, origin_sensor=t, rmax=float(zz.max()),
                               sensor_pts=sp, hits=hits, pix=(v[ii], u[jj]), r=zz,
                               win=(v[0], v[-1], u[0], u[-1]), spherical=spherical,
                               pose_name="T_world_sensor" if spherical else "T_world_cam")
        scan.free_hits = hits[:: -(-len(hits) // 4096)]      # at most ~4096 free-space rays
        self._run_update(scan)

    # -- sensor model ---------------------------------------------------------------------------
    def _proj(self, q, spherical):
        """(v, u, depth) of sensor-frame points q (..., 3)."""
        if spherical:
            r = np.linalg.norm(q, axis=-1)
            with np.errstate(invalid="ignore", divide="ignore"):
                v = np.arcsin(np.clip(q[..., 2] / r, -1, 1))
            return v, np.arctan2(q[..., 1], q[..., 0]), r
        z = q[..., 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            return q[..., 1] / z, q[..., 0] / z, z

    def _oc(self, q, gp, spherical=None):
        sph = self._scan_sph if spherical is None else spherical
        v, u, z = self._proj(q, sph)
        front = z > 0
        v = np.where(front, v, np.nan)
        rho_hat, var = gp.predict(v.ravel(), np.where(front, u, np.nan).ravel())
        rho_hat, var = rho_hat.reshape(z.shape), var.reshape(z.shape)
        obs = (var <= self.obs_var_thre) & front
        with np.errstate(invalid="ignore", divide="ignore"):
            oc = np.tanh(15.0 * (1.0 - z * rho_hat))
            rhat = 1.0 / rho_hat
        return oc, obs, rhat

    def _fd(self, q, gp):
        dx = float(self.delx)
        E = np.array([[dx, 0, 0], [-dx, 0, 0], [0, dx, 0], [0, -dx, 0], [0, 0, dx], [0, 0, -dx]])
        oc, obs, rhat = self._oc(q[:, None, :] + E[None], gp)
        return oc, obs.all(1), rhat

    def _child_visible(self, cent, scan):
        p = (cent - scan.t) @ scan.R
        v, u, z = self._proj(p, scan.spherical)
        v0, v1, u0, u1 = scan.win
        with np.errstate(invalid="ignore"):
            return (z > 0) & (u > u0) & (u < u1) & (v > v0) & (v < v1)

    def _new_samples(self, scan):
        self._scan_sph = scan.spherical
        tr = self.tree_
        _, var = scan.gp.predict(*scan.pix)
        ok = var <= self.obs_var_thre
        # finite differences only where an insert can succeed (see maybe_new)
        ok &= K.maybe_new(scan.hits, tr.geo, tr.root, tr.level_off, tr.cgrid, tr.gshape, tr.goff,
                        tr.node_sample, tr.node_internal, tr.pos, tr.strict)
        k = len(ok)
        n, sp, sg = np.zeros((k, 3)), np.zeros(k), np.zeros(k)
        bad = np.zeros(k, bool)
        j = np.nonzero(ok)[0]
        if len(j):
            s = scan.sensor_pts[j]
            oc, fd_ok, _ = self._fd(s, scan.gp)
            g = np.stack([oc[:, 0] - oc[:, 1], oc[:, 2] - oc[:, 3], oc[:, 4] - oc[:, 5]], 1)
            n[j], sp[j], sg[j] = normal_noise(g / self.delx, oc.mean(1), s,
                                              np.linalg.norm(s, axis=1), self.min_position_noise,
                                              self.min_grad_noise, scan.R)
            bad[j] = ~fd_ok
        return scan.hits, ok, bad, n, sp, sg

    def _reeval(self, cand, scan):
        self._scan_sph = scan.spherical
        tr = self.tree_
        P, N = tr.pos[cand], tr.nrm[cand]
        p = (P - scan.t) @ scan.R
        n = N @ scan.R
        def search(p, n):
            return line_search(p, n, lambda q: self._oc(q, scan.gp), self.delx, self._OC_SKIP,
                               depth=True, reproject_bug=self._pub("fusion"))

        return fuse(self, p, n, P, N, tr.sp[cand], tr.sg[cand], scan, search, self._fd, scan.R,
                    scan.t)


def _axis(a, tol=1e-4):
    """Sorted grid values of angles a (n,) and each angle's index; bins of width tol merge."""
    order = np.argsort(a, kind="stable")
    sa = a[order]
    new = np.concatenate([[True], np.diff(sa) > tol])
    grp = np.cumsum(new) - 1
    vals = sa[new]
    idx = np.empty(len(a), np.int64)
    idx[order] = grp
    return vals, idx
