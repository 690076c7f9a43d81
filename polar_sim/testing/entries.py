"""The entry points of the contract under test, with small exact valid data (numpy only; the
simulator and the envs are imported only by their own entry points)."""

from __future__ import annotations

import hashlib
import io
from pathlib import Path
from collections.abc import Callable

import numpy as np

from polar_sim.testing.entry import EntryPoint, Graceful
from polar_sim.testing.digest import state_digest

__all__ = ["ENTRY_POINTS", "entry_points_of", "entry_point_names"]



def _poses_line(n=40, step=3.0):
    P = np.tile(np.eye(4), (n, 1, 1))
    P[:, 0, 3] = np.arange(n) * step
    th = 0.01 * np.arange(n)
    P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = np.cos(th), -np.sin(th), np.sin(th), np.cos(th)
    return P


def _gpis2d(n_scans=2):
    from polar_sim.gpis import GPISMap2D
    from polar_sim.gpis.synthetic import scan_circle

    m = GPISMap2D()
    for k in range(n_scans):
        pose = (0.1 * k, 0.05 * k, 0.1 * k)
        m.update(*scan_circle(pose=pose), pose)
    return m


def _ep_localize():
    from polar_sim.gpis.localize import localize

    def args(t, tmp):
        from polar_sim.gpis.synthetic import scan_circle

        return {"map": t, "scan": scan_circle(pose=(0.05, 0.02, 0.05)), "initial_pose": np.array([0.0, 0.0, 0.0])}

    return EntryPoint("localize", setup=lambda tmp: _gpis2d(2), args=args,
                      call=lambda t, a: localize(a["map"], a["scan"], a["initial_pose"]),
                      kinds={"map": "object", "scan": "scan2d", "initial_pose": "pose2d"},
                      names={"scan": ("angles", "ranges"), "map": ("query",)})


def _ep_metric(fname, kinds, make_args, names=None):
    def build():
        from polar_sim import metrics

        fn = getattr(metrics, fname)
        return EntryPoint(f"metrics.{fname}", setup=lambda tmp: None, args=lambda t, tmp: make_args(),
                          call=lambda t, a: fn(**a), kinds=kinds, names=names or {})
    return build


def _pose(t=(0.1, 0.0, 0.5), yaw=0.2):
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = t
    return T


def _pts(n=50, seed=0):
    return np.random.default_rng(seed).normal(0, 0.05, (n, 3))


def _ep_recording_append():
    from polar_sim.sim.recorders.recording import Recording

    def frame():
        return {"depth": np.ones((8, 10), np.float32), "pose": np.eye(4), "t": 0.1}

    def setup(tmp):
        r = Recording(meta={"what": "battery"})
        r.append(frame())
        return r

    return EntryPoint("Recording.append", setup=setup, args=lambda t, tmp: {"frame": frame()},
                      call=lambda t, a: t.append(a["frame"]), kinds={"frame": "frame"})


def _recording(n=3):
    from polar_sim.sim.recorders.recording import Recording

    r = Recording(meta={"what": "battery"})
    for i in range(n):
        r.append({"rgb": np.full((12, 16, 3), 10 * i, np.uint8), "depth": np.full((12, 16), 1.0 + i, np.float32),
                  "pose": np.eye(4), "t": 0.1 * i})
    return r


def _ep_recording_save():
    return EntryPoint("Recording.save", setup=lambda tmp: _recording(), args=lambda t, tmp: {"path": str(Path(tmp) / "rec.npz")},
                      call=lambda t, a: t.save(a["path"]), kinds={"path": "path_out"})


