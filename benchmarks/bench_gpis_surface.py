"""Evidence-gated ``GPISMap2D.surface()`` (issue 35, item 2) against the exact SDF, per seed and
per point class, with and without the gates.

    python benchmarks/bench_gpis_surface.py --split dev                      # office2d + warehouse2d, seeds 0-4
    python benchmarks/bench_gpis_surface.py --split dev --sweep              # the gate choices (dev only)
    python benchmarks/bench_gpis_surface.py --split test                     # held-out seeds 10,000-10,004
    python benchmarks/bench_gpis_surface.py --split test --reevaluation gated   # the default before issue 35

Each map is the ``gpis_accuracy`` drive (60 s, 1081-beam lidar at 10 Hz, sigma 1 cm, true poses),
built once and cached as a map file (``--cache``). Scores of the surface (points every 1 cm along
the returned polylines, inside the observed area of ``metrics.maps.ObservedArea``):

- ``max_err_m``, ``p99_err_m``, ``share_over_10cm``: |exact SDF| at the returned points (the
  directed distance from the claimed surface to the true one);
- ``hausdorff_claimed_m``: the larger of ``max_err_m`` and the distance from every *claimed* true
  surface point to the returned surface; a point of the observed true surface (a noise-free end
  point) is claimed when its nearest returned point lies within 10 cm, or within the 0.3 m band
  *beside* a polyline running along the point's face (the offset to the nearest returned point
  and the true face's tangent both within 45 deg of the polyline's normal and tangent, and the
  true outward normals at both within 45 deg: not the other face of a thin wall): a polyline
  beside the true surface counts, the stretches the map leaves out, past the ends of what it
  returns, do not (they are in ``coverage``);
- ``coverage``: share of the observed true surface points within 10 cm of a returned point
  (``coverage_wellseen``: of those hit by >= 10 scans), so that gating cannot win by returning
  nothing;
- per class of the returned points (projected on the true surface along the exact gradient):
  ``corner`` (within 0.3 m of a true corner), ``sparse`` (hit by < 10 scans), ``wellseen``;
- ``near_rmse_m``: the query's SDF RMSE near the surface (``map_scores_2d``; the gates do not touch
  the query, so it is the same with and without them).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))

import _gpis_common as C  # noqa: E402

from polar_sim.gpis import GPISMap2D, _surface  # noqa: E402
from polar_sim.gpis.config import REEVALUATIONS  # noqa: E402
from polar_sim.metrics.maps import ObservedArea, map_scores_2d, sdf_gradient  # noqa: E402
from polar_sim.sim.recorders.drives2d import recorded_drives, section_corners  # noqa: E402

SPLITS = {"dev": range(5), "test": range(10_000, 10_005)}
TOL, CORNER_R, WELL_K = 0.10, 0.3, 10
CLAIM_R = 0.3       # m: a true point beside a polyline's interior is claimed up to this far (the band)
#: The dev sweep: (name, surface() keywords).
SWEEP = [("off", {"evidence": False}), ("default", {})] + [
    (f"fd{fd}_end{e}", {"free_depth": fd, "face_end": e}) for fd in (0.05, 0.1) for e in (0.125, 0.15, 0.175, 0.2, 0.25)]


def build(scene, seed, cache, reevaluation=REEVALUATIONS[0]):
    """The map of the ``gpis_accuracy`` drive of (scene, seed), cached; and its drive."""
    d, = recorded_drives(scene, seed, [dict(route_seed=seed, every_steps=1, **C.ROUTE)])
    f = Path(cache) / f"{scene}_{seed}_{reevaluation}.npz"
    if f.exists():
        return GPISMap2D.load(f), d
    m = C.make("mapper2d", "gpis", seed=seed).set_params(noise__reevaluation=reevaluation)
    C.fuse(m, d.angles, d.poses, d.ranges)
    f.parent.mkdir(parents=True, exist_ok=True)
    m.save(f)
    return m, d


class Level:
    """A map's ungated zero level, sampled every 1 cm per segment and scored once against the truth;
    :meth:`scores` then scores any subset of its vertices (a gate setting) without re-tracing.
    ``surface()``'s gated lines are exactly the runs of >= 2 kept vertices of these lines (or a kept
    lone point), so a segment is kept when both of its vertices are."""

    def __init__(self, lines, sdf, obs, corners, spacing=0.01):
        pts, seg, v0, v1 = [], [], [], []
        base, nseg = 0, 0
        for ln in lines:
            if len(ln) == 1:
                segs = [(ln[0], ln[0], base, base)]
            else:
                segs = [(ln[i], ln[i + 1], base + i, base + i + 1) for i in range(len(ln) - 1)]
            for k, (a, b, i, j) in enumerate(segs):
                n = max(int(np.ceil(np.linalg.norm(b - a) / spacing)), 1)
                t = np.linspace(0, 1, n + 1)[:-1] if k < len(segs) - 1 else np.linspace(0, 1, n + 1)
                pts.append(a + t[:, None] * (b - a))
                seg.append(np.full(len(t), nseg))
                v0.append(i)
                v1.append(j)
                nseg += 1
            base += len(ln)
        self.n_vertices = base
        P = np.vstack(pts) if pts else np.zeros((0, 2))
        keep = obs.reached(P) if len(P) else np.zeros(0, bool)
        self.P, self.seg = P[keep], np.concatenate(seg)[keep] if seg else np.zeros(0, int)
        self.v0, self.v1 = np.array(v0, int), np.array(v1, int)
        self.err = np.abs(sdf(self.P))
        self.sdf = sdf
        tan = np.vstack([np.diff(ln, axis=0) if len(ln) > 1 else np.zeros((1, 2)) for ln in lines]) \
            if lines else np.zeros((0, 2))
        self.tan = tan / np.maximum(np.linalg.norm(tan, axis=1), 1e-12)[:, None]
        g = sdf_gradient(sdf, self.P)
        g /= np.maximum(np.linalg.norm(g, axis=1), 1e-9)[:, None]
        q = self.P - sdf(self.P)[:, None] * g
        self.normal = g
        dc = cKDTree(corners).query(q)[0] if len(corners) else np.full(len(q), np.inf)
        corner = dc < CORNER_R
        sparse = ~corner & (obs.count(q) < WELL_K)
        self.cls = {"corner": corner, "sparse": sparse, "wellseen": ~corner & ~sparse}
        self.hits = obs.hits
        well = obs.count(self.hits) >= WELL_K
        dch = cKDTree(corners).query(self.hits)[0] if len(corners) else np.full(len(self.hits), np.inf)
        self.hit_cls = {"all": np.ones(len(self.hits), bool), "wellseen_all": well, "corner": dch < CORNER_R,
                        "sparse": (dch >= CORNER_R) & ~well, "wellseen": (dch >= CORNER_R) & well}

    def scores(self, vertex_ok=None):
        """The scores of the module docstring for the kept vertices (all when None)."""
        ok = np.ones(self.n_vertices, bool) if vertex_ok is None else vertex_ok
        sk = ok[self.v0] & ok[self.v1]
        kp = sk[self.seg]
        P = self.P[kp]
        nan = float("nan")
        if not len(P):
            return {"max_err_m": nan, "hausdorff_claimed_m": nan, "coverage": 0.0, "coverage_wellseen": 0.0,
                    "n_points": 0}
        err = self.err[kp]
        dB, j = cKDTree(P).query(self.hits)
        beside = (dB > TOL) & (dB <= CLAIM_R)
        if beside.any():            # beside a polyline (not past its end), along the point's face
            h = self.hits[beside]
            n = sdf_gradient(self.sdf, h)
            n /= np.maximum(np.linalg.norm(n, axis=1), 1e-9)[:, None]
            t = self.tan[self.seg[kp][j[beside]]]
            u = (h - P[j[beside]]) / dB[beside][:, None]
            c45 = np.cos(np.radians(45.0))
            nP = self.normal[kp][j[beside]]         # the true face the polyline lies on, outward
            beside[beside] = ((np.abs(np.einsum("ij,ij->i", n, t)) < c45) & (np.abs(np.einsum("ij,ij->i", u, t)) < c45)
                              & (np.einsum("ij,ij->i", n, nP) > c45))
        claimed = beside | (dB <= TOL)
        out = {"max_err_m": float(err.max()), "p99_err_m": float(np.percentile(err, 99)),
               "share_over_10cm": float(np.mean(err > TOL)), "surface_rmse_m": float(np.sqrt(np.mean(err ** 2))),
               "hausdorff_claimed_m": float(max(err.max(), dB[claimed].max() if claimed.any() else 0.0)),
               "h_true_to_claimed_m": float(dB[claimed].max()) if claimed.any() else 0.0,
               "coverage": float(np.mean(dB <= TOL)), "coverage_wellseen": float(np.mean(dB[self.hit_cls["wellseen_all"]] <= TOL)),
               "n_points": int(len(P))}
        for name, mask in self.cls.items():
            m = mask[kp]
            out[f"{name}_max_err_m"] = float(err[m].max()) if m.any() else 0.0
            out[f"{name}_n"] = int(m.sum())
        for name in ("corner", "sparse", "wellseen"):
            m = self.hit_cls[name]
            out[f"{name}_coverage"] = float(np.mean(dB[m] <= TOL)) if m.any() else nan
        return out


def trial(scene, seed, cache, settings, near=True, reevaluation=REEVALUATIONS[0]):
    m, d = build(scene, seed, cache, reevaluation)
    w = C.truth_world(scene, seed)
    obs = ObservedArea(d.angles, d.poses, d.clean)
    corners = section_corners(w)
    rows = []
    raw = m.surface(evidence=False)
    level = Level(raw, w.sdf, obs, corners)
    verts = np.vstack(raw) if raw else np.zeros((0, 2))
    for name, kw in settings:
        t0 = time.process_time()
        if "evidence" in kw:             # the ungated level
            sc = level.scores()
        elif not sweep_only(kw):         # surface() itself, scored on its own polylines
            sc = Level(m.surface(**kw), w.sdf, obs, corners).scores()
        else:                            # the sweep: the same vertices, gated per setting
            g = _surface.gate_args(m, None, kw.get("free_depth"), kw.get("support_radius"), kw.get("min_support"),
                                   kw.get("gate_var"), False, kw.get("face_end"))
            g.pop("lone")               # the sweep scores the level's own vertices (no lone samples)
            if kw.get("free_depth", 0) is None:
                g["free_depth"] = None
            sc = level.scores(_surface.gate_2d(m, verts, **g)[0] == 0)
        rows.append({"scene": scene, "seed": seed, "gates": name, **sc, "score_cpu_s": time.process_time() - t0})
    if near:
        sc, _ = map_scores_2d(m.query, None, w.sdf, obs, corners, seed=seed)
        for r in rows:
            r.update(near_rmse_m=sc["near_rmse_m"], corner_rmse_m=sc.get("corner_rmse_m", float("nan")),
                     sparse_rmse_m=sc.get("sparse_rmse_m", float("nan")), wall_rmse_m=sc.get("wall_rmse_m", float("nan")))
    w.close()
    return rows


def sweep_only(kw):
    """A setting of the sweep (scored on the ungated level's vertices), not the default."""
    return bool(kw)


KEYS = ("max_err_m", "share_over_10cm", "hausdorff_claimed_m", "coverage", "coverage_wellseen", "corner_max_err_m",
        "sparse_max_err_m", "wellseen_max_err_m", "corner_coverage", "sparse_coverage", "wellseen_coverage",
        "near_rmse_m", "score_cpu_s")


def summary(rows):
    """Per (scene, gates): the mean and the worst over seeds of every key."""
    out = []
    for scene in sorted({r["scene"] for r in rows}):
        for g in dict.fromkeys(r["gates"] for r in rows):
            rs = [r for r in rows if r["scene"] == scene and r["gates"] == g]
            if not rs:
                continue
            s = {"scene": scene, "gates": g, "seeds": len(rs)}
            for k in KEYS:
                v = np.array([r.get(k, np.nan) for r in rs], float)
                s[k] = round(float(np.nanmean(v)), 4)
                s[k + "_worst"] = round(float(np.nanmax(v) if "coverage" not in k else np.nanmin(v)), 4)
            out.append(s)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=sorted(SPLITS), default="dev")
    ap.add_argument("--scenes", default=",".join(C.SCENES_2D))
    ap.add_argument("--seeds", default=None, help="comma-separated subset of the split's seeds")
    ap.add_argument("--sweep", action="store_true", help="score every gate setting of SWEEP (dev only)")
    ap.add_argument("--cache", default="polar_sim_out/bench_gpis_surface")
    ap.add_argument("--json", default=None, help="write the per-seed rows here")
    ap.add_argument("--reevaluation", choices=REEVALUATIONS, default=REEVALUATIONS[0],
                    help="the maps' NoiseConfig2D.reevaluation (default: the library's)")
    a = ap.parse_args(argv)
    if a.sweep and a.split != "dev":
        ap.error("--sweep: the gates are chosen on dev seeds only")
    seeds = list(SPLITS[a.split]) if a.seeds is None else [int(s) for s in a.seeds.split(",")]
    if any(s not in SPLITS[a.split] for s in seeds):
        ap.error(f"--seeds: not all in the {a.split} split")
    settings = SWEEP if a.sweep else SWEEP[:2]
    rows = []
    for scene in a.scenes.split(","):
        for seed in seeds:
            rows += trial(scene, seed, a.cache, settings, near=not a.sweep, reevaluation=a.reevaluation)
            print(json.dumps(rows[-1]), flush=True)
    print(f"# load {os.getloadavg()[0]:.1f}")
    for s in summary(rows):
        print(json.dumps(s))
    if a.json:
        Path(a.json).write_text(json.dumps({"split": a.split, "rows": rows, "summary": summary(rows)}, indent=1))


if __name__ == "__main__":
    main()
