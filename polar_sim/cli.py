"""``polar-sim``: the command line. It parses, calls the library and prints; nothing more.

Heavy modules are imported inside each command. A ``ValueError``, ``TypeError``, ``OSError``
(``FileNotFoundError`` included) or ``ImportError`` (a ``--policy MODULE:CALLABLE`` that does not
import) becomes exit code 1 with a one-line message that names the option at fault (an OS error
names the path option whose path it concerns); argparse's usage errors exit 2. ``run`` and
``reproduce`` exit 0 when every trial ran and no check regressed (recorded misses are reported,
not failed), and 2 otherwise; ``--strict`` also fails on recorded misses. Every command takes
``--quiet`` (no progress bars; bars show only on a terminal anyway).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

# Headless rendering for every command (CPU EGL through Mesa).
os.environ.setdefault("MUJOCO_GL", "egl")


def _cmd_list(args):
    from polar_sim.runner import get_experiment, list_experiments
    from polar_sim.runner.describe import describe_experiment
    from polar_sim.runner.methods import describe_methods
    from polar_sim.sim.scenes import describe_scene, list_scenes, scene_options

    if args.name:   # one experiment, every value in full
        exp = get_experiment(args.name)
        print(f"{exp.name}: {exp.description}")
        for line in describe_experiment(exp, full=True):
            print(f"  {line}")
        return 0
    print("scenes:")
    for s in list_scenes():
        opts = ", ".join(f"{k}={v!r}" for k, v in scene_options(s).items())
        print(f"  {s:<14} {describe_scene(s)}" + (f"  [options: {opts}]" if opts else ""))
    print("experiments (polar-sim run NAME [--quick] [--split dev|test] [--set KEY=VALUE ...]):\n"
          "  under each, the grid axes and protocol params of a full run on the default split, then what the quick\n"
          "  size and the other split change; each KEY=, and seed, can be --set (polar-sim list NAME: lists in full)")
    for e in list_experiments():
        try:
            exp = get_experiment(e)
        except Exception as exc:   # one broken file must not hide the others
            print(f"  {e:<22} (cannot be loaded: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")
            continue
        print(f"  {e:<22} {exp.description}  [splits: {', '.join(exp.splits)}]")
        for line in describe_experiment(exp):
            print(f"      {line}")
    print("environments (gym.make(ID) after `import polar_sim.envs`):")
    for env_id, doc in _env_ids():
        print(f"  {env_id:<30} {doc}")
    methods = describe_methods()
    if methods:
        print("methods (--set method=NAME, or method=package.module:factory for your own):")
        for kind, name, desc in methods:
            print(f"  {kind:<12} {name:<14} {desc}")
    return 0


def _env_ids():
    """(id, one-line summary) of every registered polar_sim environment."""
    from polar_sim.envs import ENV_SUMMARIES

    return list(ENV_SUMMARIES.items())


def _cmd_render(args):
    from polar_sim.sim import World

    _positive_int(args.width, "--width", 8192)
    _positive_int(args.height, "--height", 8192)
    if not 0 <= args.steps <= 1_000_000:
        raise ValueError(f"--steps: expected an integer in [0, 1000000], got {args.steps}")
    if args.seed < 0:
        raise ValueError(f"--seed: expected an integer >= 0, got {args.seed}")
    _out_dir(args.out)
    from polar_sim.sim.pictures import render_scene_pictures

    with World(args.scene, seed=args.seed) as w:
        for _ in range(args.steps):
            w.step()
        paths = render_scene_pictures(w, args.out, width=args.width, height=args.height)
    for p in paths:
        print(p)
    return 0


def _parse_value(text):
    """A --set value: JSON if it parses, a bracketed list of bare words (``[office2d, gazebo1]``),
    or the plain string."""
    import json

    text = text.strip()
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        pass
    if text.startswith("[") and text.endswith("]"):
        inner = text[1:-1].strip()
        return [] if not inner else [_parse_value(part) for part in inner.split(",")]
    if text.startswith(("[", "{", '"')) or text.endswith(("]", "}")):
        raise ValueError(f"--set: cannot parse {text!r}; use JSON (e.g. [1.0, 2.0]) or [a, b]")
    return text


def _parse_overrides(items):
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--set: expected KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        if not k:
            raise ValueError(f"--set: empty key in {item!r}")
        out[k] = _parse_value(v)
    return out


def _positive_int(value, name, maximum=None):
    if value < 1 or (maximum is not None and value > maximum):
        bound = f" and <= {maximum}" if maximum is not None else ""
        raise ValueError(f"{name}: expected an integer >= 1{bound}, got {value}")
    return value


def _timeout(value, name="--trial-timeout"):
    """None or a finite number of seconds > 0."""
    import math

    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite number of seconds > 0, got {value}")
    return value


def _show(p):
    return repr(str(p)[:200])


def _writable(folder, option, what):
    """``ValueError`` naming ``option`` unless a file can be created in ``folder`` (a probe that
    leaves nothing: an unnamed temporary file)."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise ValueError(f"{option}: cannot {what} ({exc.strerror or exc})") from None