def _rewrite_npz(src, dst, *, header=None, arrays=None, drop=()):
    """Copy the .npz ``src`` to ``dst`` with the JSON header and some arrays replaced (a fresh zip:
    every checksum is valid, so only the reader's own checks can refuse it)."""
    import json
    import zipfile

    with zipfile.ZipFile(src) as z:
        members = {n: z.read(n) for n in z.namelist()}
    if header is not None:
        raw = header if isinstance(header, bytes) else json.dumps(header).encode()
        arrays = dict(arrays or {}, header=np.frombuffer(raw, np.uint8))
    for name, a in (arrays or {}).items():
        a = np.asanyarray(a)
        buf = io.BytesIO()
        if a.dtype.hasobject:     # a trap: an .npy that only a pickle-enabled reader would open
            np.lib.format.write_array_header_1_0(buf, {"descr": "|O", "fortran_order": False, "shape": a.shape})
            buf.write(b"\x80\x04N.")
        else:
            np.lib.format.write_array(buf, a)
        members[f"{name}.npy"] = buf.getvalue()
    with zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as z:
        for n, b in members.items():
            if n.removesuffix(".npy") not in drop:
                z.writestr(n, b)


def _tampered_recordings(valid, tmp, rng):
    """Hand-crafted recordings (valid zip checksums; altered headers and arrays)."""
    import copy
    import json
    import zipfile

    from polar_sim.testing.inputs import BadInput

    with zipfile.ZipFile(valid) as z:
        header = json.loads(bytes(np.load(io.BytesIO(z.read("header.npy")))).decode())
        off = np.load(io.BytesIO(z.read("png_offsets/rgb.npy")))
        blob = np.load(io.BytesIO(z.read("png/rgb.npy")))
    n = header["n"]
    edits = []
    for v in ("1", 1.5, 2, None, True, 0):
        edits.append((f"version={v!r}", {"version": v}))
    for v in (-1, 10**12, "3", 1.5, n + 1, n - 1, None):
        edits.append((f"n={v!r}", {"n": v}))
    for v in ([], "x", None):
        edits.append((f"meta={v!r}", {"meta": v}))
    for v in ({}, [], None):
        edits.append((f"keys={v!r}", {"keys": v}))
    edits.append(("format=other", {"format": "other"}))
    for key in ("rgb", "depth", "pose"):
        for field, vals in (("storage", ("pickle", None, 3)), ("shape", ([-1, 3], [10**9], ["a"], [], [1] * 5, None, "3")),
                            ("dtype", ("|O", "<c16", "V8", "<U3", "garbage", "M8", None, 5))):
            for v in vals:
                edits.append((f"{key}.{field}={v!r}", (key, field, v)))
    out = []
    for k, (label, edit) in enumerate(edits):
        h = copy.deepcopy(header)
        if isinstance(edit, dict):
            h.update(edit)
        else:
            key, field, v = edit
            h["keys"][key][field] = v
        p = Path(tmp) / f"tamper_{k}.npz"
        _rewrite_npz(valid, p, header=h)
        out.append(BadInput("path", f"tamper:{label}", str(p), "refuse"))
    arrays = [("png_offsets-negative", {"png_offsets/rgb": -off}), ("png_offsets-decreasing", {"png_offsets/rgb": off[::-1]}),
              ("png_offsets-past-end", {"png_offsets/rgb": off + 10**6}), ("png_offsets-float", {"png_offsets/rgb": off + 0.5}),
              ("png_offsets-short", {"png_offsets/rgb": off[:-1]}), ("png-random", {"png/rgb": rng.integers(0, 256, blob.shape, dtype=np.uint8)}),
              ("png-empty", {"png/rgb": np.zeros(0, np.uint8)}), ("raw-float32", {"raw/pose": np.zeros((n, 4, 4), np.float32)}),
              ("raw-shape", {"raw/pose": np.zeros((n + 1, 4, 4))}), ("raw-object", {"raw/pose": np.array([None] * n, object)}),
              ("header-object", {"header": np.array(["x"], object)}), ("header-2d", {"header": np.zeros((2, 2), np.uint8)}),
              ("depth-nan-shape", {"raw/depth": np.full((n, 1, 1), np.nan, np.float32)})]
    for k, (label, arr) in enumerate(arrays):
        p = Path(tmp) / f"tamper_arr_{k}.npz"
        _rewrite_npz(valid, p, arrays=arr)
        out.append(BadInput("path", f"tamper:{label}", str(p), "refuse"))
    for k, (label, raw) in enumerate((("header-not-utf8", b"\xff\xfe"), ("header-not-json", b"{"), ("header-list", b"[1]"))):
        p = Path(tmp) / f"tamper_h_{k}.npz"
        _rewrite_npz(valid, p, header=raw)
        out.append(BadInput("path", f"tamper:{label}", str(p), "refuse"))
    for k, name in enumerate(("header", "png/rgb", "png_offsets/rgb", "raw/pose")):
        p = Path(tmp) / f"tamper_drop_{k}.npz"
        _rewrite_npz(valid, p, drop=(name,))
        out.append(BadInput("path", f"tamper:missing-{name}", str(p), "refuse"))
    return out


