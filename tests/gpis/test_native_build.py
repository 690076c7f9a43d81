"""``polar-sim compile``'s module gives the JIT's answers (the README tells users to build it, and the
CI otherwise never runs it): build it into a temporary folder, then map, query (contiguous and
strided points), trace the surface and localise in a process that uses it and in one that does
not, and compare."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

# the same work in both processes: ten scans of the analytic room, a query at 400 points near the
# samples, the same through a reversed (strided) view, the surface's vertices, an ICP-G pose
_WORK = textwrap.dedent("""
    import json, sys
    import numpy as np
    sys.path.insert(0, {tests!r})
    from gpis.scenes import room_path, scan_2d
    from polar_sim.gpis import GPISMap2D
    from polar_sim.gpis._native import K
    from polar_sim.gpis.localize import localize

    ang = np.deg2rad(np.arange(-135.0, 135.0, 1.0))
    m = GPISMap2D()
    for pose in room_path(10):
        m.update(ang, scan_2d(pose, ang), pose)
    rng = np.random.default_rng(0)
    s = m.samples()["points"]
    pts = s[rng.integers(0, len(s), 400)] + rng.normal(scale=0.1, size=(400, 2))
    out = {{"compiled": bool(K.compiled), "query": np.concatenate(m.query(pts)[:2], axis=None).tolist(),
           "gp": m._gp_query(pts).tolist(), "gp_strided": m._gp_query(pts[::-1])[::-1].tolist(),
           "surface": np.vstack(m.surface()).tolist(), "runs": m.tree_.run[m.tree_.alive()].tolist()}}
    pose = room_path(10)[3]
    out["pose"] = np.asarray(localize(m, (ang, scan_2d(pose, ang)), pose + np.array([0.05, -0.03, 0.02]))[0],
                             float).tolist()
    print(json.dumps(out))
""")


def _run(code, env):
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    return p.stdout


@pytest.mark.slow
def test_the_compiled_module_gives_the_jits_answers(tmp_path):
    env = {**os.environ, "POLAR_SIM_NATIVE_DIR": str(tmp_path)}
    _run("from polar_sim.gpis.build_native import build; build()", env)
    assert list(tmp_path.glob("_gpis_native_*"))
    work = _WORK.format(tests=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    aot = json.loads(_run(work, env).splitlines()[-1])
    jit = json.loads(_run(work, {**env, "POLAR_SIM_NATIVE": "0"}).splitlines()[-1])
    assert aot["compiled"] and not jit["compiled"]
    for k in ("query", "gp", "gp_strided", "surface", "runs", "pose"):
        a, b = np.asarray(aot[k], float), np.asarray(jit[k], float)
        assert a.shape == b.shape, k
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, err_msg=k)
    np.testing.assert_array_equal(np.asarray(aot["gp_strided"]), np.asarray(aot["gp"]))
