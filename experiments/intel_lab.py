"""intel_lab: GPIS on the real Intel Research Lab log (Dirk Hähnel, 2003; GMapping-corrected poses)
(issue 14; dissertation Figs 7.12a and 7.19).

``polar_sim.datasets.load_intel_lab()``: 910 scans of 180 beams, poses corrected by GMapping. With
the ``mapper2d`` method (``gpis``):

- **update time** of every scan of the whole log, fused in order (process CPU time; Fig 7.12a);
- **the map** of the whole log: SDF, zero level and variance (Fig 7.19);
- **held-out self-consistency**: map 4 of every 5 scans, then |SDF| at the end points of the 5th;
- **scan-to-map odometry**: each scan registered by ICP-G to the map of the scans before it (at
  their estimated poses), from the previous estimate moved by the raw odometry, then fused;
  scored with ``metrics.relation_errors`` on the Freiburg benchmark relations of these scans
  (Kümmerle et al. 2009; the 90 of 2984 whose two scans are among the 910, matched by ``t_abs``),
  split into *local* relations (scans at most 5 apart in the log: the front end's accuracy) and
  *loop* relations (revisits of a place after a long excursion: the accumulated drift, which a
  SLAM system removes by closing the loop). It is **not** a SLAM result: no polar_sim method closes
  loops, and the figure is not comparable to the benchmark's tables, which score full SLAM systems on
  all 2984 relations of the full log. GMapping's poses and the raw odometry are scored beside it.

With the ``localizer2d`` method (``icpg``, ``icpd``, ``pf1000``, ``pf5000`` or a plug-in), built from
the 4-of-5 mapping scans: **relocalisation** of each held-out scan from its corrected pose perturbed
by 0.2 m (random direction) and 3 deg (random sign), three steps with no motion, scored against the
corrected pose (itself accurate to a few cm). The log was never used for tuning: seed 10,000 (the
perturbations) is the test split.
"""

from __future__ import annotations

import time

import numpy as np

from polar_sim.runner import Check, Experiment, Finding
from polar_sim.runner.report import markdown_table, savefig, write_csv_table

try:
    from polar_sim.experiments import _gpis_common as C
except ImportError:  # pragma: no cover
    import _gpis_common as C

MAP_COLS = ["mapper", "update_cpu_ms_median", "update_cpu_ms_p99", "heldout_abs_sdf_median_m", "heldout_abs_sdf_p90_m",
            "heldout_within_5cm"]
REL_COLS = ["trajectory", "all_trans_mean_m", "all_rot_mean_deg", "local_trans_mean_m", "local_rot_mean_deg",
            "loop_trans_mean_m", "loop_rot_mean_deg", "loop_trans_max_m"]
LOC_COLS = ["method", "seed", "reloc_median_m", "reloc_p90_m", "reloc_max_m", "reloc_head_median_deg", "reloc_fail",
            "reloc_cpu_ms_median", "loc_map_abs_sdf_median_m"]


def _odometry(m_factory, d, rel):
    """Scan-to-map odometry (see the module docstring) and its relation errors, with the raw odometry's
    and GMapping's on the same relations, over all, local and loop relations."""
    from polar_sim.metrics import relation_errors
    from polar_sim.runner.gpis_methods import scan_to_map_odometry

    est = scan_to_map_odometry(m_factory, d["angles"], d["ranges"], d["odom"], d["poses"][0])
    ta = d["t_abs"]
    ok = np.isin(rel[:, 0], ta) & np.isin(rel[:, 1], ta)
    pairs = np.column_stack([np.searchsorted(ta, rel[ok, 0]), np.searchsorted(ta, rel[ok, 1])])
    loop = np.abs(pairs[:, 1] - pairs[:, 0]) > 5      # a revisit: the two scans are far apart in time
    out = {}
    for name, P in (("s2m", np.asarray(est)), ("odom", d["odom"]), ("gmapping", d["poses"])):
        for part, sel in (("", slice(None)), ("_local", ~loop), ("_loop", loop)):
            if not np.any(np.ones(len(pairs), bool)[sel]):
                continue
            e = relation_errors(P, pairs[sel], rel[ok, 2:][sel])
            out.update({f"{name}{part}_trans_mean_m": e.trans_mean, f"{name}{part}_trans_max_m": e.trans_max,
                        f"{name}{part}_rot_mean_deg": e.rot_mean_deg, f"{name}{part}_rot_max_deg": e.rot_max_deg})
    out.update(n_loop_relations=int(loop.sum()))
    return {**out, "n_relations": int(ok.sum())}, np.asarray(est)


