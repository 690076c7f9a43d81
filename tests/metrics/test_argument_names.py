"""Every public function of polar_sim.metrics (but the ground and calibration modules, whose owners
audit them) refuses bad input with an error that names the argument at fault.

Each function has one valid call; each of its arguments is then replaced, one at a time, by hostile
values: a string or an array of strings, complex numbers and None are the wrong kind (``TypeError``);
an extra axis and a NaN are the wrong value (``ValueError``). The error must name the argument
replaced (where two arguments disagree in shape, naming both is right: either may be the wrong one).
"""

import re

import numpy as np
import pytest

from polar_sim import metrics as M
from polar_sim.metrics import maps

# -- small valid inputs ------------------------------------------------------------------------
K = np.array([[100.0, 0.0, 32.0], [0.0, 100.0, 24.0], [0.0, 0.0, 1.0]])
CUBE = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.05, 0.05) for z in (-0.05, 0.05)])


def _pose(angle=0.0, t=(0.0, 0.0, 0.5)):
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = t
    return T


G3 = np.stack([_pose(0.0), _pose(0.1), _pose(0.2)])
E3 = np.stack([_pose(0.01), _pose(0.12), _pose(0.18)])
ROUTE = np.stack([_pose(0.0, (1.0 * i, 0.0, 0.0)) for i in range(30)])
MASK = np.zeros((4, 5), bool)
MASK[1:3, 1:4] = True
PRED = np.zeros((4, 5), bool)
PRED[1:3, 2:5] = True
ANGLES = np.linspace(-np.pi, np.pi, 90, endpoint=False)
POSES2D = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.1]])
RANGES = np.full((2, 90), 3.0)
SDF = lambda P: 3.0 - np.linalg.norm(P, axis=1)  # noqa: E731  (inside a circle of 3 m)
OBS = maps.ObservedArea(ANGLES, POSES2D, RANGES)
EVAL = maps.sample_eval_points(OBS, SDF, 200, 0)
SURF = 2.95 * np.column_stack([np.cos(ANGLES), np.sin(ANGLES)])
_, DETAILS = maps.surface_scores_2d(SURF, SDF, OBS)
REL_T = np.arange(10.0)
REL_P = np.column_stack([REL_T * 0.1, np.zeros(10), np.zeros(10)])
RELS = np.array([[0.0, 1.0, 0.1, 0.0, 0.0], [2.0, 9.0, 0.7, 0.0, 0.0]])