def _ep_recording_load():
    from polar_sim.sim.recorders.recording import Recording

    def args(t, tmp):
        p = Path(tmp) / "valid_rec.npz"
        if not p.exists():
            _recording().save(p)
        return {"path": str(p)}

    return EntryPoint("Recording.load", setup=lambda tmp: None, args=args,
                      call=lambda t, a: Recording.load(a["path"]), kinds={"path": "path_in"},
                      extra=lambda t, tmp, rng: _tampered_recordings(args(t, tmp)["path"], tmp, rng))


def _world(scene="office2d", **kw):
    from polar_sim.sim import World

    return World(scene, seed=0, kinematic=True, **kw)


def _world_state(w):
    d = w.data
    return hashlib.sha256(b"".join(np.asarray(x).tobytes() for x in (d.qpos, d.qvel, d.ctrl, [d.time]))
                          + repr(w._rng.bit_generator.state).encode()
                          + repr(sorted(w._noise.items(), key=str)).encode()).hexdigest()


def _ep_world_init():
    def call(t, a):
        from polar_sim.sim import World

        w = World(a["scene"], seed=a["seed"], kinematic=a["kinematic"], control_dt=a["control_dt"],
                  camera_height=a["camera_height"])
        w.close()

    return EntryPoint("World", setup=lambda tmp: None,
                      args=lambda t, tmp: {"scene": "rover_flat", "seed": 0, "kinematic": True, "control_dt": 0.1,
                                           "camera_height": 1.2},
                      call=call, kinds={"scene": "name", "seed": "seed", "kinematic": "bool", "control_dt": "float+",
                                        "camera_height": "float+"}, timeout=120.0,
                      graceful={"control_dt": {"None"}, "camera_height": {"None"}})   # None: the scene's default


def _ep_world_step():
    return EntryPoint("World.step", setup=lambda tmp: _world(), args=lambda t, tmp: {"action": np.array([0.5, 0.1])},
                      call=lambda t, a: t.step(a["action"]), kinds={"action": "vector"}, state=_world_state,
                      graceful={"action": {"None"}})   # documented: no action is (0, 0)


def _ep_world_camera():
    return EntryPoint("World.camera", setup=lambda tmp: _world(),
                      args=lambda t, tmp: {"name": "front", "width": 32, "height": 24},
                      call=lambda t, a: t.camera(a["name"], width=a["width"], height=a["height"]),
                      kinds={"name": "name", "width": "int+", "height": "int+"}, state=_world_state, pure=True,
                      graceful={"width": {"None"}, "height": {"None"}})   # None: the camera's resolution


def _ep_world_lidar():
    return EntryPoint("World.lidar", setup=lambda tmp: _world(), args=lambda t, tmp: {"name": "lidar"},
                      call=lambda t, a: t.lidar(a["name"]), kinds={"name": "name"}, state=_world_state, pure=True)


def _ep_world_sdf():
    return EntryPoint("World.sdf", setup=lambda tmp: _world(), args=lambda t, tmp: {"points": np.array([[1.0, 2.0, 0.3], [5.0, 5.0, 0.5]])},
                      call=lambda t, a: t.sdf(a["points"]), kinds={"points": "points"}, state=_world_state, pure=True,
                      graceful={"points": {"shape:last-axis", "shape:transposed"}})   # (n, 2) points are documented


