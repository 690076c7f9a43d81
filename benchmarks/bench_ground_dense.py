"""``vo`` plug-ins for the dense ground alignment's dev comparison (issue 35, item 1).

GroundVO's default runs the dense alignment (``DenseConfig``); these plug-ins are the variants it was
compared with on ``dev`` routes, for ``polar-sim run ground_odometry`` / ``ground_appearance`` (run
from the repository root)::

    PYTHONPATH=. polar-sim run ground_odometry --split dev --set 'method=[w6,benchmarks.bench_ground_dense:w6_nodense]'

- ``w6_nodense``: w6 without the dense stage (bit-identical to w6 before the dense stage existed).
- ``w6_nolabels``: w6 with the dense speed but without the dense ground self-labels.
- ``w6_plane``: w6 with the dense fit's plane model (no pitch change between images, no side slope).
- ``w6_pitch``: w6 with the dense fit's pitch model (no side slope: the default before 2026-12-07).
- ``w6_nosky``: w6 without the non-ground self-labels above the horizon (``ClassifierConfig(sky_labels=0)``:
  the default before 2026-12-07's eleventh session); ``w6_sky30``, ``w6_sky50``, ``w6_sky300``: other
  numbers of them, and ``w6_sky300m05`` 300 from 0.05 rad above the horizon (the default: 100 from 0.1 rad).
- ``w6_slip0``, ``w6_slip05``, ``w6_slip10``, ``w6_slip15``: w6 with the camera's sideways slip
  ``MotionConfig(slip=...)`` of 0, 0.005, 0.01 and 0.015 s (the experiments give the built-in w6 the
  rover's, ``ROVER_SLIP`` = 0.01). In the dev sweep of 2026-12-07 (twelfth session) only the tracks' flow
  model took the slip; the dense fit took it afterwards, and the sweep was not re-run.
- ``w6_smooth20``: w6 (with the rover's slip, as the built-in one) whose dense fit smooths its pyramid by
  2 px instead of 1 (``DenseConfig(smoothing=2.0)``; 2026-12-07, thirteenth session).

Each runs at the working size and with the 3-D integration that the experiments give the built-in
``w6`` (``downsample=1``, ``integration="3d"``); a plug-in gets only the protocol from them. (Before
2026-12-07 these plug-ins ran at GroundVO's own defaults, ``downsample=2`` and planar integration, so
the ``w6_nodense`` rows in ``benchmarks/RESULTS.md`` from 2026-12-06 compare unequal settings.)
"""


def _w6(K, camera_height, seed, params, classifier=None, motion=None, **dense):
    from polar_sim.ground import ClassifierConfig, DenseConfig, GroundVO, MotionConfig

    params.setdefault("downsample", 1)
    params.setdefault("integration", "3d")
    return GroundVO(K, camera_height, model="6param", sampling="weighted", seed=seed, dense=DenseConfig(**dense),
                    classifier=ClassifierConfig(**(classifier or {})), motion=MotionConfig(**(motion or {})),
                    **params)


def w6_nodense(K, camera_height, *, seed=0, **params):
    """w6 without the dense ground alignment."""
    return _w6(K, camera_height, seed, params, enabled=False)


def w6_nolabels(K, camera_height, *, seed=0, **params):
    """w6 with the dense speed, without the dense ground self-labels."""
    return _w6(K, camera_height, seed, params, label_evidence=0.0)


def w6_plane(K, camera_height, *, seed=0, **params):
    """w6 with the dense fit's plane model (arc length and yaw change only)."""
    return _w6(K, camera_height, seed, params, model="plane")


def w6_pitch(K, camera_height, *, seed=0, **params):
    """w6 with the dense fit's pitch model (arc length, yaw change and pitch change; a level ground)."""
    return _w6(K, camera_height, seed, params, model="pitch")


def w6_nosky(K, camera_height, *, seed=0, **params):
    """w6 without the sky labels (``ClassifierConfig(sky_labels=0)``)."""
    return _w6(K, camera_height, seed, params, classifier={"sky_labels": 0})


def _sky(n, margin=0.1):
    def make(K, camera_height, *, seed=0, **params):
        return _w6(K, camera_height, seed, params, classifier={"sky_labels": n, "sky_margin": margin})

    make.__doc__ = f"w6 with {n} sky labels from {margin} rad above the horizon."
    return make


w6_sky30, w6_sky50, w6_sky300, w6_sky300m05 = _sky(30), _sky(50), _sky(300), _sky(300, 0.05)


def _slip(k):
    def make(K, camera_height, *, seed=0, **params):
        return _w6(K, camera_height, seed, params, motion={"slip": k})

    make.__doc__ = f"w6 with the camera's sideways slip {k} s (``MotionConfig(slip=...)``)."
    return make


w6_slip0, w6_slip05, w6_slip10, w6_slip15 = _slip(0.0), _slip(0.005), _slip(0.010), _slip(0.015)


def _smooth(s):
    def make(K, camera_height, *, seed=0, **params):
        from polar_sim.sim.recorders.rover_sequences import ROVER_SLIP

        return _w6(K, camera_height, seed, params, motion={"slip": ROVER_SLIP}, smoothing=s)

    make.__doc__ = (f"w6 with the dense fit's pyramid smoothed by {s} px (``DenseConfig(smoothing=...)``) and the "
                    "rover's slip, as the built-in w6 has it.")
    return make


w6_smooth20 = _smooth(2.0)