# function: (valid keyword arguments, {argument: the hostile kinds it must refuse})
#   s: a string / array of strings, c: complex, n: None, d: an extra axis, f: a NaN (not for integers:
#   a float is the wrong kind there), v: an unknown choice (a ValueError)
CASES = {
    # surface
    M.nearest_distances: (dict(points=CUBE, reference=CUBE + 0.01), dict(points="scndf", reference="scndf")),
    M.hausdorff: (dict(points_a=CUBE, points_b=CUBE + 0.01), dict(points_a="scndf", points_b="scndf")),
    M.chamfer: (dict(points_a=CUBE, points_b=CUBE + 0.01), dict(points_a="scndf", points_b="scndf")),
    M.surface_rmse: (dict(points_est=CUBE, points_true=CUBE), dict(points_est="scndf", points_true="scndf")),
    M.sdf_error: (dict(est=[1.0, 2.0], truth=[1.1, 2.0], mask=np.array([True, True])),
                  dict(est="scnf", truth="scnf", mask="scd")),
    M.normal_angles: (dict(est_normals=CUBE, true_normals=CUBE + 0.01), dict(est_normals="scndf", true_normals="scndf")),
    M.normal_angle_error: (dict(est_normals=CUBE, true_normals=CUBE), dict(est_normals="scndf", true_normals="scndf")),
    M.sample_polyline: (dict(vertices=[[0.0, 0.0], [1.0, 0.0]], spacing=0.1), dict(vertices="scndf", spacing="scnf")),
    # segmentation
    M.iou: (dict(mask_a=MASK, mask_b=PRED), dict(mask_a="scnd", mask_b="scnd")),
    M.iou_success: (dict(ious=[0.4, 0.7], threshold=0.5), dict(ious="scnf", threshold="scnf")),
    M.iou_success_curve: (dict(ious=[0.4, 0.7], thresholds=[0.2, 0.5]), dict(ious="scnf", thresholds="scf")),
    M.precision_recall: (dict(pred=PRED, gt=MASK), dict(pred="scnd", gt="scnd")),
    M.occluder_as_target: (dict(pred=PRED, occluder=MASK, within=MASK), dict(pred="scnd", occluder="scnd", within="scd")),
    M.roc_auc: (dict(scores=[0.1, 0.9, 0.4], labels=[False, True, False]), dict(scores="scnf", labels="scnd")),
    M.near_mask: (dict(mask=MASK, radius_px=2), dict(mask="scnd", radius_px="scn")),
    M.mask_frame_scores: (dict(pred=PRED, truth=MASK, occluder=MASK, within=MASK),
                          dict(pred="scnd", truth="scnd", occluder="scd", within="scd")),
    M.iou_success_rate: (dict(ious=[0.4, 0.7], threshold=0.5, where=np.array([True, False])),
                         dict(ious="scndf", threshold="scnf", where="scd")),
    M.pooled_ece: (dict(counts=np.ones((2, 3, 4))), dict(counts="scndf")),
    M.pooled_precision_recall: (dict(n_tp=[1, 2], n_pred=[2, 2], n_gt=[3, 2]), dict(n_tp="scnd", n_pred="scnd", n_gt="scnd")),
    M.pooled_occluder_as_target: (dict(n_occluder=[4, 2], n_occluder_target=[1, 0], where=np.array([True, True])),
                                  dict(n_occluder="scnd", n_occluder_target="scnd", where="scd")),
    # pose
    M.object_diameter: (dict(points=CUBE), dict(points="scndf")),
    M.add: (dict(model_points=CUBE, T_gt=G3, T_est=E3), dict(model_points="scndf", T_gt="scndf", T_est="scndf")),
    M.adds: (dict(model_points=CUBE, T_gt=G3, T_est=E3), dict(model_points="scndf", T_gt="scndf", T_est="scndf")),
    M.rotation_error: (dict(T_gt=G3, T_est=E3), dict(T_gt="scndf", T_est="scndf")),
    M.translation_error: (dict(T_gt=G3, T_est=E3), dict(T_gt="scndf", T_est="scndf")),
    M.success_5cm5deg: (dict(T_gt=G3, T_est=E3, max_translation=0.05, max_rotation=0.1),
                        dict(T_gt="scndf", T_est="scndf", max_translation="scnf", max_rotation="scnf")),
    M.add_success: (dict(errors=[0.01, 0.02], diameter=0.1, k=0.1), dict(errors="scnf", diameter="scnf", k="scnf")),
    M.success_rate: (dict(errors=[0.01, 0.02], threshold=0.015), dict(errors="scnf", threshold="scnf")),
    M.success_curve: (dict(errors=[0.01, 0.02], thresholds=[0.01, 0.03]), dict(errors="scnf", thresholds="scnf")),
    M.pose_auc: (dict(errors=[0.01, 0.02], max_threshold=0.1), dict(errors="scnf", max_threshold="scnf")),
    M.frames_until_loss: (dict(errors=[0.01, 0.2, 0.3], threshold=0.1, patience=2),
                          dict(errors="scnf", threshold="scnf", patience="scn")),
    M.rotation_drift: (dict(T_gt=G3, T_est=E3, start=0), dict(T_gt="scndf", T_est="scndf", start="scn")),
    M.static_segments: (dict(T_gt=G3, max_rotation=0.05, max_translation=0.01, min_frames=1),
                        dict(T_gt="scndf", max_rotation="scnf", max_translation="scnf", min_frames="scn")),
    M.static_rotation_drift: (dict(T_gt=G3, T_est=E3, horizon=3), dict(T_gt="scndf", T_est="scndf", horizon="scn")),
    M.pose_frame_errors: (dict(model_points=CUBE, K=K, T_gt=G3, T_est=E3),
                          dict(model_points="scndf", K="scndf", T_gt="scndf", T_est="scndf")),
    M.mssd: (dict(model_points=CUBE, T_gt=G3, T_est=E3, symmetries=np.eye(4)[None]),
             dict(model_points="scndf", T_gt="scndf", T_est="scndf", symmetries="scdf")),
    M.mspd: (dict(model_points=CUBE, K=K, T_gt=G3, T_est=E3), dict(model_points="scndf", K="scndf", T_gt="scndf",
                                                                    T_est="scndf")),
    M.vsd: (dict(depth_est=np.full((4, 5), 0.5), depth_gt=np.full((4, 5), 0.5), depth_test=np.full((4, 5), 0.6), K=K,
                 diameter=0.1, taus=[0.1, 0.2], delta=0.015),
            dict(depth_est="scnd", depth_gt="scnd", depth_test="scnd", K="scndf", diameter="scnf", taus="scnf",
                 delta="scn")),
    M.render_depth: (dict(model_points=CUBE, K=K, T=_pose(), shape=(48, 64), radius_px=2),
                     dict(model_points="scndf", K="scndf", T="scndf", shape="scnd", radius_px="sc")),
    M.bop_recall: (dict(errors=[0.01, 0.02], thresholds=[0.015, 0.03]), dict(errors="scnf", thresholds="scnf")),
    M.ar_vsd: (dict(vsd_errors=[[0.1, 0.2]], thetas=[0.15, 0.3]), dict(vsd_errors="scnf", thetas="scnf")),
    M.ar_mssd: (dict(mssd_errors=[0.01], diameter=0.1, fractions=[0.1, 0.2]),
                dict(mssd_errors="scnf", diameter="scnf", fractions="scnf")),
    M.ar_mspd: (dict(mspd_errors=[3.0], image_width=640, pixels=[5.0, 10.0]),
                dict(mspd_errors="scnf", image_width="scnf", pixels="scnf")),
    M.add_success_rate: (dict(errors=[0.01, 0.02], diameter=0.1, k=0.1, where=np.array([True, False])),
                         dict(errors="scndf", diameter="scnf", k="scnf", where="scd")),
    M.success_5cm5deg_rate: (dict(rotation=[0.01, 0.2], translation=[0.01, 0.01], where=np.array([True, True]),
                                  max_translation=0.05, max_rotation=0.1),
                             dict(rotation="scnd", translation="scnd", where="scd", max_translation="scnf",
                                  max_rotation="scnf")),
    M.pooled_rate: (dict(rates=[0.5, 0.7], weights=[10, 20]), dict(rates="scnd", weights="scndf")),
    M.spearman: (dict(x=[1.0, 2.0, 3.0, 4.0], y=[1.0, 3.0, 2.0, 4.0]), dict(x="scndf", y="scndf")),
    # odometry
    M.kitti_segment_errors: (dict(gt_poses=ROUTE, est_poses=ROUTE, lengths=(1.0,), step=1, frame_period=0.1),
                             dict(gt_poses="scndf", est_poses="scndf", lengths="scndf", step="scn",
                                  frame_period="scnf")),
    M.kitti_errors: (dict(gt_poses=ROUTE, est_poses=ROUTE, lengths=(1.0,), step=1),
                     dict(gt_poses="scndf", est_poses="scndf", lengths="scndf", step="scn")),
    M.scaled_lengths: (dict(gt_poses=ROUTE, n=4), dict(gt_poses="scndf", n="scn")),
    M.ate_errors: (dict(gt_poses=ROUTE, est_poses=ROUTE, align="se3"), dict(gt_poses="scndf", est_poses="scndf",
                                                                            align="v")),
    M.ate: (dict(gt_poses=ROUTE, est_poses=ROUTE), dict(gt_poses="scndf", est_poses="scndf")),
    M.rpe_errors: (dict(gt_poses=ROUTE, est_poses=ROUTE, delta=2), dict(gt_poses="scndf", est_poses="scndf", delta="scn")),
    M.rpe: (dict(gt_poses=ROUTE, est_poses=ROUTE, delta=2), dict(gt_poses="scndf", est_poses="scndf", delta="scn")),
    M.umeyama: (dict(src=CUBE, dst=CUBE + 1.0), dict(src="scndf", dst="scndf")),
    # relations and localisation
    M.relation_errors: (dict(poses=REL_P, pairs=np.array([[0, 1], [2, 9]]), reference=RELS[:, 2:]),
                        dict(poses="scndf", pairs="scnd", reference="scndf")),
    M.relation_scores: (dict(trajectories={"a": REL_P}, t_abs=REL_T, relations=RELS, local_gap=3),
                        dict(trajectories="sn", t_abs="scndf", relations="scndf", local_gap="scn")),
    M.heading_error_deg: (dict(est=[0.1, 0.2], truth=[0.0, 0.3]), dict(est="scndf", truth="scndf")),
    M.pose2d_errors: (dict(est=REL_P, truth=REL_P + 0.01), dict(est="scndf", truth="scndf")),
    M.pooled_pose2d_errors: (dict(errors=[[0.1, 1.0], [0.2, 2.0]], fail_m=0.5), dict(errors="scndf", fail_m="scnf")),
    # maps
    M.hit_points: (dict(angles=ANGLES, poses=POSES2D, ranges=RANGES, max_range=30.0),
                   dict(angles="scndf", poses="scndf", ranges="scnd", max_range="scnf")),
    M.beam_cells: (dict(angles=ANGLES, poses=POSES2D, ranges=RANGES, cell=0.1, origin=(-4.0, -4.0), shape=(80, 80),
                        extend=0.0, max_range=30.0),
                   dict(angles="scndf", poses="scndf", ranges="scnd", cell="scnf", origin="scndf", shape="scnd",
                        extend="scnf", max_range="scnf")),
    M.ObservedArea: (dict(angles=ANGLES, poses=POSES2D, ranges=RANGES, tol=0.03, behind=0.3, cell=0.05),
                     dict(angles="scndf", poses="scndf", ranges="scnd", tol="scnf", behind="scnf", cell="scnf")),
    M.scan_hit_counts: (dict(angles=ANGLES, poses=POSES2D, ranges=RANGES, cell=0.05),
                        dict(angles="scndf", poses="scndf", ranges="scnd", cell="scnf")),
    M.sdf_gradient: (dict(sdf=SDF, P=CUBE[:, :2], h=1e-4), dict(sdf="sn", P="scndf", h="scnf")),
    M.angle_deg: (dict(a=CUBE, b=CUBE + 0.1), dict(a="scndf", b="scndf")),
    M.sample_eval_points: (dict(obs=OBS, sdf=SDF, n=10, seed=0, margin=0.5),
                           dict(obs="sn", sdf="sn", n="scn", seed="scn", margin="scnf")),
    M.sdf_map_scores: (dict(d=EVAL["gt"], grad=EVAL["G"], E=EVAL), dict(d="scnd", grad="scnd", E="sn")),
    M.surface_scores_2d: (dict(est=SURF, sdf=SDF, obs=OBS, well_k=1), dict(est="scndf", sdf="sn", obs="sn",
                                                                          well_k="sc")),
    M.classify_worst: (dict(details=DETAILS, sdf=SDF, obs=OBS, corners=np.zeros((1, 2)), top=0.1, corner_r=0.3,
                            sparse_k=1),
                       dict(details="s", sdf="sn", obs="sn", corners="scndf", top="scnf", corner_r="scnf",
                            sparse_k="scn")),
    M.class_report: (dict(err=[0.1, -0.2], var=[0.01, 0.02], classes={"a": np.array([True, False])}, z=1.96),
                     dict(err="scnd", var="scd", classes="sn", z="scnf")),
    M.object_map_scores: (dict(sdf_est=[0.01, 0.0], sdf_true=[0.0, 0.0], dist=[0.001, 0.002],
                               visible=np.array([True, False]), to_surface=[0.001], vertex_grad=np.eye(3)[:1],
                               true_normals=np.eye(3)[:1]),
                          dict(sdf_est="scnd", sdf_true="scndf", dist="scndf", visible="scnd", to_surface="scndf",
                               vertex_grad="scnd", true_normals="scnd")),
    M.polyline_points: (dict(lines=[np.array([[0.0, 0.0], [1.0, 0.0]])], spacing=0.1), dict(lines="sn", spacing="scnf")),
    M.map_scores_2d: (dict(query=lambda P: (SDF(P), np.zeros((len(P), 2)), None), surface=SURF, sdf=SDF, obs=OBS,
                           corners=np.zeros((1, 2)), n_eval=50, seed=0, well_k=1, sparse_k=1, corner_r=0.3),
                      dict(query="sn", corners="scndf", n_eval="scn", seed="scn", well_k="scn", sparse_k="scn",
                           corner_r="scnf")),
    # the speed-error scale of the ground module (issue 34: it took strings and complex numbers)
    M.laplace_scale: (dict(errors=[0.1, -0.2]), dict(errors="scnf")),
}

