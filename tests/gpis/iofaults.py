"""Fault harnesses for GPIS map files (issue 17, "Saved state"), shared by tests/gpis/test_io.py
and benchmarks/bench_gpis_io.py.

* :func:`kill_mid_save`: a subprocess re-saves a map over one path in a loop and is SIGKILLed at
  random (seeded) moments; after every kill the file must load and answer exactly like the map.
* :func:`tamper_cases` / :func:`run_tampered`: tampered copies of valid 2D and 3D map files,
  re-saved with ``np.savez`` (valid zip checksums): out-of-range indices (dtype max/min, -1/-2,
  one past the end), NaN/inf in float arrays, wrong shapes and dtypes, missing and extra keys,
  object arrays, wrong versions. Each is loaded, and if accepted updated and queried, in a worker
  subprocess with a time limit (many cases per worker): a crash or hang is recorded against the
  case, and a new worker goes on from the next one.

    python -m tests.gpis.iofaults tamper-worker BASE_DIR NAMES START STOP [selftest]   # (internal) one worker
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
ANG = np.deg2rad(np.arange(-135.0, 135.0, 1.0))


# -- valid maps ------------------------------------------------------------------------------------
def make_maps(n2=6, n3=2):
    """Valid maps: 2D default, 2D published (free lists in use), 3D default."""
    sys.path.insert(0, str(ROOT / "tests"))
    from gpis.scenes import intrinsics, orbit_poses, render_sphere, room_path, scan_2d

    from polar_sim.gpis import GPISMap2D, GPISMap3D

    out = {}
    # the published map of 20 room scans has removed samples and a freed slot: the free lists are
    # in use (and tampered)
    for name, m, n in (("2d", GPISMap2D(), n2), ("2d_legacy", GPISMap2D.published(sensor_offset=(0.08, 0.0)), 20)):
        for pose in room_path(n):
            m.update(ANG, scan_2d(pose, ANG), pose)
        out[name] = m
    m = GPISMap3D()
    K = intrinsics(160, 120, 130.0)
    for T in orbit_poses(n3):
        m.update(render_sphere(T, K, 160, 120), K, T)
    out["3d"] = m
    return out


def write_bases(folder, **kw):
    """Save :func:`make_maps` into ``folder`` (``<name>.npz``); returns the names."""
    folder = Path(folder)
    maps = make_maps(**kw)
    for name, m in maps.items():
        m.save(folder / f"{name}.npz")
    return list(maps)


def _cls(name):
    from polar_sim.gpis import GPISMap2D, GPISMap3D

    return GPISMap3D if name.startswith("3d") else GPISMap2D


# -- kill mid-save ---------------------------------------------------------------------------------
_SAVER = """
import sys, time
from polar_sim.gpis import GPISMap2D, GPISMap3D
cls = GPISMap3D if sys.argv[3] == '3' else GPISMap2D
m = cls.load(sys.argv[1])
t = time.perf_counter(); m.save(sys.argv[2]); dt = time.perf_counter() - t
print('ready', dt, flush=True)
while True:
    m.save(sys.argv[2])