def trial(params, seed, ctx):
    from polar_sim.datasets import load_intel_lab
    from polar_sim.metrics.maps import hit_points

    d = load_intel_lab()
    A, P, R = d["angles"], d["poses"], d["ranges"]
    k = np.arange(len(P))
    used, held = k[k % 5 != 4], k[k % 5 == 4]
    held = held[::4] if ctx.quick else held
    mk = lambda: C.make("mapper2d", params["mapper"], seed=seed)  # noqa: E731
    full = mk()
    cpu = C.fuse(full, A, P, R)                                     # the whole log, in order
    m = mk()
    C.fuse(m, A, P[used], R[used])
    E = hit_points(A, P[held], R[held])
    a = np.abs(m.query(E)[0])
    row = {**C.cpu_stats(cpu), "heldout_abs_sdf_median_m": float(np.median(a)), "heldout_abs_sdf_p90_m": float(np.percentile(a, 90)),
           "heldout_within_5cm": float(np.mean(a < 0.05)), "heldout_endpoints": len(E)}
    od, est = _odometry(mk, d, d["benchmark_relations"])
    row.update(od)
    # relocalisation of the held-out scans with the localiser built from the mapping scans
    loc = C.make("localizer2d", params["method"], seed=seed, init_std=(0.2, 0.2, np.radians(3.0)))
    loc.fit(A, R[used], P[used])
    rng = np.random.default_rng(np.random.SeedSequence([seed, 1414]))
    err, lcpu = [], []
    for h in held:
        b = rng.uniform(-np.pi, np.pi)
        loc.reset(P[h] + np.array([0.2 * np.cos(b), 0.2 * np.sin(b), np.radians(3.0) * rng.choice([-1.0, 1.0])]))
        c0 = time.process_time()
        for _ in range(3):
            pose = loc.step(A, R[h], np.zeros(3))
        lcpu.append(1e3 * (time.process_time() - c0))
        err.append((np.hypot(*(pose[:2] - P[h, :2])), abs(np.degrees((pose[2] - P[h, 2] + np.pi) % (2 * np.pi) - np.pi))))
    e = np.asarray(err)
    lm = getattr(loc, "map_", None)
    row.update(reloc_median_m=float(np.median(e[:, 0])), reloc_p90_m=float(np.percentile(e[:, 0], 90)),
               reloc_max_m=float(e[:, 0].max()), reloc_head_median_deg=float(np.median(e[:, 1])),
               reloc_fail=int((e[:, 0] > 0.5).sum()), reloc_scans=len(held), reloc_cpu_ms_median=float(np.median(lcpu)),
               loc_map_abs_sdf_median_m=float(np.median(np.abs(lm.query(E)[0]))) if callable(getattr(lm, "query", None))
               else float("nan"), load=C.load_now())
    pic = C.map_picture(full, np.vstack([P[:, :2], hit_points(A, P[::10], R[::10])]), 0.2 if ctx.quick else 0.05)
    ctx.save_arrays(cpu_ms=cpu, reloc_err=e, s2m=est, path=P[:, :2], **pic)
    return row


def checks(table, ctx):
    g = [r for r in table if r["mapper"] == "gpis"]
    out = []
    if g:
        r = g[0]
        out += [Check("Intel Lab: held-out end points' median |SDF| <= 1.5 cm", r["heldout_abs_sdf_median_m"] <= 0.015,
                      f"{100 * r['heldout_abs_sdf_median_m']:.2f} cm over {r['heldout_endpoints']} end points", known_miss=True),
                Check("Intel Lab: median update <= 8 ms per scan (CPU time)", r["update_cpu_ms_median"] <= 8.0,
                      f"{r['update_cpu_ms_median']:.2f} ms", known_miss=True)]
    for r in [r for r in table if r["method"] == "icpg"][:1]:
        out += [Check("Intel Lab: ICP-G relocalisation median <= 3 cm against the corrected poses", r["reloc_median_m"] <= 0.03,
                      f"{100 * r['reloc_median_m']:.2f} cm over {r['reloc_scans']} held-out scans"),
                Check("Intel Lab: ICP-G relocalisation, no failure > 0.5 m", r["reloc_fail"] == 0,
                      f"{r['reloc_fail']} failures, worst {r['reloc_max_m']:.3f} m")]
    return out


