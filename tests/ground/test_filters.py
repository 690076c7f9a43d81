import numpy as np

from polar_sim.ground.filters import KF1D


def _steady(q, r):
    kf = KF1D(0.0, 1.0, q, r)
    for _ in range(500):
        kf.predict()
        k = kf.update(0.0)
    return kf.P, k


def test_kf_steady_state_matches_spec_t3():
    # T3: speed filter (q 0.15, r 3) -> P 0.600, gain 0.200; yaw filter (q 2, r 5) -> P 2.317, gain 0.463.
    P, k = _steady(0.15, 3.0)
    assert round(P, 3) == 0.600 and round(k, 3) == 0.200
    P, k = _steady(2.0, 5.0)
    assert round(P, 3) == 2.317 and round(k, 3) == 0.463


def test_kf_adaptive_rules():
    # Published rule: innovation beyond sqrt(r) sets r = innovation²; the fixed rule subtracts the prior variance.
    code = KF1D(0.0, 0.6, 0.15, 3.0, adaptive="code")
    k, r = code.gain(4.0)
    assert r == 16.0 and np.isclose(k, 0.6 / 16.6)
    assert code.gain(1.0)[1] == 3.0
    fixed = KF1D(0.0, 25.0, 0.15, 3.0, adaptive="innovation")
    k, r = fixed.gain(8.0)
    assert r == 64.0 - 25.0 and np.isclose(k, 25.0 / 64.0)
    # A converged filter (small P) behaves like the published rule within P.
    small = KF1D(0.0, 0.6, 0.15, 3.0, adaptive="innovation")
    assert np.isclose(small.gain(4.0)[1], 16.0 - 0.6)


def test_kf_from_wide_prior_converges_on_constant_measurements():
    # From x0 = 0 with P0 = 25 (the fixed default prior) a constant 8 m/s is adopted within a few frames.
    kf = KF1D(0.0, 25.0, 0.15, 3.0, adaptive="innovation")
    for _ in range(10):
        kf.predict()
        kf.update(8.0)
    assert abs(kf.x - 8.0) < 0.3


def test_kf_measurement_variance_above_the_nominal_noise_is_used():
    # A measurement with its own variance larger than r is fused with that variance (and the adaptive
    # rule starts from it); a smaller one keeps the nominal r, so variance 0 is the plain update.
    kf = KF1D(0.0, 2.0, 0.15, 3.0, adaptive="innovation")
    assert kf.gain(1.0, var=30.0) == (2.0 / 32.0, 30.0)
    assert kf.gain(1.0, var=0.5) == kf.gain(1.0) == (2.0 / 5.0, 3.0)
    k, r = kf.gain(10.0, var=30.0)  # innovation² 100 > P + 30: r = 100 - P
    assert r == 98.0
    kf.update(1.0, var=30.0)
    assert np.isclose(kf.x, 2.0 / 32.0) and np.isclose(kf.P, 30.0 * 2.0 / 32.0)