def _ep_world_noise():
    from polar_sim.sim.sensors import RangeNoise

    return EntryPoint("RangeNoise", setup=lambda tmp: None, args=lambda t, tmp: {"sigma": 0.01, "dropout": 0.05},
                      call=lambda t, a: RangeNoise(sigma=a["sigma"], dropout=a["dropout"]),
                      kinds={"sigma": "float+", "dropout": "unit"}, graceful={"sigma": {"zero"}})


# -- envs -------------------------------------------------------------------------------------------


def _env_ids():
    from polar_sim.envs import ENV_IDS as ids

    return list(ids)


def _make_env(env_id, **kw):
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401  (registers the ids)

    return gym.make(env_id, disable_env_checker=True, **kw)


def _env_state(env):
    return state_digest(env.unwrapped, ignore=("_rig", "_renderer", "renderer", "_viewer"))


def _ep_env_step(env_id):
    def setup(tmp):
        env = _make_env(env_id)
        env.reset(seed=0)
        return env

    def args(t, tmp):
        sp = t.action_space
        a = sp.sample() if not hasattr(sp, "low") else ((sp.low + sp.high) / 2).astype(sp.dtype)
        return {"action": a}

    def kinds():
        return {"action": "vector"}

    return EntryPoint(f"{env_id}.step", setup=setup, args=args, call=lambda t, a: t.step(a["action"]),
                      kinds=kinds(), state=_env_state, timeout=120.0)


def _ep_env_reset(env_id):
    def setup(tmp):
        env = _make_env(env_id)
        env.reset(seed=0)
        return env

    return EntryPoint(f"{env_id}.reset", setup=setup, args=lambda t, tmp: {"seed": 1},
                      call=lambda t, a: t.reset(seed=a["seed"]), kinds={"seed": "seed"}, state=_env_state, timeout=120.0)


# -- the CLI ----------------------------------------------------------------------------------------