def _out_dir(path, option="--out", *, create=True, must_exist=False):
    """The folder an option names, checked before any work (a one-line error naming ``option``,
    not a traceback): not a file, and writable by this user. ``create``: make it now; else only
    check that it can be made. ``must_exist``: it must be there already (``--report-only``)."""
    if path is None:
        return None
    if "\x00" in str(path):
        raise ValueError(f"{option}: {_show(path)} is not a folder path (it holds a NUL byte)")
    p = Path(path).expanduser()
    try:
        if p.exists():
            if not p.is_dir():
                raise ValueError(f"{option}: {_show(p)} exists and is not a folder")
            _writable(p, option, f"create files in {_show(p)}")
            return p
        if must_exist:
            raise ValueError(f"{option}: {_show(p)} does not exist")
        base = next(a for a in p.parents if a.exists())   # "/" exists
        if not base.is_dir():
            raise ValueError(f"{option}: cannot create {_show(p)}: {_show(base)} is a file")
        if create:
            p.mkdir(parents=True, exist_ok=True)
        _writable(p if create else base, option, f"create files in {_show(p)}" if create else f"create {_show(p)}")
    except OSError as exc:                         # too long, a loop of links, no permission, ...
        raise ValueError(f"{option}: cannot create {_show(p)}: {exc.strerror or exc}") from None
    return p


def _print_checks(res):
    for c in res.checks:
        print(f"  [{c.status}] {c.name}: {c.detail}")


def _exit_code(results, strict):
    """0: every trial ran and no check regressed; 2: a failure (or, with --strict, a miss or a slow timing)."""
    ok = all((r.strict_passed if strict else r.passed) for r in results)
    return 0 if ok else 2


def _cmd_run(args):
    from polar_sim.runner import run_experiment

    _out_dir(args.out, create=False)
    res = run_experiment(args.experiment, quick=args.quick, size=args.size, split=args.split, out=args.out,
                         workers=_positive_int(args.workers, "--workers", 1024), backend=args.backend,
                         address=args.address, overrides=_parse_overrides(args.set),
                         trial_timeout=_timeout(args.trial_timeout), progress=not args.quiet)
    print(f"{args.experiment}: {len(res.table)} trials ({res.config['split']} split, {res.config['size']} size), "
          f"results in {res.out_dir}")
    _print_checks(res)
    return _exit_code([res], args.strict)


def _cmd_reproduce(args):
    from polar_sim.runner.reproduce import reproduce

    workers, timeout = _positive_int(args.workers, "--workers", 1024), _timeout(args.trial_timeout)
    _out_dir(args.out, create=False, must_exist=args.report_only)
    results, report = reproduce(args.out, quick=args.quick if args.report_only else bool(args.quick),
                                split=args.split, only=args.only, workers=workers, backend=args.backend,
                                address=args.address, trial_timeout=timeout, report_only=args.report_only,
                                progress=not args.quiet)
    for name, res in results.items():
        c = [x.status for x in res.checks]
        print(f"{name}: {c.count('pass')} met, {c.count('missed')} missed (recorded), {c.count('slow')} slow (timing), "
              f"{c.count('FAIL')} failed, {len(res.failures)} trial errors")
    print(f"report: {report} (and {report.with_suffix('.html').name})")
    return _exit_code(list(results.values()), args.strict)


