"""Replay a visual odometry over recorded frames and keep, per frame, what is scored.

Works with any ``vo`` plug-in (``polar_sim.runner.methods``): an object with ``process(rgb, t)``
returning a result with ``pose`` and optionally ``speed``, ``yaw_rate``, ``speed_raw``,
``rates_raw``, ``status``, ``ground_prob`` (the fields of :class:`polar_sim.ground.GroundEstimate`;
missing ones are NaN). Frames are dicts with ``rgb`` (H, W, 3) uint8 and ``t`` (s), e.g. from
``RecordingReader.frames()``; nothing here imports the simulator.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["replay"]

_SCALARS = ("speed", "yaw_rate", "speed_raw", "yaw_rate_raw")


def replay(vo, frames, *, on_frame=None):
    """Feed ``frames`` (an iterable of ``(index, frame)`` or of frames) through ``vo.process``.

    ``on_frame(i, frame, estimate, previous_frame)`` is called after every image (the estimate of
    image i describes the middle frame i - 1, whose frame is ``previous_frame``; None for i = 0), for
    scoring that needs the images or the truth. Returns a dict of per-frame arrays: ``speed``,
    ``yaw_rate``, ``speed_raw``, ``yaw_rate_raw`` (n,), ``rates_raw`` (n, 3), ``status`` (n,) str,
    ``cpu_ms`` (n,) process CPU time of ``process``, ``times`` (n,), and ``poses`` (n, 4, 4): the
    estimator's ``trajectory()`` if it has one (GroundVO revises pose 1 once image 2 arrives), else
    the per-image poses.
    """
    cols = {k: [] for k in _SCALARS}
    rates, status, cpu, times, poses = [], [], [], [], []
    prev = None
    for i, item in enumerate(frames):
        f = item[1] if isinstance(item, tuple) else item
        t = float(f["t"])
        c0 = time.process_time()
        e = vo.process(f["rgb"], t)
        cpu.append((time.process_time() - c0) * 1e3)
        for k in _SCALARS:
            cols[k].append(float(getattr(e, k, np.nan)))
        r = getattr(e, "rates_raw", None)
        rates.append(np.full(3, np.nan) if r is None else np.asarray(r, dtype=np.float64))
        status.append(str(getattr(e, "status", "")))
        times.append(t)
        poses.append(np.asarray(e.pose, dtype=np.float64))
        if on_frame is not None:
            on_frame(i, f, e, prev)
        prev = f
    out = {k: np.array(v, dtype=np.float64) for k, v in cols.items()}
    out.update(rates_raw=np.array(rates).reshape(-1, 3), status=np.array(status, dtype=str),
               cpu_ms=np.array(cpu), times=np.array(times))
    traj = getattr(vo, "trajectory", None)
    out["poses"] = np.asarray(traj()) if callable(traj) else np.array(poses).reshape(-1, 4, 4)
    return out
