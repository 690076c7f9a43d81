"""intel_lab: GPIS on the real Intel Research Lab log (Dirk Hähnel, 2003; GMapping-corrected poses)
(dissertation Figs 7.12a and 7.19).

``polar_sim.datasets.load_intel_lab()``: 910 scans of 180 beams, poses corrected by GMapping. With
the ``mapper2d`` method (``gpis``):

- **update time** of every scan of the whole log, fused in order (process CPU time; Fig 7.12a);
- **the map** of the whole log: SDF, zero level and variance (Fig 7.19);
- **held-out self-consistency**: map 4 of every 5 scans, then |SDF| at the end points of the 5th
  (every ``held_out_stride``-th of these held-out scans: all at full size, every 4th quick);
- **scan-to-map odometry**: each scan registered by ICP-G to the map of the scans before it, from
  the previous estimate moved by the raw odometry, then fused; scored (``metrics.relation_scores``)
  on the Freiburg benchmark relations among these scans (Kümmerle et al. 2009; 90 of 2984, matched by
  ``t_abs``): *local* ones (scans <= 5 apart: the front end's accuracy) and *loop* ones (a place
  revisited: the drift a SLAM system removes by closing the loop). **Not** a SLAM result (no polar_sim
  method closes loops; not comparable to the benchmark's tables). Raw odometry and GMapping beside it.

With the ``localizer2d`` method (``icpg``, ``icpd``, ``pf1000``, ``pf5000`` or a plug-in), built from
the 4-of-5 mapping scans: **relocalisation** of each held-out scan from its corrected pose perturbed
by 0.2 m (random direction) and 3 deg (random sign), three steps with no motion, scored against the
corrected pose (itself accurate to a few cm). The log was never used for tuning: seed 10,000 (the
perturbations) is the test split.
"""

from __future__ import annotations

import numpy as np

from polar_sim.runner import Check, Experiment, Finding
from polar_sim.metrics import relation_scores
from polar_sim.runner.localise import relocalise
from polar_sim.runner.pictures2d import map_figure
from polar_sim.runner.report import duration, length, markdown_table, savefig, write_csv_table

from polar_sim.experiments import _gpis_common as C

MAP_COLS = ["mapper", "update_cpu_ms_median", "update_cpu_ms_p99", "heldout_abs_sdf_median_m", "heldout_abs_sdf_p90_m",
            "heldout_within_5cm"]
REL_COLS = ["trajectory", "all_trans_mean_m", "all_rot_mean_deg", "local_trans_mean_m", "local_rot_mean_deg",
            "loop_trans_mean_m", "loop_rot_mean_deg", "loop_trans_max_m"]
LOC_COLS = ["method", "seed", "reloc_median_m", "reloc_p90_m", "reloc_max_m", "reloc_head_median_deg", "reloc_fail",
            "reloc_cpu_ms_median", "loc_map_abs_sdf_median_m"]


def trial(params, seed, ctx):
    from polar_sim.datasets import load_intel_lab
    from polar_sim.metrics.maps import hit_points
    from polar_sim.runner.gpis_methods import scan_to_map_odometry

    d = load_intel_lab()
    A, P, R = d["angles"], d["poses"], d["ranges"]
    k = np.arange(len(P))
    used, held = k[k % 5 != 4], k[k % 5 == 4]
    held, mk = held[:: ctx.params["held_out_stride"]], lambda: C.make("mapper2d", params["mapper"], seed=seed)  # noqa: E731
    full = mk()
    cpu = C.fuse(full, A, P, R)                                     # the whole log, in order
    m = mk()
    C.fuse(m, A, P[used], R[used])
    E = hit_points(A, P[held], R[held])
    a = np.abs(m.query(E)[0])
    row = {**C.cpu_stats(cpu), "heldout_abs_sdf_median_m": float(np.median(a)), "heldout_abs_sdf_p90_m": float(np.percentile(a, 90)),
           "heldout_within_5cm": float(np.mean(a < 0.05)), "heldout_endpoints": len(E)}
    est = scan_to_map_odometry(mk, A, R, d["odom"], P[0])
    row.update(relation_scores({"s2m": est, "odom": d["odom"], "gmapping": P}, d["t_abs"], d["benchmark_relations"]))
    # relocalisation of the held-out scans with the localiser built from the mapping scans
    loc = C.make("localizer2d", params["method"], seed=seed, init_std=(0.2, 0.2, np.radians(3.0)))
    loc.fit(A, R[used], P[used])
    e, lcpu = relocalise(loc, A, R[held], P[held], np.random.default_rng(np.random.SeedSequence([seed, 1414])))
    lm = getattr(loc, "map_", None)
    lsdf = float(np.median(np.abs(lm.query(E)[0]))) if callable(getattr(lm, "query", None)) else float("nan")
    row.update(**C.reloc_scores(e, lcpu), loc_map_abs_sdf_median_m=lsdf, load=C.load_now())
    pic = C.map_picture(full, np.vstack([P[:, :2], hit_points(A, P[::10], R[::10])]), ctx.params["picture_res_m"])
    ctx.save_arrays(cpu_ms=cpu, reloc_err=e, s2m=est, path=P[:, :2], **pic)
    return row


