"""Methods as plug-ins: a user's mapper, localiser, VO or tracker runs in the same experiments as ours.

An experiment's method axis holds names. A name is either registered here (the built-in methods
and any ``register_method`` call) or an import path ``"package.module:attribute"`` naming a
factory of your own::

    polar-sim run localisation --set method=mypkg.mymod:MyLocalizer
    # or, in Python, before running:
    from polar_sim.runner import register_method
    register_method("localizer2d", "mine", MyLocalizer, description="my localiser")

Workers of the local pool and of Ray import an import-path factory themselves; a name registered
with ``register_method`` in your script is only known to that process, so give workers the import
path (or register the method at import of a module they import).

Protocols, per kind (arrays are numpy; units metres, radians, seconds):

``mapper2d``
    ``factory(**params) -> m``; ``m.update(angles (n,), ranges (n,), pose2d (3,))`` fuses one scan
    taken at the *sensor* pose ``(x, y, theta)`` (``inf``/NaN range = no return);
    ``m.query(points (k, 2)) -> (d (k,), grad (k, 2), var (k,) or None)``: signed distance,
    positive in free space; optional ``m.surface() -> list of (j, 2) polylines``.
``mapper3d``
    ``m.update(depth (H, W) float32 m, K (3, 3), T_world_cam (4, 4))``, ``m.query(points (k, 3))``
    as above; optional ``m.surface() -> trimesh.Trimesh``.
``localizer2d``
    ``factory(**params) -> loc``; ``loc.fit(angles (m,), ranges (n, m), poses (n, 3))`` builds its
    map from a mapping drive (sensor poses); ``loc.reset(pose2d (3,))`` sets the initial estimate;
    ``loc.step(angles (m,), ranges (m,), odometry_delta (3,)) -> pose2d (3,)`` takes the motion
    since the last step in the previous pose's frame and the new scan, and returns the estimate.
``vo``
    ``factory(K (3, 3), camera_height (m), *, seed) -> vo``; ``vo.process(rgb (H, W, 3) uint8, t)
    -> r`` with ``r.pose`` (4, 4): camera k in camera 0's frame, OpenCV axes (KITTI); optional
    ``r.ground_prob`` (H, W) in [0, 1] and ``r.speed`` (m/s).
``tracker``
    ``factory(model_points (M, 3), K (3, 3), initial_pose (4, 4), *, model_normals (M, 3),
    random_state) -> tr``; ``tr.process(rgb (H, W, 3) uint8, depth (H, W) float32 m, t) -> r`` with
    ``r.pose`` (4, 4) T_cam_obj; optional ``r.mask`` (H, W) bool, ``r.prob`` (H, W) in [0, 1],
    ``r.lost`` (bool).

Built-in methods are registered lazily below, one section per kind: their factories import the
heavy modules only when called.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable

__all__ = ["KINDS", "register_method", "get_method", "list_methods", "describe_methods", "Method"]

KINDS = {
    "mapper2d": "a 2D map from scans: update(angles, ranges, pose2d), query(points) -> (d, grad, var)",
    "mapper3d": "a 3D map from depth images: update(depth, K, T_world_cam), query(points) -> (d, grad, var)",
    "localizer2d": "fit(angles, ranges, poses) on a mapping drive; reset(pose2d); step(angles, ranges, odometry_delta) -> pose2d",
    "vo": "factory(K, camera_height, seed=...); process(rgb, t) -> result with .pose (4x4)",
    "tracker": "factory(model_points, K, initial_pose, model_normals=..., random_state=...); process(rgb, depth, t) -> .pose",
}


@dataclasses.dataclass(frozen=True)
class Method:
    kind: str
    name: str
    factory: Callable
    description: str = ""


_REGISTRY: dict[str, dict[str, Method]] = {k: {} for k in KINDS}


def _check_kind(kind):
    if kind not in KINDS:
        raise ValueError(f"kind: unknown method kind {kind!r}; valid: {', '.join(KINDS)}")


def register_method(kind: str, name: str, factory: Callable, *, description: str = "", replace: bool = False):
    """Register ``factory`` as method ``name`` of ``kind`` (see the module docstring for protocols)."""
    _check_kind(kind)
    if not isinstance(name, str) or not name or ":" in name:
        raise ValueError(f"name: expected a non-empty name without ':', got {name!r}")
    if not callable(factory):
        raise TypeError(f"factory: expected a callable, got {type(factory).__name__}")
    if name in _REGISTRY[kind] and not replace:
        raise ValueError(f"name: {kind} method {name!r} is already registered (pass replace=True)")
    _REGISTRY[kind][name] = Method(kind, name, factory, description)
    return factory


def _import_factory(path):
    module, _, attr = path.partition(":")
    if not module or not attr:
        raise ValueError(f"method: {path!r} is not of the form 'package.module:attribute'")
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        raise ValueError(f"method: cannot import module {module!r} of {path!r}: {exc}") from None
    obj = mod
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"method: module {module!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise ValueError(f"method: {path!r} is not callable")
    return obj


def get_method(kind: str, name: str) -> Callable:
    """The factory of method ``name`` of ``kind``: a registered name or ``"pkg.mod:attr"``.

    An unknown name raises ``ValueError`` listing the registered ones.
    """
    _check_kind(kind)
    if not isinstance(name, str):
        raise ValueError(f"method: expected a method name or 'package.module:attribute', got {name!r}")
    if ":" in name:
        return _import_factory(name)
    if name not in _REGISTRY[kind]:
        valid = ", ".join(sorted(_REGISTRY[kind])) or "(none registered)"
        raise ValueError(f"method: unknown {kind} method {name!r}; valid: {valid}, or 'package.module:attribute'")
    return _REGISTRY[kind][name].factory


def list_methods(kind: str | None = None):
    """Registered method names of ``kind`` (sorted), or ``{kind: [names]}`` for every kind."""
    if kind is None:
        return {k: sorted(v) for k, v in _REGISTRY.items()}
    _check_kind(kind)
    return sorted(_REGISTRY[kind])


def describe_methods():
    """Rows ``(kind, name, description)`` of every registered method."""
    return [(k, m.name, m.description) for k in KINDS for m in sorted(_REGISTRY[k].values(), key=lambda m: m.name)]


# ---------------------------------------------------------------------------------------------
# Built-in methods. Each section belongs to the experiments of its kind; factories import lazily.
# ---------------------------------------------------------------------------------------------

# -- mapper2d / mapper3d / localizer2d (the GPIS experiments) --
# Implementations: polar_sim.runner.gpis_methods (imports the heavy modules on first use).
#
# Besides the protocols above, the GPIS experiments use two optional parts: a mapper2d may offer
# ``surface_points() -> (k, 2)`` (a point set, e.g. grid cells) instead of ``surface()``; and a
# factory that names one of these keywords in its signature is given it when the experiment has it: ``seed`` (int, the
# trial's seed), ``init_std`` ((3,) m, m, rad: the spread of the initial estimate, localisers),
# ``exact_sdf`` (a callable points (k, 2) -> (k,): the scene's exact SDF, an oracle input that only
# ground-truth baselines such as ``icpd_gt`` ask for). ``polar_sim.runner.gpis_methods.call_factory``
# does this matching.
from polar_sim.runner import gpis_methods as _gm  # noqa: E402  (light: no heavy imports at module level)

for _name, _f, _d in [
    ("gpis", _gm.gpis2d, "GPISMap2D, default mode, taking the sensor pose"),
    ("gpis_legacy", _gm.gpis2d_legacy, "GPISMap2D.published(): the published behaviour"),
    ("grid5", lambda **kw: _gm.GridMapper2D(0.05, **kw), "5 cm occupancy grid; SDF = its signed EDT; surface = occupied cells next to free"),
    ("grid10", lambda **kw: _gm.GridMapper2D(0.10, **kw), "10 cm occupancy grid (as grid5)"),
    ("edt5", lambda **kw: _gm.EDTMapper2D(0.05, **kw), "signed EDT of a 5 cm grid; surface = its zero contour"),
]:
    register_method("mapper2d", _name, _f, description=_d)
register_method("mapper3d", "gpis", _gm.gpis3d, description="GPISMap3D, default mode")
register_method("mapper3d", "gpis_legacy", _gm.gpis3d_legacy, description="GPISMap3D.published(): the published behaviour")
for _n in (1000, 5000, 10000):
    register_method("localizer2d", f"pf{_n}", _gm.pf_factory(_n),
                    description=f"MCL, {_n} particles, likelihood field of a 5 cm grid")
register_method("localizer2d", "icpd", _gm.ICPDLocalizer2D, description="ICP-D on the signed EDT of a 5 cm grid")
register_method("localizer2d", "icpd_gt", _gm.icpd_gt,
                description="ICP-D on the exact SDF sampled at 5 cm (the dissertation's ground-truth discrete SDF; oracle)")
register_method("localizer2d", "icpg", _gm.ICPGLocalizer2D, description="ICP-G on a GPISMap2D of the mapping drive")

# -- vo (the ground experiments) --


def _groundvo_factory(model, sampling):
    def factory(K, camera_height, *, seed=0, **params):
        from polar_sim.ground import GroundVO

        return GroundVO(K, camera_height, model=model, sampling=sampling, seed=seed, **params)

    factory.__name__ = f"groundvo_{model}_{sampling}"
    return factory


def _held_scale_vo(K, camera_height, *, seed=0, speed_truth, **params):
    from polar_sim.ground.held_scale import HeldScaleVO

    params.setdefault("model", "6param")
    params.setdefault("sampling", "uniform")
    return HeldScaleVO(K, camera_height, speed_truth=speed_truth, seed=seed, **params)


register_method("vo", "groundvo", _groundvo_factory("6param", "weighted"),
                description="GroundVO with its defaults (6-parameter ground model, weighted RANSAC)")
for _name, (_model, _sampling) in {"u2": ("2param", "uniform"), "w2": ("2param", "weighted"),
                                   "u6": ("6param", "uniform"), "w6": ("6param", "weighted")}.items():
    register_method("vo", _name, _groundvo_factory(_model, _sampling),
                    description=f"GroundVO, {_model} ground model, {_sampling} RANSAC sampling")
def _w6_nocal(K, camera_height, *, seed=0, **params):
    from polar_sim.ground import CalibrationConfig, ClassifierConfig, GroundVO

    return GroundVO(K, camera_height, model="6param", sampling="weighted", seed=seed,
                    calibration=CalibrationConfig(method="none"),
                    classifier=ClassifierConfig(train_depth=None, decay_samples=None), **params)


def _w6_ng6h(K, camera_height, *, seed=0, **params):
    from polar_sim.ground import ClassifierConfig, GroundVO

    return GroundVO(K, camera_height, model="6param", sampling="weighted", seed=seed,
                    classifier=ClassifierConfig(ng_outlier_sigma=6.0, ng_outlier_history=True), **params)


register_method("vo", "w6_nocal", _w6_nocal,
                description="w6 with the spec's classifier training (no depth limit, plain decay by alpha) "
                            "and uncalibrated ground_prob: the earlier behaviour, for comparison")
register_method("vo", "w6_ng6h", _w6_ng6h,
                description="w6 with the stricter non-ground outlier rule (6 sigma, never-inlier tracks): "
                            "better on weakly textured ground, not the default")
register_method("vo", "mono", _held_scale_vo,
                description="monocular baseline (VISO2-M analogue): GroundVO's estimator with the scale taken from "
                            "the true speed once and then held through the structure; needs speed_truth=")

# -- tracker (the tracking experiments) --
#: Built-in trackers: ObjectTracker configurations (``set_params`` names over its defaults: the
#: top-level parameters, and a stage config's fields as ``stage__field``).
TRACKERS = {
    "ww": ({}, "ObjectTracker, the default: W head, confidence-weighted self-labels"),
    "wu": ({"appearance": "wu"}, "ObjectTracker, W head (weighted sum of per-scale heads), uniform self-labels"),
    "sw": ({"appearance": "sw"}, "ObjectTracker, S head (one layer on stacked features), weighted self-labels"),
    "su": ({"appearance": "su"}, "ObjectTracker, S head, uniform self-labels"),
    "h": ({"appearance": "h"}, "ObjectTracker with the 216-bin HSV Naive Bayes (the ground chapter's classifier)"),
    "shape-only": ({"appearance": "none"}, "ablation: appearance term off (prior x depth only)"),
    "no-motion": ({"motion__filter": "none"}, "ablation: motion prior off (the prediction is the last pose)"),
    "spatial-prior": ({"attention__spatial_prior": True},
                      "ablation: the blurred predicted silhouette as the prior pi (epsilon 0.02)"),
    "spatial-prior-0.1": ({"attention__spatial_prior": True, "attention__epsilon": 0.1},
                          "ablation: the silhouette prior softened to epsilon 0.1"),
    "alpha-beta": ({"motion__filter": "alpha-beta"}, "ablation: the spec's alpha-beta filter instead of the EKF"),
    "no-hold": ({"registration__hold_unobserved": False}, "ablation: velocity integrated along unobserved directions"),
    "no-deadzone": ({"registration__tangential_deadzone": 0.0},
                    "ablation: the ICP's tangential term without its dead zone (every sampling gap of the model pulls)"),
    "lost-by-silhouette": ({"guard__coverage": "silhouette"},
                           "ablation: lost when too few inliers per pixel of the whole predicted silhouette, hidden "
                           "pixels included (the rule before the visible-pixel coverage)"),
    "plain-icp": ({"appearance": "none", "registration__method": "plain"}, "baseline: robust ICP on every ROI point"),
}


def _tracker(config):
    def factory(model_points, K, initial_pose, *, model_normals=None, random_state=0, **kw):
        from polar_sim.tracking import ObjectTracker

        tr = ObjectTracker(model_points, K, initial_pose, model_normals=model_normals, random_state=random_state)
        return tr.set_params(**{**config, **kw})
    return factory


for _name, (_config, _description) in TRACKERS.items():
    register_method("tracker", _name, _tracker(_config), description=_description)
