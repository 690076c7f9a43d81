"""ground_appearance: segmentation quality and calibration of P(ground) as the ground's appearance changes.

Every route crosses four ground zones (contiguous arcs of the closed route; the default look's
asphalt, gravel, grass and dirt, or four zones of one appearance family with their own colours, or of
random families). The VO (a ``vo`` plug-in with a ``ground_prob``) runs over the route; every frame
its P(ground) is scored against the true ground mask of the same image: IoU of P > 0.5 over the whole
image, and the reliability statistics (15 bins, every 2nd pixel) for the expected calibration error
(ECE). "Settled" frames are >= 5 s after the start and outside [-40 m, +10 m] of every zone boundary
(the new texture is visible on the far ground from 40 m before; zones meet along the edges of 20 m
ground tiles). Per family the settled frames of all its zones are pooled; the worst family is the
headline. Methods: ``w6``, ``u6``, ``w6_nocal`` (w6 without the calibration of P(ground), the 30 m
training limit and the evidence-weighted decay). Splits: ``dev`` four default-look routes plus one
route of each dev family; ``test`` the twelve held-out routes (seeds >= 10,000; stripes and checker
never used while tuning). Quick: the split's quick route cut to ``max_frames`` = 120 frames, w6.
"""

import numpy as np

from polar_sim.experiments import _ground_common as G
from polar_sim.experiments import _ground_pictures as pictures
from polar_sim.metrics.calibration import pooled_reliability
from polar_sim.runner import Check, Experiment, get_method
from polar_sim.runner.report import savefig

TARGET_IOU, TARGET_ECE = 0.85, 0.05
WARMUP_S, BEFORE_M, AFTER_M = 5.0, 40.0, 10.0
#: Families whose IoU miss, and splits whose pooled ECE miss, are recorded in RESULTS (full size, issue 35:
#: none since the sky labels; checker 0.859 on test, the dev-only periodic pavers 0.959 on dev).
RECORDED_IOU_MISSES, RECORDED_ECE_MISSES = (), ()
DEV_ROUTES = ("terrain_00", "terrain_04", "flat_00", "flat_02") + G.DEV_FAMILY_ROUTES
OURS = ("w6", "u6", "w6_nocal", "w6_ng6h")  # GroundVO methods: the routes are already at working size


