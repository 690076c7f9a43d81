"""GPISMap3D: online GPIS from depth images and 3D lidar (octree), spec §2.2-§9."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from polar_sim._validation import as_depth, as_int, as_intrinsics, as_pose, as_positive_float, as_ranges
from polar_sim.gpis._base import GPISMapBase
from polar_sim.gpis._checks import as_directions
from polar_sim.gpis.config import (DistanceConfig3D, LocalGPConfig3D, NoiseConfig3D,
                                   ObservationConfig3D, TreeConfig3D)
from polar_sim.gpis._fusion import fuse, normal_noise
from polar_sim.gpis._native import K
from polar_sim.gpis._linesearch import line_search
from polar_sim.gpis._obsgp import ObsGP2D
from polar_sim.params import Tags

__all__ = ["GPISMap3D", "MAX_OBS_SKIP"]

#: obs_skip's limit (pixels): beyond it an image gives one pixel.
MAX_OBS_SKIP = 1 << 20


class GPISMap3D(GPISMapBase):
    """Online Gaussian-process implicit surface in 3D (GPisMap3, octree).

    The configs' fields are in :mod:`polar_sim.gpis.config`; ``GPISMap3D.published()`` sets
    every stage's behaviour switch to the published C++'s (3D line search that re-projects the
    original point, inverted normal-fusion weight, unnormalised rotation axis, chain-only
    spacing, box retraining, the published query).

    Parameters
    ----------
    obs_skip : int, default=2
        Use every obs_skip-th pixel in each image direction (1 to 2**20).
    min_depth, max_depth : float, default=0.4, 4.0
        Valid depth (or lidar range) window, metres.
    observation : ObservationConfig3D
        Observation GP and occupancy test (spec §3-4).
    noise : NoiseConfig3D
        Sample noise and re-evaluation (spec §5-6).
    tree : TreeConfig3D
        Octree and sample spacing (spec §7; the default map spans at most 6.4 m).
    local_gp : LocalGPConfig3D
        Local GPs and their retraining (spec §8).
    distance : DistanceConfig3D
        Query and the faithful distance (spec §9).

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
    _STAGES = {"observation": ObservationConfig3D, "noise": NoiseConfig3D, "tree": TreeConfig3D,
               "local_gp": LocalGPConfig3D, "distance": DistanceConfig3D}

    def __init__(self, *, obs_skip=2, min_depth=0.4, max_depth=4.0, observation=ObservationConfig3D(),
                 noise=NoiseConfig3D(), tree=TreeConfig3D(), local_gp=LocalGPConfig3D(),
                 distance=DistanceConfig3D()):
        self.obs_skip = obs_skip
        self.min_depth = min_depth
        self.max_depth = max_depth
        self.observation = observation
        self.noise = noise
        self.tree = tree
        self.local_gp = local_gp
        self.distance = distance
        self._check_params()  # fail early; kept until a parameter is bound again (set_params)

    @property
    def _QUERY_W(self):
        return 3.0 * float(self.tree.cluster_half)

    def _check_sensor(self):
        out = {"obs_skip": as_int(self.obs_skip, "obs_skip", minimum=1, maximum=MAX_OBS_SKIP),
               "min_depth": as_positive_float(self.min_depth, "min_depth"),
               "max_depth": as_positive_float(self.max_depth, "max_depth")}
        if not out["min_depth"] < out["max_depth"]:
            raise ValueError(f"min_depth/max_depth: expected min_depth < max_depth, got "
                             f"{out['min_depth']} and {out['max_depth']}")
        return out

    def _free_res(self):
        free_res = self.distance.free_res
        return float(self.tree.cluster_half) if free_res is None else float(free_res)

    def _surfel_radius(self):
        r = self.distance.surfel_radius
        return self._spacing() / np.sqrt(3.0) if r is None else float(r)

    def _spacing(self):
        s = self.tree.sample_spacing
        return 0.01 if s is None else float(s)

    def _retrain_tol(self):
        tol = self.local_gp.retrain_tol
        return 0.0005 if tol is None else float(tol)

    def _blend_band(self):
        return float(self.distance.blend_near), float(self.distance.blend_far)

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
        obs = (var <= self.observation.obs_var_thre) & front
        with np.errstate(invalid="ignore", divide="ignore"):
            oc = np.tanh(15.0 * (1.0 - z * rho_hat))
            rhat = 1.0 / rho_hat
        return oc, obs, rhat

    def _fd(self, q, gp):
        dx = float(self.observation.delx)
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
        ok = var <= self.observation.obs_var_thre
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
            n[j], sp[j], sg[j] = normal_noise(g / self.observation.delx, oc.mean(1), s,
                                              np.linalg.norm(s, axis=1), self.noise.min_position_noise,
                                              self.noise.min_grad_noise, scan.R)
            bad[j] = ~fd_ok
        return scan.hits, ok, bad, n, sp, sg

    def _reeval(self, cand, scan):
        self._scan_sph = scan.spherical
        tr = self.tree_
        P, N = tr.pos[cand], tr.nrm[cand]
        p = (P - scan.t) @ scan.R
        n = N @ scan.R
        def search(p, n):
            return line_search(p, n, lambda q: self._oc(q, scan.gp), self.observation.delx, self._OC_SKIP,
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