def _cli_argvs(tmp):
    """Hostile command lines: each a (flag, label, argv, expect)."""
    out_ok = str(Path(tmp) / "out")
    bad_int = ["0", "-1", "abc", "1.5", "1e300", "", "nan", "99999999999999999999", "0x10", "1_0_", "--", "-5"]
    bad_seed = ["-1", "abc", "1.5", "1e300", "", "nan", "0x10", "1_0_", "--", "-5", "-99999999999999999999", "one"]
    bad_out = ["/dev/null/x", "/tmp/" + "x" * 5000, str(Path(tmp) / "file_as_dir" / "o"), "\x00"]
    cases = []
    for v in bad_int:
        cases += [("--width", f"int:{v}", ["render", "office2d", "--width", v, "--height", "24", "--out", out_ok]),
                  ("--height", f"int:{v}", ["render", "office2d", "--width", "32", "--height", v, "--out", out_ok]),
                  ("--episodes", f"int:{v}", ["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--episodes", v]),
                  ("--workers", f"int:{v}", ["run", "sensors", "--quick", "--workers", v, "--out", out_ok]),
                  ("--n-boot", f"int:{v}", ["compare", out_ok, out_ok, "--n-boot", v])]
    for v in ["-1", "abc", "1.5", "99999999999999999999", "", "nan", "1e3"]:
        cases.append(("--steps", f"int:{v}", ["render", "office2d", "--steps", v, "--width", "32", "--height", "24", "--out", out_ok]))
    for v in bad_seed[:7]:
        cases.append(("--seed", f"int:{v}", ["render", "office2d", "--seed", v, "--width", "32", "--height", "24", "--out", out_ok]))
    for v in bad_out:
        cases += [("--out", f"out:{v[:12]}", ["render", "office2d", "--width", "32", "--height", "24", "--out", v]),
                  ("--out", f"out:{v[:12]}", ["demo", "--out", v])]
    for v in ["[1]", "{bad", "null", '"str"', "1", '{"no_such_kwarg": 1}', "{}" * 1000, '{"a": NaN}', "[" * 5000, "true"]:
        cases.append(("--env-kwargs", f"json:{v}", ["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--episodes", "1",
                                                    "--env-kwargs", v, "--out", out_ok]))
    for v in ["nope:thing", "os:getcwd", "random.x", ""]:
        cases.append(("--policy", f"policy:{v}", ["eval", "polar_sim/GPISNav-v1", "--policy", v, "--episodes", "1", "--out", out_ok]))
    for v in ["train", "", "ñ"]:
        cases.append(("--split", f"split:{v}", ["run", "sensors", "--quick", "--split", v, "--out", out_ok]))
    for v in ["-1", "abc", "0", "nan", "inf", "-inf", "1e-400", ""]:
        cases.append(("--trial-timeout", f"float:{v}", ["run", "sensors", "--quick", "--trial-timeout", v, "--out", out_ok]))
        cases.append(("--trial-timeout", f"float:{v}", ["reproduce", "--quick", "--only", "sensors", "--trial-timeout", v,
                                                        "--out", out_ok]))
    for v in bad_int:
        cases.append(("--workers", f"int:{v}", ["reproduce", "--quick", "--only", "sensors", "--workers", v, "--out", out_ok]))
    for v in bad_seed:
        cases.append(("--seed", f"int:{v}", ["eval", "polar_sim/GPISNav-v1", "--policy", "random", "--episodes", "1",
                                              "--seed", v, "--out", out_ok]))
    for v in ["nope", "", "ñ" * 20, "sensors,nope"]:
        cases.append(("--only", f"only:{v[:12]}", ["reproduce", "--quick", "--only", v, "--out", out_ok]))
    for v in ["nohost:1", "127.0.0.1:1", "::::", "x" * 300]:
        cases.append(("--address", f"address:{v[:12]}", ["run", "sensors", "--quick", "--backend", "ray", "--address", v,
                                                         "--out", out_ok]))
    run = Path(tmp) / "run_a"            # a minimal run folder, so compare gets as far as --metric / --by
    run.mkdir(exist_ok=True)
    (run / "results.csv").write_text("trial_key,status,method,seed,err_m\nk1,ok,a,0,0.1\nk2,ok,a,1,0.2\n"
                                     "k3,ok,b,0,0.3\nk4,ok,b,1,0.4\n")
    for v in ["no_such_metric", "", "ñ"]:
        cases.append(("--metric", f"metric:{v}", ["compare", str(run), str(run), "--metric", v, "--out", out_ok]))
        cases.append(("--by", f"by:{v}", ["compare", str(run), str(run), "--by", v, "--out", out_ok]))
    for v in ["bogus=1", "novalue", "=3", "seed=[", "seed=abc", "seed=-1", "seed=1.5", "seed=[]", "scene=[moon]",
              "scene=", "seed=true", "seed={}", "method=nope:x"]:
        cases.append(("--set", f"set:{v}", ["run", "sensors", "--quick", "--set", v, "--out", out_ok]))
    bad_xml = Path(tmp) / "bad.xml"
    bad_xml.write_text("<mujoco><worldbody>")
    for v in ["moon_base", "x" * 5000, str(Path(tmp) / "missing.xml"), "ñ.xml", str(Path(tmp) / "file_as_dir"),
              str(bad_xml), "/dev/null", "", "../" * 50 + "etc/passwd.xml", str(Path(tmp))]:
        cases.append(("scene", f"scene:{v[:12]}", ["render", v, "--out", out_ok]))
    for v in ["nope", "", "x" * 3000]:
        cases.append(("experiment", f"exp:{v[:12]}", ["run", v, "--quick", "--out", out_ok]))
        cases.append(("env_id", f"env:{v[:12]}", ["eval", v, "--policy", "random"]))
    cases += [("run_a", "compare:missing", ["compare", str(Path(tmp) / "nope_a"), str(Path(tmp) / "nope_b")]),
              ("--size", "size:huge", ["run", "sensors", "--size", "huge", "--out", out_ok]),
              ("--backend", "backend:x", ["run", "sensors", "--quick", "--backend", "x"]),
              ("only", "bench:unknown", ["bench", "no_such_bench"])]
    for v in ["", "../x", "battery;rm", "ñ", "x" * 3000]:
        cases.append(("bench", f"bench:{v[:12]}", ["bench", v]))
    for argv in ([], ["frobnicate"], ["run"], ["render"], ["compare", "a"], ["list", "--bogus"], ["demo", "--bogus"],
                 ["reproduce", "--only", "--quick", "--bogus"], ["eval", "polar_sim/GPISNav-v1"], ["run", "--quick"],
                 ["render", "office2d", "--width"], ["eval", "--policy", "random"]):
        cases.append(("usage", f"usage:{' '.join(argv)[:20]}", list(argv)))
    return cases