KINDS = {"s": TypeError, "c": TypeError, "n": TypeError, "d": ValueError, "f": ValueError, "v": ValueError}


def _hostile(v, kind):
    """The hostile variant ``kind`` of a valid argument ``v``."""
    scalar = np.ndim(v) == 0 and not isinstance(v, np.ndarray)
    if kind == "n":
        return None
    if kind == "v":
        return "bogus"
    if kind == "s":
        return "1" if scalar or callable(v) or isinstance(v, (dict, maps.ObservedArea)) else np.full(np.shape(v), "a")
    if kind == "c":
        return complex(v, 1.0) if scalar else np.asarray(v) + 1j
    if kind == "d":
        return np.stack([np.asarray(v)] * 2, axis=-1)
    a = np.array(v, dtype=float)
    a.flat[0] = np.nan
    return float(a) if scalar else a


def _cases():
    for fn, (kw, bad) in CASES.items():
        for arg, kinds in bad.items():
            for kind in kinds:
                yield pytest.param(fn, kw, arg, kind, id=f"{fn.__name__}-{arg}-{kind}")


# The valid call of every case works: the hostile variants fail because of what they change.
@pytest.mark.parametrize("fn", list(CASES), ids=lambda f: f.__name__)
def test_the_valid_call_works(fn):
    fn(**CASES[fn][0])


# A hostile argument raises TypeError (wrong kind) or ValueError (wrong value) naming it.
@pytest.mark.parametrize("fn, kw, arg, kind", list(_cases()))
def test_error_names_the_argument(fn, kw, arg, kind):
    with pytest.raises(KINDS[kind]) as e:
        fn(**{**kw, arg: _hostile(kw[arg], kind)})
    assert re.search(rf"(?<![\w]){re.escape(arg)}(?![\w])", str(e.value)), str(e.value)


# Every public function of the audited modules is in the table (a new one must join it).
def test_every_public_function_is_audited():
    import inspect

    from polar_sim.metrics import localisation, odometry, pose, relations, segmentation, surface

    public = [getattr(m, n) for m in (localisation, maps, odometry, pose, relations, segmentation, surface)
              for n in m.__all__]
    functions = {f for f in public if inspect.isfunction(f) or f is maps.ObservedArea}
    file_io = {M.write_kitti, M.read_kitti, M.write_tum, M.read_tum, M.kitti_errors_pooled}   # tested in test_odometry
    assert functions - file_io - set(CASES) == set()