def _cmd_compare(args):
    from polar_sim.runner.compare import compare_runs

    _positive_int(args.n_boot, "--n-boot", 10_000_000)
    _out_dir(args.out, create=False)
    out = compare_runs(args.run_a, args.run_b, by=args.by, metrics=args.metric, out=args.out,
                       n_boot=args.n_boot, seed=args.seed)
    print(out.read_text())
    return 0


def _cmd_demo(args):
    from polar_sim.demo import run_demo

    return run_demo(_out_dir(args.out), workers=args.workers, progress=not args.quiet)


def _cmd_eval(args):
    import json

    from polar_sim.envs import ENV_IDS, register_envs
    from polar_sim.envs.evaluate import evaluate

    register_envs()
    if args.env_id not in ENV_IDS:
        raise ValueError(f"env_id: unknown environment {args.env_id!r}; valid: {', '.join(ENV_IDS)}")
    if not args.policy:
        raise ValueError("--policy: required: 'pretrained', a policy file (.npz), MODULE:CALLABLE (a class is "
                         "instantiated) or 'random'")
    _positive_int(args.episodes, "--episodes", 1_000_000)
    if args.seed < 0:
        raise ValueError(f"--seed: expected an integer >= 0, got {args.seed}")
    try:
        kwargs = json.loads(args.env_kwargs) if args.env_kwargs else {}
    except json.JSONDecodeError as exc:
        raise ValueError(f"--env-kwargs: not valid JSON ({exc.msg})") from None
    except RecursionError:
        raise ValueError("--env-kwargs: JSON nested too deeply") from None
    if not isinstance(kwargs, dict):
        raise ValueError(f"--env-kwargs: expected a JSON object like {{\"sdf_source\": \"truth\"}}, got {args.env_kwargs}")
    out = str(_out_dir(args.out or f"polar_sim_out/eval/{args.env_id.replace('/', '_')}"))
    rows, summary = evaluate(args.env_id, args.policy, episodes=args.episodes, seed=args.seed,
                             env_kwargs=kwargs, out_dir=out, progress=not args.quiet)
    n = summary["episodes"]
    print(f"{args.env_id}: {n} episode{'s' if n != 1 else ''}, seeds {args.seed}..{args.seed + n - 1}; "
          "means over the episodes:")
    for name, value in _eval_lines(rows, summary):
        print(f"  {name:<24} {value}")
    print(f"per-episode metrics: {out}/episodes.csv")
    return 0


def _cmd_compile(args):
    import time

    from polar_sim.gpis.build_native import build

    t0 = time.perf_counter()
    path, skipped = build(args.out)
    print(f"compiled the GPIS kernels in {time.perf_counter() - t0:.0f} s: {path}")
    if skipped:
        print(f"left to numba's JIT: {', '.join(skipped)}")
    return 0


def _cmd_train(args):
    import json

    from polar_sim.envs.recipes import check_recipe, train

    try:
        params = json.loads(args.params) if args.params else {}
    except json.JSONDecodeError as exc:
        raise ValueError(f"--params: not valid JSON ({exc.msg})") from None
    check_recipe(args.recipe, params, args.env)  # every argument checked before anything is built
    if not 0 <= args.test_episodes <= 1_000_000:
        raise ValueError(f"--test-episodes: expected an integer in [0, 1000000], got {args.test_episodes}")
    if args.seed < 0:
        raise ValueError(f"--seed: expected an integer >= 0, got {args.seed}")
    out = _out_dir(args.out or f"polar_sim_out/train/{args.recipe}_{args.env.split('/')[-1]}_s{args.seed}")
    policy, summary = train(args.recipe, args.env, params=params, seed=args.seed, out=out,
                            progress=False if args.quiet else None)
    print(f"{args.recipe} on {args.env}: {summary['steps']} env steps, {summary['wall_s'] / 60:.1f} min wall, "
          f"{summary['cpu_s'] / 60:.1f} min CPU; policy: {out}/policy.npz")
    if args.test_episodes:
        from polar_sim.envs.evaluate import evaluate

        _, s = evaluate(args.env, str(out / "policy.npz"), episodes=args.test_episodes, seed=10_000,
                        out_dir=out / "test", progress=not args.quiet)
        print(f"held-out worlds (seeds 10000..{10_000 + args.test_episodes - 1}, slam): success "
              f"{100 * s['success_rate']:.1f} % of episodes, collisions {100 * s['mean_collision']:.1f} % of episodes")
    return 0