def _ep_cli():
    """The CLI as one entry point: argument ``argv`` takes hostile command lines; a clear outcome
    is exit code 1 with one line on stderr naming the flag, or argparse's usage error (exit 2)."""

    def setup(tmp):
        (Path(tmp) / "file_as_dir").write_bytes(b"x")
        return None

    def call(t, a):
        import contextlib

        from polar_sim.cli import main

        flag, label, argv = a["argv"]
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc = main(argv)
            except SystemExit as exc:
                rc = exc.code
        text = err.getvalue().strip()
        if rc == 0:
            return rc
        last = text.splitlines()[-1] if text else ""
        if rc == 1 and last.startswith("polar-sim: error:") and "Traceback" not in text:
            # one line that says what was wrong: names the flag, the value, or what was expected
            value = argv[argv.index(flag) + 1] if flag in argv and argv.index(flag) + 1 < len(argv) else None
            if (flag.lstrip("-") in last or (value and value[:40] in last) or "expected" in last or "valid" in last):
                raise ValueError(f"argv: {flag}: exit 1: {last[:160]}")
        if rc == 2 and "usage:" in text and (flag in text or "argument" in text or "invalid choice" in text):
            raise ValueError(f"argv: {flag}: exit 2: {last[:160]}")
        if rc == 2 and "failed" in text and "Traceback" not in text:
            raise Graceful("the run recorded the failing trials and exited 2, as documented")
        raise RuntimeError(f"exit {rc}: {last[-300:]}")

    ep = EntryPoint("cli", setup=setup, args=lambda t, tmp: {"argv": None}, call=call, kinds={}, timeout=180.0)
    ep.cases = _cli_argvs
    return ep



_METRIC_ENTRIES = {
    "metrics.kitti_errors": _ep_metric(
        "kitti_errors", {"gt_poses": "poses", "est_poses": "poses", "lengths": "lengths", "step": "int+"},
        lambda: {"gt_poses": _poses_line(), "est_poses": _poses_line(), "lengths": [30.0, 60.0], "step": 5},
        names={"gt_poses": ("gt_poses", "est_poses"), "est_poses": ("gt_poses", "est_poses")}),
    "metrics.ate": _ep_metric("ate", {"gt_poses": "poses", "est_poses": "poses", "align": "choice"},
                              lambda: {"gt_poses": _poses_line(), "est_poses": _poses_line(), "align": "se3"},
                              names={"gt_poses": ("est_poses",), "est_poses": ("gt_poses",)}),
    "metrics.rpe": _ep_metric("rpe", {"gt_poses": "poses", "est_poses": "poses", "delta": "int+"},
                              lambda: {"gt_poses": _poses_line(), "est_poses": _poses_line(), "delta": 2},
                              names={"gt_poses": ("est_poses",), "est_poses": ("gt_poses",)}),
    "metrics.add": _ep_metric("add", {"model_points": "points", "T_gt": "pose_or_stack", "T_est": "pose_or_stack"},
                              lambda: {"model_points": _pts(), "T_gt": _pose(), "T_est": _pose(yaw=0.25)}),
    "metrics.adds": _ep_metric("adds", {"model_points": "points", "T_gt": "pose_or_stack", "T_est": "pose_or_stack"},
                               lambda: {"model_points": _pts(), "T_gt": _pose(), "T_est": _pose(yaw=0.25)}),
    "metrics.iou": _ep_metric("iou", {"mask_a": "mask", "mask_b": "mask"},
                              lambda: {"mask_a": np.eye(8, dtype=bool), "mask_b": np.tri(8, dtype=bool)},
                              names={"mask_a": ("mask_b",), "mask_b": ("mask_a",)}),
    "metrics.hausdorff": _ep_metric("hausdorff", {"points_a": "points", "points_b": "points"},
                                    lambda: {"points_a": _pts(30, 1), "points_b": _pts(40, 2)},
                                    names={"points_a": ("points_b",), "points_b": ("points_a",)}),
    "metrics.chamfer": _ep_metric("chamfer", {"points_a": "points", "points_b": "points"},
                                  lambda: {"points_a": _pts(30, 1), "points_b": _pts(40, 2)},
                                  names={"points_a": ("points_b",), "points_b": ("points_a",)}),
}

