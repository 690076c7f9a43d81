"""The reliability diagram, drawn on the runner side (moved out of polar_sim.metrics, which draws nothing)."""

import numpy as np
import pytest

from polar_sim import metrics
from polar_sim.runner.pictures_calibration import plot_reliability


# the plot draws one line per curve plus the diagonal, with labelled axes; labels must match the curves
def test_plot_reliability():
    import matplotlib

    matplotlib.use("Agg")
    rng = np.random.default_rng(1)
    p = rng.uniform(size=1000)
    r = metrics.reliability(p, rng.uniform(size=1000) < p)
    ax = plot_reliability([r, r], ["a", "b"])
    assert len(ax.lines) == 3 and ax.get_xlabel() and ax.get_ylabel()
    assert len(plot_reliability(r).lines) == 2
    with pytest.raises(ValueError, match="labels"):
        plot_reliability([r, r], ["a"])
