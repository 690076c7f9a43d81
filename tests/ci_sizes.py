"""The CI size of slow end-to-end tests (imported by conftest.py and by tests that need it at
collection time, e.g. in ``parametrize``)."""

import os

FULL = os.environ.get("POLAR_SIM_FULL", "") == "1"


def size(full, reduced):
    """Problem size for a slow end-to-end test: ``full`` with POLAR_SIM_FULL=1, else ``reduced``.

    CI runs every slow test at its reduced size; nothing is skipped.
    """
    return full if FULL else reduced
