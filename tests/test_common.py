"""One hostile battery over every module, entry point family and env (polar_sim.testing): one
pytest id per named check. A new module or env is checked by adding it to the lists below.

CI size: N_BAD hostile inputs per entry point, all of an entry point's inputs in one worker
subprocess with a time limit (a crash or hang is a failure, never a frozen suite);
POLAR_SIM_FULL=1 runs 200 per entry point, the size of benchmarks/bench_battery.py.
"""

import pytest

from ci_sizes import size
from polar_sim.envs import ENV_IDS
from polar_sim.testing import check_module, check_polar_env

N_BAD = size(200, 12)

# Checked in CI: the simulator's entry points, the shared layers, the modules, the metrics and the CLI.
MODULES = [
    "World",                      # World(...) options, step, camera, lidar, sdf
    "RangeNoise",
    "Recording",                  # append, save, load
    "metrics.kitti_errors", "metrics.ate", "metrics.rpe", "metrics.iou", "metrics.hausdorff", "metrics.chamfer",
    "metrics.add", "metrics.adds",
    "GPISMap2D", "GPISMap3D", "localize", "GroundVO", "ObjectTracker",
    "cli",
]

# Every registered environment id.
ENVS = list(ENV_IDS)


def _checks():
    for name in MODULES:
        for check in check_module(name, n_bad=N_BAD):
            yield pytest.param(check, id=check.name)
    for env_id in ENVS:
        for check in check_polar_env(env_id, n_bad=N_BAD):
            yield pytest.param(check, id=check.name)


@pytest.mark.parametrize("check", list(_checks()))
def test_common(check):
    check()
