"""The experiment runner: declared sweeps, a local process pool or Ray, results, reports.

>>> from polar_sim.runner import run_experiment
>>> res = run_experiment("sensors", quick=True, split="dev", out="runs/sensors")
>>> res.passed, res.out_dir / "summary.md"
"""

from polar_sim.runner.experiment import Check, Experiment, Finding, RunContext, TrialContext
from polar_sim.runner.methods import get_method, list_methods, register_method
from polar_sim.runner.registry import get_experiment, list_experiments
from polar_sim.runner.run import RunResult, run_experiment

__all__ = ["Experiment", "Check", "Finding", "TrialContext", "RunContext", "RunResult", "run_experiment",
           "get_experiment", "list_experiments", "register_method", "get_method", "list_methods"]
