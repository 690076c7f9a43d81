"""Shared declarations of the ground-chapter experiments (not an experiment: the underscore keeps it
out of the registry). The work is in the library: routes are recordings from the one cache
(``polar_sim.sim.recorders.rover_sequences.load_route``), VOs are ``vo`` plug-ins
(``polar_sim.runner.methods``) replayed by ``polar_sim.ground.replay``, integration is
``polar_sim.ground.integration``, scores are ``polar_sim.metrics``. What stays here is the protocol:
the route lists per split and the size-dependent protocol values (``ROUTE_PARAMS``,
``QUICK_PARAMS``). The RANSAC candidate sets are in ``_ground_candidates``, the figures in
``_ground_pictures``.
"""

from __future__ import annotations

import numpy as np

#: The ten routes every pre-protocol figure was measured on (the dev split's default-appearance routes).
DEV10 = ("terrain_00", "terrain_01", "terrain_02", "terrain_03", "terrain_04", "terrain_05",
         "flat_00", "flat_01", "flat_02", "flat_03")
#: One dev route per dev appearance family (``dev_pavers``: the dev split's periodic ground).
DEV_FAMILY_ROUTES = ("dev_speckle", "dev_gravel", "dev_grass", "dev_blotches", "dev_uniform", "dev_pavers")
TEST_ROUTES = ("test_speckle", "test_gravel", "test_grass", "test_uniform", "test_stripes", "test_checker",
               "test_blotches", "test_random_0", "test_random_1", "test_random_2", "test_default_0", "test_default_1")

#: The CI (``quick``) routes: the first 120 frames (54 m on dev, 65 m on test) of one route per split,
#: shared by all experiments so each is recorded once per cache (about 20 s). The ``route`` axis
#: value ``"quick"`` names the split's quick route.
QUICK_FRAMES = 120
QUICK_ROUTE = {"dev": "terrain_00", "test": "test_random_0"}

#: Protocol parameters of the experiments that drive a route (``Experiment.params``, overridable with
#: ``--set``): ``max_frames``, the frames of each route replayed (null = the whole route). The quick
#: size cuts every route to ``QUICK_FRAMES`` (``QUICK_PARAMS``, its ``sizes["quick"]["params"]``).
ROUTE_PARAMS = {"max_frames": None}
QUICK_PARAMS = {"max_frames": QUICK_FRAMES}
#: The shortest KITTI devkit segment, m.
KITTI_MIN_M = 100.0


def single_thread():
    """OpenCV on one thread: per-frame CPU times are single-threaded and parallel trials do not
    oversubscribe the cores."""
    import cv2

    cv2.setNumThreads(1)


def route_choices():
    """The values the ``route`` axis accepts: ``"quick"`` (the split's quick route) and every dev and
    test route (``polar_sim.sim.recorders.rover_sequences.SPLITS``)."""
    from polar_sim.sim.recorders.rover_sequences import SPLITS

    return ["quick", *SPLITS["dev"], *SPLITS["test"]]


def route_of(params, ctx):
    """The route name of a trial: the axis value, or the split's quick route for ``"quick"``."""
    return QUICK_ROUTE[ctx.split] if params["route"] == "quick" else params["route"]


def max_frames(ctx):
    """The run's ``max_frames`` param: None (the whole route) or a positive int."""
    n = ctx.params["max_frames"]
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise ValueError(f"max_frames: expected a positive number of frames or null (the whole route), got {n!r}")
    return n


def load(params, ctx):
    """The trial's recording (its first ``max_frames`` frames, a run param) and its truth."""
    from polar_sim.sim.recorders.rover_sequences import load_route, route_truth

    rec = load_route(route_of(params, ctx), max_frames=max_frames(ctx))
    return rec, route_truth(rec)


def rover_vo_params(tr):
    """GroundVO's settings for the rover's recordings (the built-in methods'): the working size (the
    routes are recorded at it) and the rover's calibrated sideways slip (``tr["slip"]``)."""
    from polar_sim.ground import MotionConfig

    return {"downsample": 1, "motion": MotionConfig(slip=tr["slip"])}


def table(rows, cols, why=None):
    """A markdown table without the columns that are empty (None, "" or NaN) in every row, followed by
    one line naming the columns left out and why (``why``: {column: reason}; a column without one is
    "empty in every row"). A route under 100 m, for example, has no 100 m KITTI segment."""
    from polar_sim.runner.report import markdown_table, nonempty_columns

    rows, cols = list(rows), list(cols)
    keep, _ = nonempty_columns(rows, cols)
    gone = [c for c in cols if c not in keep]
    out = markdown_table(rows, keep, drop_empty=False)
    if rows and gone:
        reasons = {}
        for c in gone:
            reasons.setdefault((why or {}).get(c, "empty in every row"), []).append(f"`{c}`")
        out += "\n\nNot shown: " + "; ".join(f"{', '.join(cs)} ({r})" for r, cs in reasons.items()) + "."
    return out


def family_names(rec):
    """Family label of each zone of a route: the appearance family, or ``default <type>`` for the
    default look (whose asphalt/gravel/grass/dirt textures are not the families of the same name)."""
    zones = [str(z) for z in rec.meta["zones"]]
    return zones if rec.meta.get("appearance") else [f"default {z}" for z in zones]


def _finite(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and bool(np.isfinite(x))


def segments(table):
    """(translation key, rotation key, label, note) of the odometry segments the routes of ``table``
    hold: the KITTI 100-800 m segments when a route has one, else the scaled segments (every route
    under 100 m, e.g. the quick size's)."""
    if any(_finite(r.get("t_pct")) for r in table):
        return "t_pct", "r_degm", "100–800 m segments", "KITTI segments of 100–800 m"
    longest = max((r["length_m"] for r in table if _finite(r.get("length_m"))), default=float("nan"))
    return ("t_pct_scaled", "r_degm_scaled", f"scaled segments: routes under {KITTI_MIN_M:.0f} m",
            f"scaled segments L_j = j·L_max/8: no route reaches the {KITTI_MIN_M:.0f} m of the shortest KITTI "
            f"segment (longest {longest:.0f} m)")


def why_absent(table, prefixes=("", "planar_", "oracle_")):
    """{column: reason} for the 100-800 m columns when no route has a 100 m segment."""
    if segments(table)[0] == "t_pct":
        return {}
    why = f"no {KITTI_MIN_M:.0f} m KITTI segment on routes under {KITTI_MIN_M:.0f} m"
    return {f"{p}{k}": why for p in prefixes for k in ("t_pct", "r_degm")}


def pooled_odometry(table, ctx):
    """Odometry scores pooled over every segment of every route of ``table`` (ground_odometry's
    trials, their ``trajectories`` arrays): {label: dict(method, routes, t %, deg/m, t % scaled, deg/m
    scaled, median CPU)}, one label per method, its planar re-integration and the oracle scale."""
    from polar_sim.metrics.ground import kitti_scores_pooled

    pairs = {}
    for r in table:
        z = ctx.arrays(r, "trajectories")
        for key, lab in (("est", r["method"]), ("planar", r["method"] + " planar"), ("oracle", "oracle scale")):
            if key in z:
                pairs.setdefault(lab, []).append((z["gt"], z[key]))
    cpu = {lab: [r["cpu_ms_median"] for r in table if r["method"] == lab] for lab in pairs}
    return {lab: dict(method=lab, **kitti_scores_pooled(ps), cpu_ms_median=float(np.median(cpu[lab])) if cpu[lab] else None)
            for lab, ps in pairs.items()}
