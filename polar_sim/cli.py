"""``polar-sim``: the command line. It parses, calls the library and prints; nothing more.

Heavy modules are imported inside each command. A ``PolarSimError`` or ``ValueError`` becomes
exit code 1 with a one-line message.
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
    from polar_sim.sim.scenes import describe_scene, list_scenes, scene_options

    print("scenes:")
    for s in list_scenes():
        opts = ", ".join(f"{k}={v!r}" for k, v in scene_options(s).items())
        print(f"  {s:<14} {describe_scene(s)}" + (f"  [options: {opts}]" if opts else ""))
    print("experiments:")
    for e in list_experiments():
        print(f"  {e:<22} {get_experiment(e).description}")
    return 0


def _cmd_render(args):
    from polar_sim.sim import World
    from polar_sim.sim.pictures import render_scene_pictures

    with World(args.scene, seed=args.seed) as w:
        for _ in range(args.steps):
            w.step()
        paths = render_scene_pictures(w, args.out, width=args.width, height=args.height)
    for p in paths:
        print(p)
    return 0


def _parse_overrides(items):
    import json

    out = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--set: expected KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
    return out


def _print_checks(res):
    for c in res.checks:
        print(f"  [{'pass' if c.passed else 'FAIL'}] {c.name}: {c.detail}")


def _cmd_run(args):
    from polar_sim.runner import run_experiment

    res = run_experiment(args.experiment, quick=args.quick, out=args.out, workers=args.workers,
                         backend=args.backend, overrides=_parse_overrides(args.set))
    print(f"{args.experiment}: {len(res.table)} trials, results in {res.out_dir}")
    _print_checks(res)
    return 0 if res.passed else 2


def _cmd_reproduce(args):
    from polar_sim.runner import list_experiments, run_experiment
    from polar_sim.runner.report import build_report

    root = Path(args.out)
    results = []
    names = args.only or list_experiments()
    for name in names:
        res = run_experiment(name, quick=args.quick, out=root / name, workers=args.workers, backend=args.backend)
        print(f"{name}: {sum(c.passed for c in res.checks)}/{len(res.checks)} checks passed")
        results.append(res)
    report = build_report(results, root)
    print(f"report: {report}")
    return 0 if all(r.passed for r in results) else 2


def _cmd_demo(args):
    from polar_sim.demo import run_demo

    return run_demo(Path(args.out), quick=True)


def _cmd_eval(args):
    import json

    import polar_sim  # noqa: F401  (registers the environment ids)
    from polar_sim.envs.evaluate import evaluate

    kwargs = json.loads(args.env_kwargs) if args.env_kwargs else {}
    out = args.out or f"polar_sim_out/eval/{args.env_id.replace('/', '_')}"
    rows, summary = evaluate(args.env_id, args.policy, episodes=args.episodes, seed=args.seed,
                             env_kwargs=kwargs, out_dir=out)
    for k, v in summary.items():
        print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
    print(f"per-episode metrics: {out}/episodes.csv")
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

    s = sub.add_parser("list", help="list scenes and experiments")
    s.set_defaults(func=_cmd_list)

    s = sub.add_parser("demo", help="a short headless run of every part; PNGs in ./polar_sim_out/")
    s.add_argument("--out", default="polar_sim_out", help="output folder (default ./polar_sim_out)")
    s.set_defaults(func=_cmd_demo)

    s = sub.add_parser("render", help="pictures of a scene from its cameras")
    s.add_argument("scene", help="scene name (see `polar-sim list`) or MJCF path")
    s.add_argument("--out", default="polar_sim_out/render")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--steps", type=int, default=0, help="steps to run (scripted scenes) before rendering")
    s.add_argument("--width", type=int, default=640)
    s.add_argument("--height", type=int, default=480)
    s.set_defaults(func=_cmd_render)

    s = sub.add_parser("run", help="run one experiment")
    s.add_argument("experiment")
    s.add_argument("--quick", action="store_true", help="the small CI size")
    s.add_argument("--out", default=None, help="run folder (default polar_sim_out/runs/NAME/TIMESTAMP); reused to resume")
    s.add_argument("--workers", type=int, default=1)
    s.add_argument("--backend", choices=["local", "ray"], default="local")
    s.add_argument("--set", nargs="*", metavar="KEY=VALUE", help="override grid axes, e.g. --set spacing_m=[1.0]")
    s.set_defaults(func=_cmd_run)

    s = sub.add_parser("reproduce", help="run every experiment and write one report")
    s.add_argument("--quick", action="store_true")
    s.add_argument("--out", default="polar_sim_out/reproduce")
    s.add_argument("--workers", type=int, default=1)
    s.add_argument("--backend", choices=["local", "ray"], default="local")
    s.add_argument("--only", nargs="*", help="a subset of experiments")
    s.set_defaults(func=_cmd_reproduce)

    s = sub.add_parser("eval", help="closed-loop evaluation of a policy in an environment")
    s.add_argument("env_id", help="e.g. polar_sim/GPISNav-v0")
    s.add_argument("--policy", required=True, help="MODULE:CALLABLE (a class is instantiated) or 'random'")
    s.add_argument("--episodes", type=int, default=10)
    s.add_argument("--seed", type=int, default=10_000, help="seed of the first episode (default 10000: held out)")
    s.add_argument("--env-kwargs", default=None, help='JSON, e.g. \'{"sdf_source": "truth"}\'')
    s.add_argument("--out", default=None, help="output folder (default polar_sim_out/eval/ENV)")
    s.set_defaults(func=_cmd_eval)

    s = sub.add_parser("bench", help="run the speed/memory benchmarks (from a repository clone)")
    s.add_argument("only", nargs="*", help="benchmark names (bench_NAME.py); default all")
    s.add_argument("--quick", action="store_true")
    s.set_defaults(func=_cmd_bench)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"polar-sim: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("polar-sim: interrupted; finished trials are kept in results.csv", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
