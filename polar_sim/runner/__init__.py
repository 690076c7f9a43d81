"""The experiment runner: declared sweeps, a local process pool or Ray, results, reports.

>>> from polar_sim.runner import run_experiment
>>> res = run_experiment("sensors", quick=True, out="runs/sensors")
>>> res.passed, res.out_dir / "summary.md"
"""

from polar_sim.runner.experiment import Check, Experiment, TrialContext
from polar_sim.runner.registry import get_experiment, list_experiments
from polar_sim.runner.run import RunResult, run_experiment

__all__ = ["Experiment", "Check", "TrialContext", "RunResult", "run_experiment", "get_experiment",
           "list_experiments"]