#: Units of the per-episode metrics of the environments' final ``info`` (their docstrings say
#: them); ``eval`` prints each mean with its unit, and a true/false metric as a % of episodes.
_EVAL_UNITS = {"return": "(reward)", "length": "steps", "path_length": "m", "goal_distance": "m",
               "geodesic_distance": "m", "pose_error": "m", "heading_error": "rad", "cross_track_error": "m",
               "drift": "m", "drift_pct": "% of the distance driven", "est_progress": "m", "progress": "m",
               "route_length": "m", "speed": "m/s", "time": "s", "yaw_rate": "rad/s",
               "distance": "m (position error + 0.05 m/rad x yaw error)", "position_error": "m", "yaw_error": "rad",
               "tracking_error": "m", "tracking_error_deg": "deg", "tracking_add": "m",
               "localization_failures": "steps per episode"}
_SUFFIX_UNITS = (("_m", "m"), ("_deg", "deg"), ("_rad", "rad"), ("_s", "s"), ("_ms", "ms"), ("_pct", "%"))


def _eval_lines(rows, summary):
    """(name, value with its unit) per metric ``evaluate`` summarised."""
    out = []
    for key, value in summary.items():
        if key in ("env_id", "episodes", "seed"):
            continue
        name = "success" if key == "success_rate" else key.removeprefix("mean_")
        col = "is_success" if key == "success_rate" else name
        if all(isinstance(r.get(col), bool) for r in rows):
            out.append((name, f"{100 * value:.1f} % of episodes"))
            continue
        unit = _EVAL_UNITS.get(name) or next((u for suf, u in _SUFFIX_UNITS if name.endswith(suf)), "(no unit)")
        out.append((name, f"{value:.4g} {unit}" if isinstance(value, float) else f"{value} {unit}"))
    return out


def _cmd_bench(args):
    import subprocess

    here = Path.cwd() / "benchmarks"
    if not here.is_dir():
        here = Path(__file__).resolve().parents[1] / "benchmarks"
    if not here.is_dir():
        raise ValueError("bench: the benchmarks/ folder was not found; run from a clone of the repository")
    scripts = sorted(here.glob("bench_*.py"))
    if args.only:
        known = {p.stem.removeprefix("bench_"): p for p in scripts}
        bad = [n for n in args.only if n not in known]
        if bad:
            raise ValueError(f"bench: unknown benchmark(s) {bad}; valid: {sorted(known)}")
        scripts = [known[n] for n in args.only]
    rc = 0
    for s in scripts:
        print(f"== {s.name}", flush=True)
        cmd = [sys.executable, str(s)] + (["--quick"] if args.quick else [])
        rc |= subprocess.call(cmd)
    return rc


