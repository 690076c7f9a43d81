"""GroundVO.published(): the published code's behaviour (spec §10) as stage configs, the one route to it.

Every check here is against the spec's description of the published code, not against a second
route to the same behaviour.
"""

import numpy as np
import pytest

from ground_helpers import HEIGHT, run
from polar_sim.ground import GroundVO, fit_ground
from polar_sim.ground.vo import STAGE_CONFIGS

#: (stage, field) of every switch between the spec with its fixes and the published code.
SWITCHES = [("tracking", "track_gates"), ("motion", "depth_fusion"), ("ground", "ransac_draw"), ("filters", "rules"),
            ("filters", "pose_steps"), ("classifier", "hue_wrap"), ("classifier", "ground_labels")]


@pytest.fixture(scope="module")
def published_run(corridor):
    vo = GroundVO.published(corridor["K"], corridor["camera_height"], seed=0)
    return vo, run(vo, corridor, range(10))


# The preset is each stage config's published values, with the values that depend on other settings
# (B18's iteration count per model, the speed filter's P0 = 2 q) following the overrides.
def test_published_preset_is_the_stage_configs(corridor):
    p = GroundVO.published(corridor["K"], 1.0).get_params(deep=True)
    assert all(p[f"{s}__{f}"] == "published" for s, f in SWITCHES)
    assert p["ground__n_iter"] == 99 and p["ground__weight_exponent"] == 2.0  # B18, B11
    assert p["motion__irls_iter"] == 0 and not p["motion__exact_flow"] and p["motion__n_global"] == 3  # B1, B4
    assert p["motion__slip"] == 0.0  # the camera moves along its optical axis (spec §3.1)
    assert p["filters__speed_prior_var"] == pytest.approx(2 * p["filters__speed_q"])
    assert p["classifier__ng_from_outliers"] is False and p["classifier__sky_labels"] == 0  # B9; no sky labels
    assert p["classifier__train_depth"] is None and p["classifier__decay_samples"] is None
    assert p["calibration__method"] == "none" and p["dense__enabled"] is False  # no dense stage in the paper
    assert GroundVO.published(corridor["K"], 1.0, model="2param").ground.n_iter == 16
    assert GroundVO.published(corridor["K"], 1.0, filters__speed_q=0.5).filters.speed_prior_var == 1.0
    assert GroundVO.published(corridor["K"], 1.0, filters__speed_q=0.5, filters__speed_prior_var=7.0) \
        .filters.speed_prior_var == 7.0


# Run on the corridor, the preset shows the published code's counts and pose steps: 99 RANSAC
# iterations (B18), no IRLS (B1), frames 0 and 1 both at the origin (B27).
def test_published_run_follows_the_spec(published_run):
    vo, es = published_run
    ok = [e for e in es if e.status == "ok"]
    assert ok and all(e.diagnostics["ransac_iterations"] == 99 and e.diagnostics["irls_iterations"] == 0 for e in ok)
    traj = vo.trajectory()
    assert np.array_equal(traj[0], np.eye(4)) and np.array_equal(traj[1], np.eye(4))
    assert not any(e.diagnostics["pose_provisional"] for e in es)


# B11 and the cumulative draw: re-fitting a frame's candidates offline with weights P_G² and the
# published draw (compat="code" of fit_ground), from the same generator state, gives its inliers.
def test_published_ransac_draws_by_squared_probability(corridor):
    vo = GroundVO.published(corridor["K"], corridor["camera_height"], seed=0)
    run(vo, corridor, range(5))
    state = vo.rng_.bit_generator.state
    e = vo.process(corridor["rgb"][5], corridor["times"][5])
    assert e.status == "ok" and np.all(e.candidate_prob > 0)
    rng = np.random.default_rng()
    rng.bit_generator.state = state
    u, v = e.candidate_uv.T
    fit = fit_ground(u, v, e.candidate_dbar, HEIGHT, model="6param", weights=e.candidate_prob ** 2, n_iter=99, rng=rng,
                     compat="code")
    assert fit.speed == e.speed_raw and np.array_equal(fit.inliers, e.inlier_mask)


def test_published_differs_from_the_default(corridor):
    K, h = corridor["K"], corridor["camera_height"]
    a = run(GroundVO.published(K, h), corridor, range(8))
    b = run(GroundVO(K, h), corridor, range(8))
    assert any(not np.array_equal(x.ground_prob, y.ground_prob) for x, y in zip(a, b))


# A bad switch value raises naming stage__field, in published() and set_params(); the object is unchanged.
@pytest.mark.parametrize("stage, name", SWITCHES)
def test_a_bad_switch_names_the_parameter_and_set_params_leaves_the_object(corridor, stage, name):
    key = f"{stage}__{name}"
    with pytest.raises(ValueError, match=key):
        GroundVO.published(corridor["K"], 1.0, **{key: "code"})
    vo = GroundVO(corridor["K"], 1.0)
    with pytest.raises(ValueError, match=key):
        vo.set_params(**{key: 1})
    assert getattr(getattr(vo, stage), name) == "fixed"
    vo.set_params(**{key: "published"})
    assert vo.get_params()[key] == "published"


def test_published_rejects_an_unknown_override(corridor):
    for bad in ("bogus", "tracking__bogus", "nostage__x"):
        with pytest.raises(ValueError, match=bad):
            GroundVO.published(corridor["K"], 1.0, **{bad: 1})


# A whole stage config given to published() replaces the stage's preset; fields then apply on top.
def test_published_takes_a_whole_config(corridor):
    cfg = STAGE_CONFIGS["calibration"](method="platt", window=3)
    vo = GroundVO.published(corridor["K"], 1.0, calibration=cfg, calibration__decay=0.5)
    assert vo.calibration.method == "platt" and vo.calibration.window == 3 and vo.calibration.decay == 0.5
