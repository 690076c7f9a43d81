"""sensors: how exact are the simulator's sensors and ground truth?

Over scenes and seeds, drives the rover kinematically and measures, at several poses:
the largest |SDF| at 2D and 3D lidar endpoints, the largest |SDF| of depth pixels
back-projected with K and T_world_cam (within 5 m, and the 99th percentile overall), the share of
pixels whose ground label agrees with the exact geometry, and the kinematic rover's deviation
from the closed-form unicycle. The checks are the exactness bounds: lidar end points within 1 mm of
the geometry, depth within 2 mm up to 5 m, labels agreeing on >= 99.9 % of pixels, the kinematic
rover on the unicycle to 1e-9 m.
"""

import numpy as np

from polar_sim.runner import Check, Experiment
from polar_sim.runner.report import group_rows, length, markdown_table, percent, write_csv_table

SPEED = {"rover_terrain": (6.0, 0.1), "rover_flat": (6.0, 0.1), "office2d": (1.0, 0.3)}


def _backproject(f):
    H, W = f.depth.shape
    v, u = np.mgrid[0:H, 0:W]
    z = f.depth.astype(np.float64)
    ok = np.isfinite(z)
    pc = np.stack([(u - f.K[0, 2]) / f.K[0, 0] * z, (v - f.K[1, 2]) / f.K[1, 1] * z, z], -1)[ok]
    return pc @ f.T_world_cam[:3, :3].T + f.T_world_cam[:3, 3], z[ok], ok


def _world_points(scan):
    P = scan.points()
    if P.shape[1] == 2:
        P = np.c_[P, np.zeros(len(P))]
    return P @ scan.T_world_sensor[:3, :3].T + scan.T_world_sensor[:3, 3]


def trial(params, seed, ctx):
    from polar_sim.sim import LABELS, World

    scene, frames = params["scene"], int(params["frames"])
    rng = np.random.default_rng(seed)
    lid2, lid3, dep5, dep99, agree, kin = [], [], [], [], [], []
    with World(scene, seed=seed, kinematic=True) as w:
        x, y, th = w.meta.start_pose2d
        vmax, wmax = SPEED[scene]
        for k in range(frames):
            for _ in range(10):
                v, om = rng.uniform(0.3, 1.0) * vmax, rng.uniform(-wmax, wmax)
                w.step((v, om))
                dt = w.dt
                x, y = x + v / om * (np.sin(th + om * dt) - np.sin(th)), y + v / om * (np.cos(th) - np.cos(th + om * dt))
                th += om * dt
                T = w.truth()["robot_pose"]
                kin.append(max(abs(T[0, 3] - x), abs(T[1, 3] - y)))
            s2 = w.lidar("lidar")
            if np.isfinite(s2.ranges).any():
                lid2.append(np.abs(w.sdf(_world_points(s2))).max())
            P3 = _world_points(w.lidar("lidar3d"))
            if len(P3):
                lid3.append(np.abs(w.sdf(P3[rng.choice(len(P3), min(3000, len(P3)), replace=False)])).max())
            f = w.camera("front")
            P, z, ok = _backproject(f)
            idx = rng.choice(len(P), min(5000, len(P)), replace=False)
            d = np.abs(w.sdf(P[idx]))
            near = z[idx] <= 5.0
            if near.any():
                dep5.append(d[near].max())
            dep99.append(np.percentile(d, 99))
            geo = w.nearest_surface(P[idx]) == LABELS["ground"]
            agree.append(np.mean(geo == (f.labels[ok][idx] == LABELS["ground"])))
    nan = float("nan")
    return {
        "lidar2d_max_abs_sdf_m": float(max(lid2)) if lid2 else nan,
        "lidar3d_max_abs_sdf_m": float(max(lid3)) if lid3 else nan,
        "depth_max_abs_sdf_within5m_m": float(max(dep5)) if dep5 else nan,
        "depth_p99_abs_sdf_m": float(max(dep99)),
        "ground_label_agreement": float(min(agree)),
        "kinematic_max_error_m": float(max(kin)),
    }


METRICS = ["lidar2d_max_abs_sdf_m", "lidar3d_max_abs_sdf_m", "depth_max_abs_sdf_within5m_m",
           "depth_p99_abs_sdf_m", "ground_label_agreement", "kinematic_max_error_m"]


def summarize(table, ctx):
    out_dir = ctx.out_dir
    rows = group_rows(table, ["scene"], METRICS, stats=("max",))
    for r in rows:
        r["ground_label_agreement_min"] = min(t["ground_label_agreement"] for t in table if t["scene"] == r["scene"])
    cols = ["scene"] + [f"{m}_max" for m in METRICS if m != "ground_label_agreement"] + ["ground_label_agreement_min"]
    write_csv_table(rows, cols, out_dir / "sensors_table.csv")
    return ("Worst case over seeds and poses (lidar and depth errors in metres):\n\n"
            + markdown_table(rows, cols) + "\n\nTable: `sensors_table.csv`.")


def _worst(table, key, fn=max):
    vals = [r[key] for r in table if isinstance(r.get(key), float) and not np.isnan(r[key])]
    return fn(vals) if vals else float("nan")


def checks(table, ctx):
    l2, l3 = _worst(table, "lidar2d_max_abs_sdf_m"), _worst(table, "lidar3d_max_abs_sdf_m")
    d5 = _worst(table, "depth_max_abs_sdf_within5m_m")
    ag = _worst(table, "ground_label_agreement", min)
    kin = _worst(table, "kinematic_max_error_m")
    return [
        Check("lidar endpoints on the geometry: |sdf| < 1 mm", max(l2, l3) < 1e-3,
              f"2D {length(l2, 'mm')}, 3D {length(l3, 'mm')}"),
        Check("depth back-projection: |sdf| < 2 mm within 5 m", d5 < 2e-3, length(d5, "mm")),
        Check("ground label agrees with geometry on >= 99.9% of pixels", ag >= 0.999, f"worst {percent(ag, 3)}"),
        Check("kinematic rover follows the unicycle to 1e-9", kin < 1e-9, f"{kin:.2e} m"),
    ]


EXPERIMENT = Experiment(
    name="sensors",
    description="exactness of lidar, depth, labels and the kinematic rover against the scene geometry",
    grid={"scene": ["rover_terrain", "rover_flat", "office2d"], "frames": [4]},
    choices={"scene": list(SPEED)},
    splits={"dev": {"seeds": range(5)}},
    sizes={"quick": {"n_seeds": 1, "grid": {"scene": ["rover_terrain", "office2d"], "frames": [1]}}, "full": {}},
    trial=trial,
    summarize=summarize,
    checks=checks,
)