def build_parser():
    p = argparse.ArgumentParser(prog="polar-sim", description="polar_sim: simulation-in-the-loop testbed for online learning of appearance and structure")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--quiet", action="store_true",
                        help="no progress bars (they show only when stderr is a terminal anyway)")
    sub = _Subparsers(p.add_subparsers(dest="command", required=True), common)

    s = sub.add_parser("list", help="list scenes, experiments (with their --set keys), environments and methods")
    s.add_argument("name", nargs="?", default=None, help="one experiment: its grid, params and sizes in full")
    s.set_defaults(func=_cmd_list)

    s = sub.add_parser("demo", help="a short headless run of every part; PNGs in ./polar_sim_out/")
    s.add_argument("--out", default="polar_sim_out", help="output folder (default ./polar_sim_out)")
    s.add_argument("--workers", type=int, choices=(1, 2), default=None,
                   help="processes: 1 runs the parts one by one, 2 (default on 2+ cores) in two lanes")
    s.set_defaults(func=_cmd_demo)

    s = sub.add_parser("render", help="pictures of a scene from its cameras")
    s.add_argument("scene", help="scene name (see `polar-sim list`) or MJCF path")
    s.add_argument("--out", default="polar_sim_out/render")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--steps", type=int, default=0, help="steps to run (scripted scenes) before rendering")
    s.add_argument("--width", type=int, default=640)
    s.add_argument("--height", type=int, default=480)
    s.set_defaults(func=_cmd_render)

    def sweep_options(s):
        s.add_argument("--split", default=None, help="dev (tuning) or test (held out; the default)")
        s.add_argument("--workers", type=int, default=1, help="parallel trials (default 1)")
        s.add_argument("--backend", choices=["local", "ray"], default="local")
        s.add_argument("--address", default=None,
                       help="Ray cluster to join with --backend ray ('auto', HOST:PORT); default $RAY_ADDRESS or a local one")
        s.add_argument("--trial-timeout", type=float, default=None, metavar="S",
                       help="stop a trial after S seconds and record it as failed")
        s.add_argument("--strict", action="store_true", help="exit 2 on recorded misses too")

    s = sub.add_parser("run", help="run one experiment")
    s.add_argument("experiment")
    s.add_argument("--quick", action="store_true", help="the small CI size (same as --size quick)")
    s.add_argument("--size", default=None, help="a size the experiment declares: quick or full (default)")
    s.add_argument("--out", default=None, help="run folder (default polar_sim_out/runs/NAME/TIMESTAMP); reused to resume")
    s.add_argument("--set", nargs="*", metavar="KEY=VALUE",
                   help="override grid axes, protocol params or seeds: --set spacing_m=[0.5,1.0] scene=[office2d] "
                        "seed=3 method=mypkg.mymod:MyLocalizer (polar-sim list shows each experiment's)")
    sweep_options(s)
    s.set_defaults(func=_cmd_run)

    s = sub.add_parser("reproduce", help="run every experiment and write one report (report.md, report.html)")
    s.add_argument("--quick", action="store_true", default=None, help="the CI size of every experiment")
    s.add_argument("--out", default="polar_sim_out/reproduce")
    s.add_argument("--only", nargs="*", help="a subset of experiments")
    s.add_argument("--report-only", action="store_true",
                   help="run nothing: write the report from the finished run folders in --out (their size; "
                        "refused, writing nothing, unless every folder is a finished run of one size)")
    sweep_options(s)
    s.set_defaults(func=_cmd_reproduce)

    s = sub.add_parser("compare", help="metric differences between two runs, with bootstrap confidence intervals")
    s.add_argument("run_a", help="run folder A (holds results.csv)")
    s.add_argument("run_b", help="run folder B")
    s.add_argument("--by", nargs="*", default=None, help="group by these parameters (default: every parameter but seed)")
    s.add_argument("--metric", nargs="*", default=None, help="metrics to compare (default: every numeric metric)")
    s.add_argument("--out", default=None, help="folder for compare.md, compare.csv and compare.png (default RUN_B/compare)")
    s.add_argument("--n-boot", type=int, default=2000, help="bootstrap resamples (default 2000)")
    s.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    s.set_defaults(func=_cmd_compare)

    s = sub.add_parser("eval", help="closed-loop evaluation of a policy in an environment")
    s.add_argument("env_id", help="e.g. polar_sim/GPISNav-v1 (polar-sim list shows them all)")
    s.add_argument("--policy", default=None,
                   help="required: 'pretrained' (the policy shipped for ENV_ID), a policy file (.npz), MODULE:CALLABLE "
                        "(a class is instantiated) or 'random'")
    s.add_argument("--episodes", type=int, default=10)
    s.add_argument("--seed", type=int, default=10_000, help="seed of the first episode (default 10000: held out)")
    s.add_argument("--env-kwargs", default=None, help='JSON, e.g. \'{"sdf_source": "truth"}\'')
    s.add_argument("--out", default=None, help="output folder (default polar_sim_out/eval/ENV)")
    s.set_defaults(func=_cmd_eval)

    s = sub.add_parser("compile", help="compile the GPIS kernels ahead of time (once after install: "
                                       "first runs then start in seconds; needs a C compiler)")
    s.add_argument("--out", default=None, help="folder (default $POLAR_SIM_NATIVE_DIR or ~/.cache/polar_sim/native)")
    s.set_defaults(func=_cmd_compile)

    s = sub.add_parser("train", help="train a learning recipe on a GPISNav tier (needs torch, stable-baselines3)")
    s.add_argument("recipe", help="dagger, dagger_map, dagger_ppo, ppo, recurrent_ppo, sac or tqc (docs/guide/learning.md)")
    s.add_argument("--env", default="polar_sim/GPISNav-Room-v1", help="the tier's env id")
    s.add_argument("--params", default=None, help='JSON object of recipe parameters, e.g. \'{"rounds": 6}\'')
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--test-episodes", type=int, default=0,
                   help="then score the policy on this many held-out worlds (seeds 10000.., slam)")
    s.add_argument("--out", default=None, help="output folder (default polar_sim_out/train/RECIPE_ENV_sSEED)")
    s.set_defaults(func=_cmd_train)

    s = sub.add_parser("bench", help="run the speed/memory benchmarks (from a repository clone)")
    s.add_argument("only", nargs="*", help="benchmark names (bench_NAME.py); default all")
    s.add_argument("--quick", action="store_true")
    s.set_defaults(func=_cmd_bench)
    return p


