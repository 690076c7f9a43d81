"""``python -m polar_sim.testing --worker NAME N SEED START``: the battery's worker process."""

import sys

from polar_sim.testing.battery import _worker

if len(sys.argv) == 6 and sys.argv[1] == "--worker":
    _worker(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))
else:
    sys.exit("usage: python -m polar_sim.testing --worker NAME N SEED START (run by polar_sim.testing.run_battery)")
