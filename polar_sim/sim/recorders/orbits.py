"""Recorded RGB-D orbits of one object (``object_orbit``) and the exact truth to score 3D maps with.

- :func:`recorded_orbit` renders ``n_frames`` depth frames over one or more turns of the camera
  around the object, masks them to the object with the exact labels (as the published BigBird
  demo masks its depth) and adds Kinect-like :class:`~polar_sim.sim.sensors.DepthNoise`; the
  frames are cached through :mod:`polar_sim.sim.recorders.sequences` and replayed without MuJoCo.
- :class:`ObjectTruth` answers the geometry questions a score needs: evaluation points near the
  observed surface with their exact SDF, and the distances between a reconstructed mesh and the
  true mesh on the observed part. The statistics are :func:`polar_sim.metrics.object_map_scores`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["Orbit", "recorded_orbit", "ObjectTruth"]

_VERSION = 2                # 2: the key holds the orbit's phase, the object's pose and colours


@dataclasses.dataclass
class Orbit:
    """Masked depth frames of one object: per frame the noisy depth (inf off the object), K, the
    camera pose, and the noise-free back-projected object points (the observed true surface)."""

    name: str
    depths: list                # (H, W) float64 m, inf off the object
    Ks: list                    # (3, 3)
    poses: list                 # (4, 4) T_world_cam, OpenCV axes
    observed: np.ndarray        # (m, 3) noise-free object points seen by some pixel, world frame
    render_s: float             # wall time spent rendering (0 when replayed from the cache)


def _backproject(z, K, T):
    H, W = z.shape
    v, u = np.mgrid[0:H, 0:W]
    ok = np.isfinite(z)
    pc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], -1)[ok]
    return pc @ T[:3, :3].T + T[:3, 3]


def _capture(world, n_frames, seed, turns):
    import time

    from polar_sim.sim.recorders.recording import Recording
    from polar_sim.sim.sensors import DepthNoise
    from polar_sim.sim.truth import LABELS

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 5151]))
    noise = DepthNoise()
    period = float(world.meta.script.period)
    steps = max(1, int(round(turns * period / world.dt / n_frames)))
    rec = Recording(meta={"object": world.meta.target, "render_s": 0.0})
    t_render = 0.0
    for k in range(n_frames):
        if k:
            for _ in range(steps):
                world.step()
        t0 = time.perf_counter()
        f = world.camera("rgbd")
        t_render += time.perf_counter() - t0
        mask = f.labels == LABELS["target"]
        _, dn = noise.apply(f.rgb, f.depth, f.K[0, 0], rng)
        rec.append({"depth": np.where(mask, dn, np.inf).astype(np.float32),
                    "clean": np.where(mask, f.depth, np.inf).astype(np.float32), "K": f.K, "T": f.T_world_cam})
    rec.meta["render_s"] = t_render
    return rec


def recorded_orbit(world, n_frames, seed, *, turns=1.0):
    """The orbit of ``world`` (an ``object_orbit`` World): ``n_frames`` frames over ``turns``
    turns, depth noise seeded by ``seed``. Recorded once under ``$POLAR_SIM_CACHE/object_orbit``
    (keyed by the world's seed and options, ``n_frames``, ``seed``, ``turns``), then replayed.
    ``world`` must be as built (or reset); it is left where the capture left it (or untouched, when
    replayed)."""
    from polar_sim.sim.recorders import sequences

    if world.time != 0.0:
        raise ValueError(f"world: record an orbit from a freshly built or reset world (its time is {world.time:g} s)")
    sc, name = world.meta.script, world.meta.target
    # Everything that shapes the frames: the same seed with other options is another world (the
    # object, its yaw and colours and the orbit's phase all come from one seeded stream).
    key = {"scene": world.scene, "world_seed": int(world.seed), "object": name, "n_frames": int(n_frames),
           "seed": int(seed), "turns": float(turns), "colours": list(world.meta.colours.get(name, [])),
           "orbit": [float(sc.radius), float(sc.period), float(sc.phase0), float(sc.elevation)] + [float(c) for c in sc.centre],
           "object_pose": np.round(world.truth()["objects"][name], 12).ravel().tolist()}
    fresh = []

    def build():
        fresh.append(True)
        return _capture(world, int(n_frames), seed, turns)

    with sequences.cached("object_orbit", key, build, version=_VERSION) as r:
        depths, Ks, poses, obs = [], [], [], []
        for _, f in r.frames():
            depths.append(f["depth"].astype(np.float64))
            Ks.append(f["K"])
            poses.append(f["T"])
            obs.append(_backproject(f["clean"].astype(np.float64), f["K"], f["T"]))
        render_s = float(r.meta["render_s"]) if fresh else 0.0
    return Orbit(world.meta.target, depths, Ks, poses, np.vstack(obs), render_s)


class ObjectTruth:
    """Exact geometry of the orbited object, for scoring a 3D map of it.

    Parameters
    ----------
    world : the ``object_orbit`` World (its static scene holds the object, welded on its stand).
    orbit : :class:`Orbit` of that world.
    seen_tol : float, default 0.002
        A true surface point counts as observed when a noise-free object pixel lies within this
        distance of it, metres.
    """

    def __init__(self, world, orbit, *, seen_tol=0.002):
        from scipy.spatial import cKDTree

        self.world, self.orbit, self.seen_tol = world, orbit, float(seen_tol)
        name = orbit.name
        mesh = world.object_mesh(name)
        mesh.apply_transform(world.truth()["objects"][name])
        self.mesh = mesh                              # trimesh.Trimesh, world frame
        self._obs = cKDTree(orbit.observed)

    def eval_points(self, n, seed):
        """Points within 1 cm of the observed true surface: uniform mesh samples moved along the
        true normal by U(-1, 1) cm, kept where the mesh point was observed, the nearest static
        surface is the object itself and |SDF| < 1 cm. Returns ``{"P" (k, 3), "gt" (k,),
        "seen_fraction", "samples" (n, 3), "normals" (n, 3), "seen" (n,) bool}``."""
        import trimesh

        from polar_sim.sim.truth import LABELS

        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 6161]))
        pts, fi = trimesh.sample.sample_surface(self.mesh, int(n), seed=int(rng.integers(2**31)))
        nrm = self.mesh.face_normals[fi]
        seen = self._obs.query(pts)[0] <= self.seen_tol
        P = pts + rng.uniform(-0.01, 0.01, len(pts))[:, None] * nrm
        gt = self.world.sdf(P)
        own = self.world.nearest_surface(P) == LABELS["target"]
        sel = seen & own & (np.abs(gt) < 0.01)
        return {"P": P[sel], "gt": gt[sel], "seen_fraction": float(seen.mean()), "samples": pts,
                "normals": nrm, "seen": seen}

    def section_xz(self, y):
        """The true object's section by the vertical plane at ``y`` (m): (k, 2) points (x, z) of its
        loops, separated by NaN rows (empty when the plane misses it)."""
        sec = self.mesh.section(plane_origin=[0.0, float(y), 0.0], plane_normal=[0.0, 1.0, 0.0])
        loops = [np.asarray(p)[:, [0, 2]] for p in sec.discrete] if sec is not None else []
        return np.vstack([np.vstack([lp, [np.nan, np.nan]]) for lp in loops]) if loops else np.zeros((0, 2))

    def compare_mesh(self, vertices, faces, true_samples, *, n_dense=100_000):
        """Distances between a reconstructed mesh and the true mesh.

        Returns ``{"dist" (v,): exact distance of every vertex to the true mesh, "visible" (v,)
        bool: its nearest true point was observed, "true_normals" (v, 3): the true face normal
        there, "to_surface" (s,): distance from each observed true sample (``true_samples``) to
        the reconstruction (its vertices plus ``n_dense`` area-weighted samples of its faces)}``.
        """
        import trimesh
        from scipy.spatial import cKDTree

        V = np.asarray(vertices, float)
        S = trimesh.Trimesh(V, np.asarray(faces), process=False)
        cp, dist, tri = trimesh.proximity.closest_point(self.mesh, V)
        vis = self._obs.query(cp)[0] <= self.seen_tol
        dense = np.vstack([V, np.asarray(trimesh.sample.sample_surface(S, n_dense, seed=1)[0])])
        return {"dist": np.asarray(dist), "visible": vis, "true_normals": self.mesh.face_normals[tri],
                "to_surface": cKDTree(dense).query(true_samples)[0]}
