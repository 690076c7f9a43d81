"""``polar-sim``: the command line. It parses, calls the library and prints; nothing more.

Heavy modules are imported inside each command. A ``ValueError``, ``TypeError``, ``OSError``
(``FileNotFoundError`` included) or ``ImportError`` (a ``--policy MODULE:CALLABLE`` that does not
import) becomes exit code 1 with a one-line message; argparse's usage errors exit 2. ``run`` and ``reproduce`` exit
0 when every trial ran and no check regressed (recorded misses are reported, not failed), and 2
otherwise; ``--strict`` also fails on recorded misses.
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


def _out_dir(path):
    """Check that an --out folder can be created (a one-line error, not a traceback)."""
    if "\x00" in str(path):
        raise ValueError(f"--out: {str(path)[:200]!r} is not a folder path (it holds a NUL byte)")
    p = Path(path).expanduser()
    try:
        if p.exists() and not p.is_dir():
            raise ValueError(f"--out: {str(p)[:200]!r} exists and is not a folder")
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--out: cannot create {str(p)[:200]!r}: {exc.strerror}") from None
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

    res = run_experiment(args.experiment, quick=args.quick, size=args.size, split=args.split, out=args.out,
                         workers=_positive_int(args.workers, "--workers", 1024), backend=args.backend,
                         address=args.address, overrides=_parse_overrides(args.set),
                         trial_timeout=_timeout(args.trial_timeout))
    print(f"{args.experiment}: {len(res.table)} trials ({res.config['split']} split, {res.config['size']} size), "
          f"results in {res.out_dir}")
    _print_checks(res)
    return _exit_code([res], args.strict)


def _cmd_reproduce(args):
    from polar_sim.runner.reproduce import reproduce

    results, report = reproduce(args.out, quick=args.quick, split=args.split, only=args.only,
                                workers=_positive_int(args.workers, "--workers", 1024), backend=args.backend,
                                address=args.address, trial_timeout=_timeout(args.trial_timeout),
                                report_only=args.report_only)
    for name, res in results.items():
        c = [x.status for x in res.checks]
        print(f"{name}: {c.count('pass')} met, {c.count('missed')} missed (recorded), {c.count('slow')} slow (timing), "
              f"{c.count('FAIL')} failed, {len(res.failures)} trial errors")
    print(f"report: {report} (and {report.with_suffix('.html').name})")
    return _exit_code(list(results.values()), args.strict)


def _cmd_compare(args):
    from polar_sim.runner.compare import compare_runs

    _positive_int(args.n_boot, "--n-boot", 10_000_000)
    out = compare_runs(args.run_a, args.run_b, by=args.by, metrics=args.metric, out=args.out,
                       n_boot=args.n_boot, seed=args.seed)
    print(out.read_text())
    return 0


def _cmd_demo(args):
    from polar_sim.demo import run_demo

    return run_demo(_out_dir(args.out), quick=True, workers=args.workers)


def _cmd_eval(args):
    import json

    from polar_sim.envs import ENV_IDS, register_envs
    from polar_sim.envs.evaluate import evaluate

    register_envs()
    if args.env_id not in ENV_IDS:
        raise ValueError(f"env_id: unknown environment {args.env_id!r}; valid: {', '.join(ENV_IDS)}")
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
                             env_kwargs=kwargs, out_dir=out)
    for k, v in summary.items():
        print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
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
    sub = p.add_subparsers(dest="command", required=True)

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
    s.add_argument("--quick", action="store_true", help="the CI size of every experiment")
    s.add_argument("--out", default="polar_sim_out/reproduce")
    s.add_argument("--only", nargs="*", help="a subset of experiments")
    s.add_argument("--report-only", action="store_true",
                   help="run nothing: write the report from the finished run folders in --out")
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
    s.add_argument("env_id", help="e.g. polar_sim/GPISNav-v0 (polar-sim list shows them all)")
    s.add_argument("--policy", required=True, help="MODULE:CALLABLE (a class is instantiated) or 'random'")
    s.add_argument("--episodes", type=int, default=10)
    s.add_argument("--seed", type=int, default=10_000, help="seed of the first episode (default 10000: held out)")
    s.add_argument("--env-kwargs", default=None, help='JSON, e.g. \'{"sdf_source": "truth"}\'')
    s.add_argument("--out", default=None, help="output folder (default polar_sim_out/eval/ENV)")
    s.set_defaults(func=_cmd_eval)

    s = sub.add_parser("compile", help="compile the GPIS kernels ahead of time (once after install: "
                                       "first runs then start in seconds; needs a C compiler)")
    s.add_argument("--out", default=None, help="folder (default $POLAR_SIM_NATIVE_DIR or ~/.cache/polar_sim/native)")
    s.set_defaults(func=_cmd_compile)

    s = sub.add_parser("bench", help="run the speed/memory benchmarks (from a repository clone)")
    s.add_argument("only", nargs="*", help="benchmark names (bench_NAME.py); default all")
    s.add_argument("--quick", action="store_true")
    s.set_defaults(func=_cmd_bench)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, TypeError, OSError, ImportError) as exc:   # ImportError: a user's MODULE:CALLABLE
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"polar-sim: error: {msg[:500]}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("polar-sim: interrupted; finished trials are kept in results.csv", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
