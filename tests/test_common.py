"""One hostile battery over every module, entry point family and env (polar_sim.testing): one
pytest id per named check. A new module is checked by adding an instance to ``MODULES`` below
(its class declares its check data in ``TAGS``), a new env by registering it.

CI size: N_BAD hostile inputs per entry point, all of an entry point's inputs in one worker
subprocess with a time limit (a crash or hang is a failure, never a frozen suite);
POLAR_SIM_FULL=1 runs 200 per entry point, the size of benchmarks/bench_battery.py.
"""

import pytest

from ci_sizes import size
from polar_sim.envs import ENV_IDS
from polar_sim.testing import check_entry_points, check_module, check_polar_env
from polar_sim.testing.contract import module_instances

N_BAD = size(200, 12)

# Checked in CI: every module class of the contract (one instance each, built from its check
# data), then the entry point families that are not modules.
FAMILIES = [
    "World",                      # World(...) options, step, camera, lidar, sdf
    "RangeNoise",
    "Recording",                  # append, save, load
    "metrics.kitti_errors", "metrics.ate", "metrics.rpe", "metrics.iou", "metrics.hausdorff", "metrics.chamfer",
    "metrics.add", "metrics.adds",
    "localize",
    "cli",
]

# Every registered environment id.
ENVS = list(ENV_IDS)


def _checks():
    for obj in module_instances():
        for check in check_module(obj, n_bad=N_BAD):
            yield pytest.param(check, id=check.name)
    for name in FAMILIES:
        for check in check_entry_points(name, n_bad=N_BAD):
            yield pytest.param(check, id=check.name)
    for env_id in ENVS:
        for check in check_polar_env(env_id, n_bad=N_BAD):
            yield pytest.param(check, id=check.name)


@pytest.mark.parametrize("check", list(_checks()))
def test_common(check):
    check()