def trial(params, seed, ctx):
    G.single_thread()
    from polar_sim.ground.replay import replay
    from polar_sim.metrics.calibration import reliability_counts
    from polar_sim.metrics.ground import class_prob_sums, classifier_iou, iou_summary
    from polar_sim.sim.recorders.rover_sequences import settled_frames

    rec, tr = G.load(params, ctx)
    t, n = tr["t"], len(rec)
    settled, z = settled_frames(rec, t, warmup_s=WARMUP_S, before_m=BEFORE_M, after_m=AFTER_M)
    pics = {}  # the middle settled frame of each zone
    for k, name in enumerate(G.family_names(rec)):
        idx = np.flatnonzero(settled & (z["zone"] == k))
        if len(idx) >= 10:
            pics[int(idx[len(idx) // 2])] = name
    iou, bins, psums, probs = np.full(n, np.nan), np.zeros((n, 3, 15)), np.zeros((n, 4)), {}

    def score(i, f, e, prev):
        iou[i] = classifier_iou(e.ground_prob, f["ground_mask"])
        bins[i] = reliability_counts(e.ground_prob[::2, ::2], f["ground_mask"][::2, ::2])
        psums[i] = class_prob_sums(e.ground_prob[::2, ::2], f["ground_mask"][::2, ::2])
        if i in pics:
            probs[i] = e.ground_prob.copy()

    m = params["method"]
    replay(get_method("vo", m)(tr["K"], tr["h"], seed=seed, **(G.rover_vo_params(tr) if m in OURS else {})),
           rec.frames(keys=("rgb", "t", "ground_mask")), on_frame=score)
    ctx.save_arrays("series", t=t, iou=iou, settled=settled, zone=z["zone"], progress=z["progress"],
                    boundaries=z["boundaries"], bins=bins, psums=psums, families=np.array(G.family_names(rec)))
    pictures.probability_maps(ctx.out_dir / "probability_maps.png", rec, probs, pics, iou)
    s = settled & np.isfinite(iou)
    ece = pooled_reliability(*bins[s].sum(axis=0)).ece if s.any() and bins[s][:, 0].sum() else float("nan")
    return {"route_used": G.route_of(params, ctx), "families": ",".join(sorted(set(G.family_names(rec)))), "frames": n,
            **iou_summary(iou, settled, (t - t[0]) >= WARMUP_S, TARGET_IOU), "ece_settled": ece}


def _families(table, ctx, method):
    """{family: pooled scores of its settled frames} (``polar_sim.metrics.ground.pool_by_family``)."""
    from polar_sim.metrics.ground import pool_by_family

    return pool_by_family(ctx.arrays(r, "series") for r in table if r["method"] == method)


def _family_rows(fams, m):
    """The per-family summary rows of one method, then its worst family and the pooled ECE."""
    rows = [dict(method=m, family=k, frames=f["frames"], iou_mean=f["iou_mean"], ece=pooled_reliability(*f["bins"]).ece,
                 p_ground=f["p_ground"], p_nonground=f["p_nonground"]) for k, f in fams.items()]
    if rows:
        wi, we = min(rows, key=lambda r: r["iou_mean"]), max(rows, key=lambda r: r["ece"])
        rows.append(dict(method=m, family=f"worst (IoU: {wi['family']}; ECE: {we['family']})", iou_mean=wi["iou_mean"],
                         ece=we["ece"]))
        rows.append(dict(method=m, family="all (pooled)", frames=sum(f["frames"] for f in fams.values()),
                         ece=pooled_reliability(*sum(f["bins"] for f in fams.values())).ece))
    return rows


def summarize(table, ctx):
    lines = [f"Split `{ctx.split}`, size `{ctx.size}`. Settled frames: ≥ {WARMUP_S:.0f} s after the start, outside "
             f"[−{BEFORE_M:.0f} m, +{AFTER_M:.0f} m] of each zone boundary. IoU: P(ground) > 0.5 against the true "
             "ground mask (whole image); ECE: 15 bins, every 2nd pixel of the settled frames. Per family (settled "
             "frames of all its zones pooled; `p_ground`/`p_nonground`: mean P(ground) on true ground / non-ground "
             "pixels, from the bins' mean confidence (±1/15) in runs that saved no per-class sums):", ""]
    rels = {}
    for m in sorted({r["method"] for r in table}):
        fams = _families(table, ctx, m)
        lines += [G.table(_family_rows(fams, m), ["method", "family", "frames", "iou_mean", "ece", "p_ground",
                                                   "p_nonground"]), ""]
        if fams:
            rels[m] = {k: pooled_reliability(*f["bins"]) for k, f in fams.items()}
    cols = ["route", "method", "families", "n_settled", "iou_settled_mean", "iou_settled_p10", "share_settled_ge_target",
            "ece_settled", "iou_transition_mean", "iou_all_mean"]
    why = {"iou_transition_mean": f"no frame within [−{BEFORE_M:.0f} m, +{AFTER_M:.0f} m] of a zone boundary after the "
                                  f"first {WARMUP_S:.0f} s"}
    lines += ["Per route:", "", G.table(sorted(table, key=lambda r: (r["route"], r["method"])), cols, why), ""]
    for m, rs in rels.items():
        fig = pictures.reliability_figure(rs, f"P(ground) reliability, {m}, {ctx.split} split (simulated routes, "
                                              "settled frames)")
        lines.append(savefig(fig, ctx.out_dir, f"reliability_{m}"))
    lines += ["", "Probability maps per trial: `trials/*/probability_maps.png`."]
    return "\n".join(lines)


def checks(table, ctx):
    fams = _families(table, ctx, "w6")
    if not fams:
        return []
    iou = {k: f["iou_mean"] for k, f in fams.items()}
    ece = {k: pooled_reliability(*f["bins"]).ece for k, f in fams.items()}
    worst, worst_ece = min(iou, key=iou.get), max(ece, key=ece.get)
    pooled = pooled_reliability(*sum(f["bins"] for f in fams.values())).ece
    missed = sorted(k for k, v in iou.items() if not v >= TARGET_IOU)
    n = f" ({len(fams)} famil{'ies' if len(fams) != 1 else 'y'} with settled frames)"
    return [Check(f"w6 settled IoU ≥ {TARGET_IOU} on every family ({ctx.split})", not missed,
                  f"worst {worst}: {iou[worst]:.3f}{n}" + (f"; below: {', '.join(missed)}" if missed else ""),
                  # a miss only on families recorded as missing it is known; any other family is a regression
                  known_miss=bool(missed) and set(missed) <= set(RECORDED_IOU_MISSES)),
            Check(f"w6 ECE of P(ground) ≤ {TARGET_ECE} ({ctx.split}, settled frames pooled)", pooled <= TARGET_ECE,
                  f"{pooled:.4f}{n}; worst family {worst_ece}: {ece[worst_ece]:.4f}",
                  known_miss=ctx.split in RECORDED_ECE_MISSES and ctx.size == "full")]


EXPERIMENT = Experiment(
    name="ground_appearance",
    description="ground segmentation IoU and calibration (ECE) of P(ground) per appearance family, as the ground "
                "changes along the routes",
    grid={"route": list(DEV_ROUTES), "method": ["w6", "u6", "w6_nocal"]},
    methods={"method": "vo"},
    splits={"dev": {"seeds": [0]}, "test": {"seeds": [10_000], "grid": {"route": list(G.TEST_ROUTES)}}},
    choices={"route": G.route_choices},
    params=dict(G.ROUTE_PARAMS),
    sizes={"quick": {"n_seeds": 1, "grid": {"route": ["quick"], "method": ["w6"]}, "params": dict(G.QUICK_PARAMS)},
           "full": {}},
    trial=trial, summarize=summarize, checks=checks,
)