def findings(table, ctx):
    g = [r for r in table if r["mapper"] == "gpis"]
    if not g:
        return []
    r = g[0]
    return [Finding("Ch. 7, Fig. 7.12a (Intel Lab)", "GPIS updates scan by scan in a few milliseconds on the Intel Research Lab log",
                    f"median {r['update_cpu_ms_median']:.2f} ms, p99 {r['update_cpu_ms_p99']:.2f} ms CPU per 180-beam scan",
                    "held" if r["update_cpu_ms_median"] <= 8.0 else "not held", "our machine and implementation; 910 corrected scans"),
            Finding("Ch. 7, Fig. 7.19 (Intel Lab)", "the GPIS map of the Intel Lab: a zero level on the walls, low variance where observed",
                    f"held-out end points lie {100 * r['heldout_abs_sdf_median_m']:.2f} cm (median) from the zero level",
                    "held" if r["heldout_abs_sdf_median_m"] <= 0.015 else "partly held",
                    "scored by self-consistency: a real log has no exact geometry")]


def summarize(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(table, key=lambda r: (r["mapper"], r["method"], r["seed"]))
    write_csv_table(rows, MAP_COLS + LOC_COLS + sorted(k for k in rows[0] if k.startswith(("s2m", "odom_", "gmapping"))),
                    ctx.out_dir / "intel_lab.csv")
    maps = [next(r for r in rows if r["mapper"] == k) for k in sorted({r["mapper"] for r in rows})]
    z = ctx.arrays(maps[0])
    fig, ax = plt.subplots(1, 3, figsize=(20, 6.2))
    ax[0].hist(z["cpu_ms"], bins=60, color="tab:blue")
    ax[0].set(xlabel="update CPU time per scan (ms)", ylabel="scans", title=f"{maps[0]['mapper']}: update time over the whole log (Fig 7.12a)")
    C.map_panel(ax[1], z, "SDF and zero level of the whole log (Fig 7.19)")
    im = ax[2].imshow(np.log10(np.maximum(z["var"], 1e-6)), origin="lower", cmap="magma",
                      extent=[z["xs"][0], z["xs"][-1], z["ys"][0], z["ys"][-1]])
    ax[2].set(title="log10 variance of the SDF", xlabel="x (m)", ylabel="y (m)", aspect="equal")
    fig.colorbar(im, ax=ax[2], shrink=0.7, label="log10 variance (m^2)")
    fig.suptitle("Intel Research Lab (real data, GMapping-corrected poses)")
    rel = [{"trajectory": f"{name} ({maps[0]['mapper']})" if name == "s2m" else name,
            **{f"{p or 'all'}_{k}": maps[0].get(f"{name}{'_' + p if p else ''}_{k}") for p in ("", "local", "loop")
               for k in ("trans_mean_m", "rot_mean_deg", "trans_max_m")}}
           for name in ("s2m", "odom", "gmapping")]
    return "\n".join([f"Mapping (per mapper; {ctx.split} split):", "", markdown_table(maps, MAP_COLS), "",
                      f"Relation errors (Kümmerle et al. 2009) on the {maps[0]['n_relations']} benchmark relations among "
                      f"these scans: {maps[0]['n_relations'] - maps[0]['n_loop_relations']} local (scans at most 5 apart), "
                      f"{maps[0]['n_loop_relations']} loop (a place revisited). `s2m`: scan-to-map odometry, ICP-G to the "
                      "map of the scans before, no loop closure; `odom`: raw wheel odometry; `gmapping`: the corrected poses "
                      "(GMapping is a SLAM system). The local figures measure a front end's accuracy; the loop figures its "
                      "drift, which only loop closure removes. Not comparable to the benchmark's SLAM tables.", "",
                      markdown_table(rel, REL_COLS), "",
                      "Relocalisation of held-out scans (0.2 m / 3 deg off, against the corrected poses):", "",
                      markdown_table(rows, LOC_COLS), "", "Table: `intel_lab.csv`.", "", savefig(fig, ctx.out_dir, "intel_lab")])


EXPERIMENT = Experiment(
    name="intel_lab",
    description="the real Intel Research Lab log: update times, map, held-out self-consistency, relocalisation, relations",
    grid={"mapper": ["gpis"], "method": ["icpg", "icpd", "pf1000", "pf5000"]},
    methods={"mapper": "mapper2d", "method": "localizer2d"},
    splits={"dev": {"seeds": [0]}, "test": {"seeds": [10_000]}},
    sizes={"quick": {"n_seeds": 1, "grid": {"method": ["icpg"]}}, "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
