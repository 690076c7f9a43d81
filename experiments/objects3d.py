"""objects3d: GPISMap3D reconstructions of single objects from RGB-D orbits.

For each object of ``polar_sim.sim.builders.objects`` (mug, box, can, bottle, drill, bracket, cube), the
``object_orbit`` scene (the object welded on a stand, an RGB-D camera circling it at 0.8 m,
elevation 30 +- 12 deg) renders ``n_frames`` frames over one turn (40; quick: 20), masked to the
object with the exact labels (as the published BigBird demo masks its depth) with Kinect-like
``DepthNoise`` (``polar_sim.sim.recorders.orbits.recorded_orbit``); the ``mapper3d`` method (``gpis``:
``GPISMap3D()``, default mode) fuses every frame at the true camera pose.

Scored against the true mesh (``polar_sim.metrics.object_map_scores`` on
``polar_sim.sim.recorders.orbits.ObjectTruth``): Chamfer distance between ``surface()`` (marching cubes) and
the mesh on the observed part (both directed means and their average); the normal error (the map's
gradient at each reconstructed vertex against the true face normal at its nearest mesh point); the
SDF RMSE within 1 cm of the observed surface (at ``n_eval`` points: 4000; quick: 2000). Pictures:
a vertical SDF slice through each object with the true and estimated zero levels, and each mesh
coloured by its distance to the truth.
Check: Chamfer <= 3 mm for every object (the bound ``gpis_accuracy`` sets on ``object_orbit``).
"""

from __future__ import annotations

import numpy as np

from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import markdown_table, savefig, write_csv_table

from polar_sim.experiments import _gpis_common as C

OBJECTS = ["mug", "box", "can", "bottle", "drill", "bracket", "cube"]
COLS = ["object", "method", "seed", "chamfer_m", "surface_to_mesh_m", "mesh_to_surface_m", "surface_to_mesh_all_m",
        "normal_median_deg", "normal_mean_deg", "normal_p90_deg", "sdf_rmse_m", "sdf_median_abs_m",
        "n_vertices", "n_samples", "n_frames", "update_cpu_ms_median", "update_cpu_ms_max", "load"]


def trial(params, seed, ctx):
    row, m, truth, cmp = C.orbit_trial(params["method"], seed, n_frames=ctx.params["n_frames"],
                                       n_eval=ctx.params["n_eval"], object=params["object"])
    mesh = truth.mesh
    centre, half = mesh.bounds.mean(0), 0.5 * float(mesh.extents.max()) + 0.02
    xs = np.arange(centre[0] - half, centre[0] + half + 1e-9, 0.0015)
    zs = np.arange(centre[2] - half, centre[2] + half + 1e-9, 0.0015)
    X, Z = np.meshgrid(xs, zs, indexing="xy")
    d, _, v = m.query(np.column_stack([X.ravel(), np.full(X.size, centre[1]), Z.ravel()]))
    S = m.surface()
    ctx.save_arrays(xs=xs, zs=zs, sdf=d.reshape(X.shape), var=v.reshape(X.shape), true=truth.section_xz(centre[1]),
                    V=np.asarray(S.vertices), F=np.asarray(S.faces), dist=cmp["dist"], centre=centre, half=half)
    row.pop("object")      # a grid axis here
    return {**row, "extent_m": float(mesh.extents.max())}


def checks(table, ctx):
    bad = [r["object"] for r in table if not r["chamfer_m"] <= 0.003]
    worst = max(table, key=lambda r: r["chamfer_m"] if np.isfinite(r["chamfer_m"]) else np.inf)
    return [Check(f"Chamfer <= 3 mm for every object ({len(table)} objects)", not bad,
                  f"worst {worst['object']} {1e3 * worst['chamfer_m']:.2f} mm" + (f"; above: {bad}" if bad else ""))]


def _object_names():
    """The objects ``object_orbit`` can hold (the catalogue of ``polar_sim.sim.builders.objects``)."""
    from polar_sim.sim.builders.objects import object_names

    return object_names()


def _order(table):
    return sorted(table, key=lambda r: (OBJECTS.index(r["object"]) if r["object"] in OBJECTS else 99, r["method"], r["seed"]))


def _figure(table, ctx):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    rows = _order(table)
    n = len(rows)
    fig = plt.figure(figsize=(3.2 * n, 6.6))
    for j, r in enumerate(rows):
        z = ctx.arrays(r)
        a = fig.add_subplot(2, n, j + 1)
        im = a.imshow(np.clip(z["sdf"], -0.02, 0.02), origin="lower", cmap="RdBu", vmin=-0.02, vmax=0.02,
                      extent=[z["xs"][0], z["xs"][-1], z["zs"][0], z["zs"][-1]])
        a.contour(z["xs"], z["zs"], z["sdf"], [0.0], colors="k", linewidths=0.8)
        if len(z["true"]):
            a.plot(z["true"][:, 0], z["true"][:, 1], "--", c="lime", lw=1.0)
        a.set_title(f"{r['object']} ({r['method']}): SDF slice", fontsize=9)
        a.set_xlabel("x (m)", fontsize=7)
        a.set_ylabel("z (m)", fontsize=7)
        b = fig.add_subplot(2, n, n + j + 1, projection="3d")
        if len(z["F"]):
            V, F = z["V"], z["F"]
            b.add_collection3d(Poly3DCollection(V[F], facecolors=plt.cm.viridis(np.clip(z["dist"][F].mean(1) / 0.005, 0, 1)),
                                                edgecolor="none"))
            c, h = z["centre"], float(z["half"]) - 0.02
            b.set(xlim=(c[0] - h, c[0] + h), ylim=(c[1] - h, c[1] + h), zlim=(c[2] - h, c[2] + h))
            b.view_init(elev=25, azim=-60)
        b.set_axis_off()
        b.set_title(f"Chamfer {1e3 * r['chamfer_m']:.2f} mm, normals {r['normal_median_deg']:.1f} deg", fontsize=8)
    fig.subplots_adjust(right=0.9, top=0.86, hspace=0.3)   # the mesh titles clear of the slices' x labels
    fig.colorbar(im, cax=fig.add_axes([0.92, 0.55, 0.012, 0.3]), label="GPIS SDF (m)")
    fig.suptitle("GPISMap3D from a simulated RGB-D orbit (Kinect-like noise). Top: vertical SDF slice, black = its zero "
                 "level, green dashed = true section.\nBottom: surface() mesh coloured by distance to the true mesh "
                 "(0-5 mm, viridis)", fontsize=9)
    return savefig(fig, ctx.out_dir, "gpis_objects3d")


def summarize(table, ctx):
    rows = _order(table)
    write_csv_table(rows, COLS, ctx.out_dir / "objects3d.csv")
    return "\n".join([f"Distances in metres (observed part of each object), {ctx.split} split.", "",
                      markdown_table(rows, COLS), "", "Table: `objects3d.csv`.", "", _figure(table, ctx)])


EXPERIMENT = Experiment(
    name="objects3d",
    description="GPISMap3D object reconstructions from simulated RGB-D orbits: Chamfer, normal error, SDF slices",
    grid={"object": OBJECTS, "method": ["gpis"]},
    methods={"method": "mapper3d"},
    splits={"dev": {"seeds": [0]}, "test": {"seeds": [10_000]}},
    choices={"object": _object_names},
    params={"n_frames": 40, "n_eval": 4000},
    sizes={"quick": {"n_seeds": 1, "grid": {"object": ["box"]}, "params": {"n_frames": 20, "n_eval": 2000}}, "full": {}},
    trial=trial, summarize=summarize, checks=checks,
)
