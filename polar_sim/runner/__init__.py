"""The experiment runner: declared sweeps, a local process pool or Ray, results, reports."""

from polar_sim.runner.experiment import Check, Experiment, TrialContext

__all__ = ["Experiment", "Check", "TrialContext"]
