"""The cost of the documentation checks: each page's code run as tests/test_docs.py runs it (one
fresh interpreter per page, at the CI size), and the strict site build.

Usage: python benchmarks/bench_docs.py [--full]   (--full: every block at its shown size, as
POLAR_SIM_FULL=1 runs them; --quick, as polar-sim bench --quick passes it, is the default CI size)
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

import docs_snippets as ds  # noqa: E402


def _children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd, cwd, env):
    """(return code, CPU seconds of the child and its children, wall seconds)."""
    c0, t0 = _children_cpu(), time.perf_counter()
    rc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True).returncode
    return rc, _children_cpu() - c0, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="run every block at its shown size")
    ap.add_argument("--quick", action="store_true", help="the CI size, as without --full (for polar-sim bench --quick)")
    args = ap.parse_args()
    env = {**os.environ, "MPLBACKEND": "Agg", "POLAR_SIM_FULL": "1" if args.full else ""}
    print(f"load average {os.getloadavg()[0]:.1f}")
    cpu = wall = 0.0
    for page in [p for p in ds.doc_pages() if ds.python_blocks(p)]:
        with tempfile.TemporaryDirectory() as tmp:
            rc, c, w = timed([sys.executable, str(REPO / "tests" / "docs_snippets.py"), str(page)], tmp, env)
        cpu, wall = cpu + c, wall + w
        print(f"{str(page):32s} {'ok' if rc == 0 else 'FAILED':6s} CPU {c:6.1f} s  wall {w:6.1f} s", flush=True)
    print(f"pages: CPU {cpu:.1f} s, wall {wall:.1f} s (one after the other)")
    with tempfile.TemporaryDirectory() as tmp:
        rc, c, w = timed([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", tmp], REPO, env)
    print(f"mkdocs build --strict: {'ok' if rc == 0 else 'FAILED'}, CPU {c:.1f} s, wall {w:.1f} s")
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
