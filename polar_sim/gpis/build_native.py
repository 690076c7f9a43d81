"""Compile the GPIS kernels ahead of time (``polar-sim compile``; see :mod:`polar_sim.gpis._native`).

:func:`build` runs a small workload under numba's JIT (planar maps in both modes, ICP-G, a depth
camera map, surfaces, a save and load) so that every kernel Python calls is typed with the
arguments of real use, then compiles those kernels, with everything they call, for this CPU into
one extension module with ``numba.pycc``. It needs a C compiler (the module's init code is C) and
takes about a minute of CPU; afterwards a fresh process runs the default path without compiling.
A kernel the workload typed with more than one signature stays with the JIT.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["build", "workload"]


def _room_ranges(pose, angles):
    """Ranges of a laser at pose (x, y, theta) in the room [-4, 4] x [-3, 3] with a disc of radius
    0.5 at (1.5, 0.8) (exact ray casts)."""
    a = pose[2] + angles
    d = np.stack([np.cos(a), np.sin(a)], 1)
    o = np.asarray(pose[:2], float)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(d[:, 0] > 0, (4.0 - o[0]) / d[:, 0], (-4.0 - o[0]) / d[:, 0])
        ty = np.where(d[:, 1] > 0, (3.0 - o[1]) / d[:, 1], (-3.0 - o[1]) / d[:, 1])
    r = np.minimum(tx, ty)
    c = o - np.array([1.5, 0.8])
    b = (d @ c)
    disc = b * b - (c @ c - 0.25)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc > 0) & (t > 0), np.minimum(r, t), r)


def _sphere_depth(T, K, shape):
    """Planar depth (H, W) of a sphere of radius 0.1 at the origin seen by camera T (OpenCV axes)."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w].astype(float)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    dw = rays @ T[:3, :3].T
    o = T[:3, 3]
    a = (dw * dw).sum(-1)
    b = 2 * (dw @ o)
    disc = b * b - 4 * a * (o @ o - 0.01)
    z = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a)
    return np.where(disc > 0, z, 0.0).astype(np.float32)


def _look_at(eye):
    f = -np.asarray(eye, float) / np.linalg.norm(eye)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    T = np.eye(4)
    T[:3, :3] = np.stack([r, np.cross(f, r), f], 1)
    T[:3, 3] = eye
    return T


def workload():
    """Call every GPIS kernel the way the library does (types recorded by numba's dispatchers)."""
    from polar_sim.gpis import GPISMap2D, GPISMap3D
    from polar_sim.gpis.localize import localize

    ang = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 270)
    rng = np.random.default_rng(0)
    for m in (GPISMap2D(), GPISMap2D.published()):
        for k in range(6):
            pose = np.array([-1.0 + 0.4 * k, -1.0 + 0.2 * k, 0.3 * k])
            m.update(ang, _room_ranges(pose, ang), pose)
        m.query(rng.uniform(-4, 4, (500, 2)))
        localize(m, (ang, _room_ranges(pose, ang)), pose + [0.03, -0.02, 0.01])
        m.surface()
        with tempfile.TemporaryDirectory() as d:
            m.save(Path(d) / "m.npz")
            type(m).load(Path(d) / "m.npz").query(rng.uniform(-4, 4, (10, 2)))
    K = np.array([[120.0, 0.0, 80.0], [0.0, 120.0, 60.0], [0.0, 0.0, 1.0]])
    m3 = GPISMap3D()
    for eye in ([0.5, 0.1, 0.2], [0.1, 0.5, 0.2], [-0.4, 0.3, 0.3]):
        T = _look_at(eye)
        m3.update(_sphere_depth(T, K, (120, 160)), K, T)
    m3.query(rng.uniform(-0.15, 0.15, (500, 3)))
    m3.surface(res=0.01, band=0.02)


def build(out_dir=None, verbose=False):
    """Compile the kernels into ``out_dir`` (default :func:`polar_sim.gpis._native.native_dir`);
    returns the module's path. Run in a process that has not called a GPIS kernel yet."""
    os.environ["POLAR_SIM_NATIVE"] = "0"            # type everything under the JIT
    from numba.core import types

    from polar_sim.gpis import _native

    t0 = time.perf_counter()
    workload()
    key = _native.source_key()
    out = Path(out_dir) if out_dir is not None else _native.native_dir()
    out.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")              # numba.pycc is "pending deprecation"
        from numba.pycc import CC
    cc = CC(_native.module_name(key))
    cc.output_dir = str(out)
    cc.target_cpu = "host"
    cc.verbose = verbose
    skipped = []
    for name, disp in sorted(_native._REGISTRY.items()):
        sigs = disp.signatures
        if len(sigs) != 1:
            skipped.append(f"{name} ({len(sigs)} signatures)")
            continue
        if disp.targetoptions.get("fastmath") or disp.targetoptions.get("parallel"):
            raise RuntimeError(f"{name}: an entry kernel must not set fastmath/parallel itself")
        ret = disp.overloads[sigs[0]].signature.return_type
        cc.export(name, ret(*[types.unliteral(a) for a in sigs[0]]))(disp.py_func)
    if skipped:
        logger.info("left to the JIT: %s", ", ".join(skipped))
    t1 = time.perf_counter()
    cc.compile()
    path = next(out.glob(_native.module_name(key) + "*"))
    logger.info("typed in %.1f s, compiled in %.1f s: %s", t1 - t0, time.perf_counter() - t1, path)
    return path, skipped