#: name -> builder of the :class:`EntryPoint` (builders import lazily).
ENTRY_POINTS: dict[str, Callable[[], EntryPoint]] = {
    "World": _ep_world_init, "World.step": _ep_world_step, "World.camera": _ep_world_camera,
    "World.lidar": _ep_world_lidar, "World.sdf": _ep_world_sdf, "RangeNoise": _ep_world_noise,
    "localize": _ep_localize,
    **_METRIC_ENTRIES,
    "Recording.append": _ep_recording_append, "Recording.save": _ep_recording_save,
    "Recording.load": _ep_recording_load,
    "cli": _ep_cli,
}


class _Entries(dict):
    """The hand-written entry points above, plus those derived on demand (so that listing them
    imports neither gymnasium nor the modules): ``ID.step``/``ID.reset`` of every env id, and the
    constructor and methods of every module class (:func:`polar_sim.testing.derive.module_entry_points`),
    by class name for :data:`~polar_sim.testing.contract.MODULE_CLASSES` (``"GPISMap2D.update"``)
    or by path for any other (``"package.module:Class.update"``)."""

    def __missing__(self, key):
        for suffix, fn in ((".step", _ep_env_step), (".reset", _ep_env_reset)):
            if key.startswith("polar_sim/") and key.endswith(suffix):
                env_id = key[: -len(suffix)]
                return lambda: fn(env_id)
        cls = _module_class(key.partition(".")[0] if ":" not in key else key.split(".")[0])
        if cls is not None:
            return _derived(cls, key)
        raise KeyError(key)


def _module_class(name):
    """The module class called ``name`` in MODULE_CLASSES, or at path ``"package.module:Class"``."""
    import importlib

    from polar_sim.testing.contract import MODULE_CLASSES

    if ":" not in name:
        name = next((p for p in MODULE_CLASSES if p.endswith(f":{name}")), None)
        if name is None:
            return None
    module, _, qual = name.partition(":")
    try:
        cls = getattr(importlib.import_module(module), qual)
    except (ImportError, AttributeError):
        return None
    return cls if isinstance(cls, type) and hasattr(cls, "TAGS") else None


def _derived(cls, key):
    from polar_sim.testing.derive import module_entry_points

    entries = module_entry_points(cls, _prefix(cls, key))
    if key not in entries:
        raise KeyError(key)
    return entries[key]


def _prefix(cls, name):
    return cls.__name__ if ":" not in name else f"{cls.__module__}:{cls.__qualname__}"


ENTRY_POINTS = _Entries(ENTRY_POINTS)


def entry_points_of(name):
    """Entry point names belonging to an env id, a module class (its name, or
    ``"package.module:Class"``) or a family of calls (``"World"``, ``"metrics.ate"``, ``"cli"``)."""
    if name.startswith("polar_sim/"):
        return [f"{name}.reset", f"{name}.step"]
    cls = _module_class(name)
    if cls is not None:
        from polar_sim.testing.derive import module_entry_points

        return list(module_entry_points(cls, _prefix(cls, name)))
    return [k for k in dict.keys(ENTRY_POINTS) if k == name or k.startswith(name + ".")]


def entry_point_names():
    """Every hand-written and module entry point name (env entry points: :func:`entry_points_of`)."""
    from polar_sim.testing.contract import MODULE_CLASSES

    names = [n for p in MODULE_CLASSES for n in entry_points_of(p.partition(":")[2])]
    return names + list(dict.keys(ENTRY_POINTS))