class _Subparsers:
    """``add_subparsers()``'s object, every subcommand given the common options (``--quiet``)."""

    def __init__(self, sub, common):
        self._sub, self._common = sub, common

    def add_parser(self, name, **kwargs):
        return self._sub.add_parser(name, parents=[self._common], **kwargs)


#: The options of each command that name paths: an OS error about a path is reported against
#: the option whose path it lies in (the positional ``scene`` of render may be an MJCF path).
_PATH_OPTIONS = {"render": ("--out", "scene"), "demo": ("--out",), "run": ("--out",), "reproduce": ("--out",),
                 "compare": ("--out", "run_a", "run_b"), "eval": ("--out",)}
#: Library argument names that are options of the command line.
_OPTIONS = {"out": "--out", "address": "--address", "workers": "--workers", "trial_timeout": "--trial-timeout",
            "backend": "--backend", "split": "--split", "size": "--size"}


def _os_error_line(exc, args):
    """An ``OSError`` as one line naming the option whose path it concerns."""
    where = exc.filename if exc.filename is not None else exc.filename2
    opts = [(o, getattr(args, o.lstrip("-").replace("-", "_"), None)) for o in _PATH_OPTIONS.get(args.command, ())]
    opts = [(o, Path(v).expanduser()) for o, v in opts if v is not None]
    hit = None
    if where is not None:
        target = Path(str(where)).expanduser()
        hits = [(o, v) for o, v in opts if target == v or v in target.parents]
        hit = max(hits, key=lambda ov: len(str(ov[1])))[0] if hits else None
    hit = hit or (opts[0][0] if opts else None)
    what = f"{_show(where)}: " if where is not None else ""
    reason = exc.strerror or str(exc) or type(exc).__name__
    return f"{hit}: cannot use {what}{reason}" if hit else f"{what}{reason}"


def _error_line(exc, args):
    """The one-line message of an error: its first line, the library's argument name given as
    the command line's option (``out:`` as ``--out:``)."""
    if isinstance(exc, OSError) and (exc.strerror or exc.filename):
        return _os_error_line(exc, args)
    msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    name, sep, rest = msg.partition(": ")
    if sep and name in _OPTIONS and hasattr(args, _OPTIONS[name].lstrip("-").replace("-", "_")):
        msg = f"{_OPTIONS[name]}: {rest}"
    return msg


def main(argv=None):
    args = build_parser().parse_args(argv)
    if args.quiet:
        from polar_sim.progress import QUIET_ENV

        os.environ[QUIET_ENV] = "1"      # every bar, in this process and in its workers
    try:
        return args.func(args)
    except (ValueError, TypeError, OSError, ImportError) as exc:   # ImportError: a user's MODULE:CALLABLE
        print(f"polar-sim: error: {_error_line(exc, args)[:500]}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("polar-sim: interrupted; finished trials are kept in results.csv", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
