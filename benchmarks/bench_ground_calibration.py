"""Dev-only sweep of the P(ground) calibration settings (issue 13, item 3; the held-out protocol).

The calibration (``polar_sim.ground.calibration.PlattCalibrator`` inside ``GroundVO``) has three
settings (GroundVO's ``calibration=CalibrationConfig(window, decay, prior_weight)``): the log-odds
window, and the calibrator's per-update decay and prior weight (0.85 and 50 when this sweep was run,
0.99 and 5 since, the sweep's best). The calibration does not feed back into the
VO (RANSAC weights its draws by the uncalibrated posterior), so one replay per route and window
drives every (decay, prior_weight) pair at once: the VO's calibrator is replaced after the first
image by a fan-out that updates one calibrator per pair with the same self-labels and returns the
default's map; after each image every calibrator maps the image's score to its own P(ground).

Scored against the true ground mask on the settled frames of ``dev`` routes only (>= 5 s after the
start, outside [-40 m, +10 m] of every zone boundary, as ``ground_appearance``): IoU of P > 0.5 and
ECE (15 bins, every 2nd pixel), per route and pooled. No test route is ever loaded.

Usage: python benchmarks/bench_ground_calibration.py [--frames 300] [--routes dev_speckle,...] [--json FILE]
"""

import argparse
import itertools
import json
import time

import numpy as np

WINDOWS = (1, 3, 7, 15)
DECAYS = (0.5, 0.7, 0.85, 0.95, 0.99)
PRIORS = (5.0, 20.0, 50.0, 200.0, 1000.0)
DEFAULT = (7, 0.85, 50.0)  # the GroundVO default when the sweep was run (the fan-out's primary)
ROUTES = ("dev_speckle", "dev_gravel", "dev_grass", "dev_blotches", "terrain_00")
WARMUP_S, BEFORE_M, AFTER_M = 5.0, 40.0, 10.0


class FanOut:
    """Calibrators updated together; ``transform`` is the one at index ``primary``."""

    def __init__(self, cals, primary):
        self.cals, self.primary = cals, primary

    def update(self, z, y):
        for c in self.cals:
            c.update(z, y)
        return self

    def transform(self, z):
        return self.cals[self.primary].transform(z)


def w6_dev_best(K, camera_height, *, seed=0, **params):
    """A ``vo`` plug-in: w6 with the calibration settings this sweep found best on dev (window 7, decay
    0.99, prior weight 5), for ``polar-sim run ground_appearance --set
    method=[benchmarks.bench_ground_calibration:w6_dev_best]`` (run from the repository root)."""
    from polar_sim.ground import CalibrationConfig, GroundVO

    params.setdefault("downsample", 1)
    return GroundVO(K, camera_height, model="6param", sampling="weighted", seed=seed,
                    calibration=CalibrationConfig(window=7, decay=0.99, prior_weight=5.0), **params)


def sweep_route(name, frames):
    import cv2

    from polar_sim.ground import CalibrationConfig, GroundVO
    from polar_sim.ground.calibration import PlattCalibrator
    from polar_sim.metrics.calibration import reliability_counts
    from polar_sim.metrics.ground import class_prob_sums, classifier_iou
    from polar_sim.sim.recorders.rover_sequences import SPLITS, load_route, route_truth, route_zones

    if name not in SPLITS["dev"]:
        raise ValueError(f"routes: {name!r} is not a dev route (the sweep never loads test routes)")
    cv2.setNumThreads(1)
    rec = load_route(name, max_frames=frames)  # the first ``frames`` images (recorded as such, once)
    tr, z = route_truth(rec), route_zones(rec, BEFORE_M)
    t, prog = tr["t"], z["progress"]
    settled = (t - t[0]) >= WARMUP_S
    for b in z["boundaries"]:
        settled &= ~((prog >= b - BEFORE_M) & (prog <= b + AFTER_M))
    n = len(rec)
    pairs = list(itertools.product(DECAYS, PRIORS))
    out = {}
    for win in WINDOWS:
        vo = GroundVO(tr["K"], tr["h"], downsample=1, seed=0, calibration=CalibrationConfig(window=win))
        bins, psums = np.zeros((len(pairs), 3, 15)), np.zeros((len(pairs), 4))
        iou = [[] for _ in pairs]
        for i, f in rec.frames(stop=n, keys=("rgb", "t", "ground_mask")):
            e = vo.process(f["rgb"], f["t"])
            if i == 0:
                vo.calibrator_ = FanOut([PlattCalibrator(decay=d, prior_weight=p) for d, p in pairs],
                                        pairs.index(DEFAULT[1:]))
            if not settled[i] or vo.prev_score_ is None:
                continue
            gm = f["ground_mask"]
            for j, c in enumerate(vo.calibrator_.cals):
                p = c.transform(vo.prev_score_)
                if j == vo.calibrator_.primary:  # the fan-out reproduces the module's own output
                    assert np.array_equal(p, e.ground_prob)
                iou[j].append(classifier_iou(p, gm))
                bins[j] += reliability_counts(p[::2, ::2], gm[::2, ::2])
                psums[j] += class_prob_sums(p[::2, ::2], gm[::2, ::2])
        for j, (d, p) in enumerate(pairs):
            out[(win, d, p)] = (bins[j], np.asarray(iou[j]), psums[j])
    return out


def main():
    from polar_sim.metrics.calibration import pooled_reliability

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300, help="first frames of each route (default 300)")
    ap.add_argument("--routes", default=",".join(ROUTES))
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    routes = a.routes.split(",")
    t0 = time.time()
    per = {r: sweep_route(r, a.frames) for r in routes}
    rows = []
    for key in per[routes[0]]:
        b = sum(per[r][key][0] for r in routes)
        ious = np.concatenate([per[r][key][1] for r in routes])
        rr = {r: pooled_reliability(*per[r][key][0]).ece for r in routes}
        ps = sum(per[r][key][2] for r in routes)
        rows.append(dict(window=key[0], decay=key[1], prior_weight=key[2], ece_pooled=pooled_reliability(*b).ece,
                         ece_worst_route=max(rr.values()), iou_mean=float(np.mean(ious)),
                         iou_worst_route=min(float(np.mean(per[r][key][1])) for r in routes),
                         frames=int(len(ious)), p_ground=ps[0] / ps[1], p_nonground=ps[2] / ps[3], **{f"ece_{r}": v for r, v in rr.items()}))
    rows.sort(key=lambda r: r["ece_pooled"])
    print(f"dev routes {routes}, first {a.frames} frames, settled frames; {time.time() - t0:.0f} s")
    print("| window | decay | prior weight | ECE pooled | ECE worst route | IoU mean | IoU worst route | mean P ground / non-ground |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        mark = " **(default)**" if (r["window"], r["decay"], r["prior_weight"]) == DEFAULT else ""
        print(f"| {r['window']} | {r['decay']} | {r['prior_weight']:g}{mark} | {r['ece_pooled']:.4f} | "
              f"{r['ece_worst_route']:.4f} | {r['iou_mean']:.3f} | {r['iou_worst_route']:.3f} | "
              f"{r['p_ground']:.3f} / {r['p_nonground']:.3f} |")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"routes": routes, "frames": a.frames, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