def _mapping(table, mapper="gpis"):
    """The mapping figures of ``mapper``: every trial re-measures them; the median over the trials."""
    rows = [r for r in table if r["mapper"] == mapper]
    return {k: float(np.median([r[k] for r in rows])) for k in ("update_cpu_ms_median", "update_cpu_ms_p99",
                                                              "heldout_abs_sdf_median_m", "heldout_endpoints")} if rows else None


def checks(table, ctx):
    r, out = _mapping(table), []
    if r:
        out += [Check("Intel Lab: held-out end points' median |SDF| <= 1.5 cm", r["heldout_abs_sdf_median_m"] <= 0.015,
                      f"{100 * r['heldout_abs_sdf_median_m']:.2f} cm over {r['heldout_endpoints']:.0f} end points", known_miss=True),
                Check("Intel Lab: median update <= 8 ms per scan (CPU time)", r["update_cpu_ms_median"] <= 8.0,
                      f"{r['update_cpu_ms_median']:.2f} ms (median over {len(table)} trials)", timing=True)]
    for r in [r for r in table if r["method"] == "icpg"][:1]:
        out += [Check("Intel Lab: ICP-G relocalisation median <= 3 cm against the corrected poses", r["reloc_median_m"] <= 0.03,
                      f"{100 * r['reloc_median_m']:.2f} cm over {r['reloc_scans']} held-out scans"),
                Check("Intel Lab: ICP-G relocalisation, no failure > 0.5 m", r["reloc_fail"] == 0,
                      f"{r['reloc_fail']} failures, worst {r['reloc_max_m']:.3f} m")]
    return out


def findings(table, ctx):
    r = _mapping(table)
    if not r:
        return []
    return [Finding("Ch. 7, Fig. 7.12a (Intel Lab)", "the distribution of GPIS update times over the Intel Lab log (online "
                    "rate); we read it as a target of a median <= 8 ms per scan",
                    f"median {duration(r['update_cpu_ms_median'] / 1e3, 'ms', decimals=2)}, p99 "
                    f"{duration(r['update_cpu_ms_p99'] / 1e3, 'ms', decimals=2)} CPU per 180-beam scan",
                    "held" if r["update_cpu_ms_median"] <= 8.0 else "not held", "our implementation on a shared 2-core VM, 910 corrected scans; the published "
                    "histogram's numbers are not transcribed here: bench_vs_published times the published C++ on the same scans"),
            Finding("Ch. 7, Fig. 7.19 (Intel Lab)", "the GPIS map of the Intel Lab: its zero level on the walls, low "
                    "variance where observed (a picture)",
                    f"held-out end points lie {length(r['heldout_abs_sdf_median_m'], 'cm', decimals=2)} (median) from the zero level",
                    "held" if r["heldout_abs_sdf_median_m"] <= 0.015 else "partly held",
                    "a picture is compared by eye; we score it by self-consistency (target: median "
                    "<= 1.5 cm), as a real log has no exact geometry")]


def summarize(table, ctx):
    rows = sorted(table, key=lambda r: (r["mapper"], r["method"], r["seed"]))
    write_csv_table(rows, MAP_COLS + LOC_COLS + sorted(k for k in rows[0] if k.startswith(("s2m", "odom_", "gmapping"))),
                    ctx.out_dir / "intel_lab.csv")
    maps = [next(r for r in rows if r["mapper"] == k) for k in sorted({r["mapper"] for r in rows})]
    fig = map_figure(ctx.arrays(maps[0]), mapper=maps[0]["mapper"], title="Intel Research Lab (real data, GMapping-corrected poses)")
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
    params={"held_out_stride": 1, "picture_res_m": 0.05},
    sizes={"quick": {"n_seeds": 1, "grid": {"method": ["icpg"]}, "params": {"held_out_stride": 4, "picture_res_m": 0.2}},
           "full": {}},
    trial=trial, summarize=summarize, checks=checks, findings=findings,
)