"""


def kill_mid_save(ref, target, n_kills, *, dim=3, seed=0):
    """Kill a re-saving subprocess ``n_kills`` times; return a list of (delay_s, ok, message,
    mid_write), ``mid_write`` True when the kill left the writer's temporary file (it landed
    while a save was under way).

    ``ref`` is a valid map file; the worker loads it and re-saves it over ``target`` in a loop,
    and is SIGKILLed ``delay`` seconds (uniform over two save times, seeded) after it reports its
    first save. After each kill ``target`` must load and answer queries exactly like ``ref``.
    """
    cls = _cls("3d" if dim == 3 else "2d")
    want = cls.load(ref)
    pts = want.samples()["points"][:64] + 0.002
    q0 = want.query(pts)
    rng = np.random.default_rng(seed)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    out = []
    for _ in range(n_kills):
        p = subprocess.Popen([sys.executable, "-c", _SAVER, str(ref), str(target), str(dim)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        line = p.stdout.readline().split()
        if not line or line[0] != "ready":
            p.kill()
            raise RuntimeError(f"saver did not start: {p.stderr.read()[-2000:]}")
        delay = float(rng.uniform(0.0, 2.0 * float(line[1])))
        time.sleep(delay)
        p.send_signal(signal.SIGKILL)
        p.wait()
        # a killed writer's temporary file shows that the kill landed mid-write; remove it
        tmps = list(Path(target).parent.glob(f".{Path(target).name}.*.tmp"))
        for t in tmps:
            t.unlink()
        mid = bool(tmps)
        try:
            got = cls.load(target)
            q = got.query(pts)
            ok = all(np.array_equal(a, b) for a, b in zip(q, q0))
            out.append((delay, ok, "" if ok else "answers differ", mid))
        except Exception as exc:  # noqa: BLE001 - any failure to load is what is counted
            out.append((delay, False, f"{type(exc).__name__}: {exc}", mid))
    return out


# -- tampered files --------------------------------------------------------------------------------
_META = ("format", "version", "cls", "params", "fitted")


def _imax(a):
    return np.iinfo(a.dtype).max


def _imin(a):
    return np.iinfo(a.dtype).min


def tamper_cases(data, dim):
    """Tamperings of one valid fitted map's arrays ``data``: list of (label, fn(dict) -> dict).

    Every tampering makes the file invalid (an index out of range, a non-finite GP or sample
    value, a wrong shape, dtype, key set or version); none is a no-op.
    """
    c = data["tree/counts"]
    n_hw, n_free, k_hw, k_free = (int(x) for x in c)
    ns = data["tree/node_sample"]
    live = ns[:k_hw][ns[:k_hw] >= 0]
    used = np.flatnonzero(data["tree/cgrid"] >= 0)
    gm = data["gp/gp_m"]
    lgp = np.flatnonzero(gm > 0)
    kinds = data["gp/kinds"]
    # gradient observations of live GPs (retraining leaves dead stretches in the buffers, which
    # no GP reads, so a change there is harmless and rightly accepted)
    in_live = np.zeros(len(kinds), bool)
    for s in lgp:
        in_live[data["gp/gp_obs"][s]:data["gp/gp_obs"][s] + gm[s]] = True
    grad_obs = np.flatnonzero(((kinds >> 32) > 0) & in_live)
    nn = ns.shape[1]
    cases = []

    def setv(key, idx, val, label):
        def fn(d, key=key, idx=idx, val=val):
            a = d[key].copy()
            a[idx] = val
            d[key] = a
            return d
        cases.append((f"{key}[{idx}]={label}", fn))

    i_live = int(live[len(live) // 2])
    s_used = int(data["tree/cgrid"][used[len(used) // 2]])
    r, col = np.argwhere(ns[:k_hw] >= 0)[len(live) // 3]
    for val, lab in ((None, "max"), ("min", "min"), (-2, "-2"), (n_hw, "n_samples"), (n_hw + 1000, "past-end")):
        v = _imax(ns) if val is None else (_imin(ns) if val == "min" else val)
        setv("tree/node_sample", (int(r), int(col)), v, lab)
    setv("tree/node_sample", (0, 0), _imax(ns), "max@root")
    for g in (int(used[0]), int(used[-1])):
        for v, lab in ((_imax(data["tree/cgrid"]), "max"), (_imin(data["tree/cgrid"]), "min"), (-2, "-2"), (k_hw, "n_slots")):
            setv("tree/cgrid", g, v, lab)
    deep = int(data["tree/node_internal"].shape[1]) - 1
    setv("tree/node_internal", (s_used, deep), 1, "split-at-max-depth")
    setv("tree/node_internal", (s_used, int(col) if ns[s_used, int(col)] >= 0 else 0), 2, "2")
    setv("tree/node_internal", (int(r), int(col)), 1, "internal-with-sample")
    setv("tree/node_internal", (s_used, 0), 255, "255")
    for key, bound in (("tree/s_slot", ns.shape[0]), ("tree/s_node", nn)):
        a = data[key]
        for v, lab in ((_imax(a), "max"), (_imin(a), "min"), (-2, "-2"), (bound, "past-end"), (-1, "-1")):
            setv(key, i_live, v, lab)
    if n_free:
        for v, lab in ((_imax(data["tree/s_free"]), "max"), (-1, "-1"), (n_hw, "n_samples"), (i_live, "live")):
            setv("tree/s_free", 0, v, lab)
    if k_free:
        for v, lab in ((_imax(data["tree/slot_free"]), "max"), (-1, "-1"), (k_hw, "n_slots"), (s_used, "used")):
            setv("tree/slot_free", 0, v, lab)
    N, S = data["tree/pos"].shape[0], ns.shape[0]
    for j, bad in enumerate(((-1, "-1"), (np.iinfo(np.int64).max, "max"), (N + 1, "past-end"))):
        for k in range(4):
            lim = (N, n_hw, S, k_hw)[k]
            v = bad[0] if bad[1] != "past-end" else lim + 1
            setv("tree/counts", k, v, bad[1])
    for key in ("tree/gshape", "free/gshape"):
        for v, lab in ((0, "0") if key == "tree/gshape" else (-1, "-1"), (-1, "-1"), (np.iinfo(np.int64).max, "max"),
                       (int(data[key][0]) + 1, "+1")):
            setv(key, 0, v, lab)
    for key in ("tree/goff", "free/goff"):
        for v, lab in ((np.iinfo(np.int64).max, "max"), (np.iinfo(np.int64).min, "min")):
            setv(key, 0, v, lab)
        setv(key, 0, int(data[key][0]) + 1 if key == "tree/goff" else np.iinfo(np.int64).max // 2, "shifted")
    for v, lab in ((np.iinfo(np.int64).max, "max"), (np.iinfo(np.int64).min, "min"), (10 ** 6, "outside-grid")):
        setv("tree/slot_coord", (s_used, 0), v, lab)
    g = int(lgp[len(lgp) // 2])
    O, T = data["gp/X"].shape[0], data["gp/Lbuf"].shape[0]
    for key, end in (("gp/gp_obs", O), ("gp/gp_tri", T), ("gp/gp_m", O)):
        for v, lab in ((np.iinfo(np.int64).max, "max"), (np.iinfo(np.int64).min, "min"), (-1, "-1"), (end + 1, "past-end")):
            setv(key, g, v, lab)
    setv("gp/gp_m", int(lgp[-1]), int(gm[lgp[-1]]) + 1, "one-too-many")
    if len(grad_obs):
        o = int(grad_obs[len(grad_obs) // 2])
        for v, lab in ((np.iinfo(np.int64).max, "max"), (np.iinfo(np.int64).min, "min"), ((dim + 1) << 32, "component"),
                       ((1 << 32) | 0xFFFFFFFF, "sample"), (-1, "-1")):
            setv("gp/kinds", o, v, lab)
    for key in ("slot_gen", "gp_gen"):
        for v, lab in ((-1, "-1"), (np.iinfo(np.int64).min, "min")):
            setv(key, 0, v, lab)
    setv("tree/geo", dim, 0.0, "zero-cell")
    setv("tree/root", dim, 1e300, "huge-root")
    setv("tree/pos", (i_live, 0), 1e6, "outside-cell")
    setv("tree/sp", i_live, -1.0, "negative-variance")
    if "tree/run" in data:          # +inf is a run that went on (a file before version 3)
        setv("tree/run", (i_live, 0), np.nan, "nan")
        setv("tree/run", (i_live, 1), -0.1, "negative-run")
    # non-finite values
    for key, idx in (("tree/pos", (i_live, 0)), ("tree/nrm", (i_live, 1)), ("tree/sp", i_live), ("tree/sg", i_live),
                     ("tree/pos_t", (i_live, 0)), ("tree/sg_t", i_live), ("gp/X", (O // 2, 0)), ("gp/alpha", O // 2),
                     ("gp/Lbuf", T // 2), ("gp/Lbuf", 0), ("tree/geo", 0), ("tree/root", 0)):
        for v, lab in ((np.nan, "nan"), (np.inf, "inf"), (-np.inf, "-inf")):
            setv(key, idx, v, lab)
    # wrong shapes and dtypes
    state = [k for k in data if k not in _META]
    for key in state:
        a = data[key]
        if a.ndim and a.shape[0] > 1:
            cases.append((f"{key}:drop-last", lambda d, key=key: {**d, key: d[key][:-1]}))
        if a.ndim == 2 and a.shape[0] != a.shape[1]:
            cases.append((f"{key}:transposed", lambda d, key=key: {**d, key: np.ascontiguousarray(d[key].T)}))
        cases.append((f"{key}:extra-axis", lambda d, key=key: {**d, key: d[key][..., None]}))
        to = np.float32 if a.dtype.kind == "f" else (np.float64 if a.dtype.kind in "iu" else np.int64)
        cases.append((f"{key}:dtype-{np.dtype(to).name}", lambda d, key=key, to=to: {**d, key: d[key].astype(to)}))
        if a.dtype.kind in "iu" and a.dtype.itemsize > 1:
            cases.append((f"{key}:byteswapped", lambda d, key=key: {**d, key: d[key].astype(d[key].dtype.newbyteorder())}))
        cases.append((f"{key}:object", lambda d, key=key: {**d, key: np.array(list(d[key].ravel()[:3]) + [None], dtype=object)}))
    for key in list(data):
        cases.append((f"{key}:missing", lambda d, key=key: {k: v for k, v in d.items() if k != key}))
    cases.append(("extra-key", lambda d: {**d, "tree/evil": np.arange(3)}))
    return cases + _header_cases()


def _header_cases():
    """Tampered header scalars: version, format, class, fitted flag, parameters, update count."""
    from polar_sim.gpis._io import VERSION

    cases = []
    # the next format version, unknown to this reader (a fixed number became the current version)
    for v, lab in ((np.array("1"), "str"), (np.array(1.5), "float"), (np.array(True), "bool"),
                   (np.array(VERSION + 1), "next"),
                   (np.array(1), "1"), (np.array(-1), "-1"), (np.array([1]), "array"), (np.array(1.0), "float-1.0"),
                   (np.array(None, dtype=object), "object")):
        cases.append((f"version={lab}", lambda d, v=v: {**d, "version": v}))
    for key, v in (("format", np.array("other")), ("format", np.array(1)), ("cls", np.array("GPISMapXD")),
                   ("fitted", np.array("yes")), ("fitted", np.array(1)), ("params", np.array("{not json")),
                   ("params", np.array('{"local_gp": {"map_scale": -1}}')), ("params", np.array('{"evil": 1}')),
                   ("params", np.array('[1, 2]')), ("params", np.array('{"tree": {"min_half": 1e-9}}')),
                   ("params", np.array('{"tree": "no"}')), ("params", np.array('{"legacy": true}')),
                   ("n_updates", np.array(-1)), ("n_updates", np.array(1.5)), ("n_updates", np.array("3"))):
        cases.append((f"{key}={v!r}", lambda d, key=key, v=v: {**d, key: v}))
    return cases


def selftest_cases(data, dim):
    """Cases whose outcome the harness must report, to show that it can fail: an untouched copy
    ("accepted"), a worker that segfaults ("crash") and one that sleeps past the time limit
    ("hang"), each followed by a real tampering ("clear"), so that a new worker is seen to go on
    after a crash or a hang."""
    real = tamper_cases(data, dim)

    def segfault(d):
        os.kill(os.getpid(), signal.SIGSEGV)

    def sleep(d):
        time.sleep(3600)

    return [("selftest:untouched", lambda d: d), ("selftest:segfault", segfault), real[0],
            ("selftest:sleep", sleep), real[1]]


def all_cases(base_dir, names, selftest=False):
    """[(base name, label, fn)] over the bases, in a fixed order (``selftest``: the harness's own
    check cases, :func:`selftest_cases`, instead of the tamperings)."""
    out = []
    for name in names:
        with np.load(Path(base_dir) / f"{name}.npz", allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        dim = 3 if name.startswith("3d") else 2
        out += [(name, lab, fn) for lab, fn in (selftest_cases if selftest else tamper_cases)(data, dim)]
    return out


def _probe(m, dim):
    """An update and a query on a map that loaded (only reached by a silent accept)."""
    if dim == 2:
        m.update(ANG, np.full(len(ANG), 2.0), np.array([0.1, 0.0, 0.0]))
        m.query(np.array([[0.5, 0.2], [2.0, -1.0]]))
    else:
        m.update(np.full((24, 32), 1.0), np.array([[30.0, 0, 15.5], [0, 30.0, 11.5], [0, 0, 1]]), np.eye(4))
        m.query(np.array([[0.0, 0.0, 0.9], [0.01, 0.0, 1.0]]))


def _worker(base_dir, names, indices, selftest=False):
    import tempfile

    cases = all_cases(base_dir, names, selftest)
    bases = {}
    tmp = Path(tempfile.mkdtemp(prefix="gpis-tamper-"))
    try:
        for i in indices:
            name, lab, fn = cases[i]
            if name not in bases:
                with np.load(Path(base_dir) / f"{name}.npz", allow_pickle=False) as z:
                    bases[name] = {k: z[k] for k in z.files}
            path = tmp / "tampered.npz"
            np.savez(path, **fn(dict(bases[name])))
            print(f"start {i}", flush=True)
            try:
                m = _cls(name).load(path)
            except ValueError as exc:
                outcome = "clear" if str(path) in str(exc) else "unclear"
            except Exception:  # noqa: BLE001
                outcome = "unclear"
            else:
                outcome = "accepted"
                try:
                    _probe(m, 3 if name.startswith("3d") else 2)
                except Exception:  # noqa: BLE001
                    pass
            print(f"done {i} {outcome}", flush=True)
    finally:
        for p in tmp.iterdir():
            p.unlink()
        tmp.rmdir()


def run_tampered(base_dir, names, indices=None, *, batch=60, timeout=120.0, selftest=False):
    """Outcome per case index: "clear" (ValueError naming the file), "unclear" (another
    exception or message), "accepted" (loaded silently), "crash" (the worker died) or "hang"
    (``timeout`` s per worker). ``selftest``: run :func:`selftest_cases` instead."""
    n = len(all_cases(base_dir, names, selftest))
    todo = list(range(n)) if indices is None else sorted(indices)
    res = {}
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    while todo:
        # the next ``batch`` wanted cases in one worker (a new worker after a crash or a hang
        # goes on with the case after the one it died on)
        wanted = todo[:batch]
        cmd = [sys.executable, "-m", "tests.gpis.iofaults", "tamper-worker", str(base_dir), ",".join(names),
               ",".join(map(str, wanted))] + (["selftest"] if selftest else [])
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ROOT, env=env)
            out, died = p.stdout, p.returncode != 0
            kind = "crash"
        except subprocess.TimeoutExpired as exc:
            out, died, kind = (exc.stdout or b"").decode() if isinstance(exc.stdout, bytes) else (exc.stdout or ""), True, "hang"
        last = None
        for line in out.splitlines():
            f = line.split()
            if f[0] == "start":
                last = int(f[1])
            elif f[0] == "done":
                res[int(f[1])] = f[2]
                last = None
        missing = [i for i in wanted if i not in res]
        if missing:
            bad = last if last is not None else missing[0]
            res[bad] = kind if died else "crash"
        todo = [i for i in todo if i not in res]
    return res


if __name__ == "__main__":
    if sys.argv[1] == "tamper-worker":
        _worker(sys.argv[2], sys.argv[3].split(","), [int(i) for i in sys.argv[4].split(",")], sys.argv[5:] == ["selftest"])
