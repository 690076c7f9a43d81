"""Where a run came from: polar_sim's version and commit, package versions, the machine."""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

__all__ = ["provenance", "git_commit"]

PACKAGES = ("numpy", "scipy", "mujoco", "gymnasium", "numba", "opencv-python-headless", "trimesh",
            "scikit-image", "matplotlib", "torch", "stable-baselines3", "sb3-contrib", "ray")


def _git(cwd, *args):
    try:
        out = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def git_commit():
    """The commit of the polar_sim source tree in use: the checkout the package is imported from,
    else the current folder if it is a polar_sim clone (an installed wheel run from its clone),
    with ``+dirty`` when tracked files differ; ``None`` when neither is a git checkout."""
    here = Path(__file__).resolve().parents[2]
    for root in (here, Path.cwd()):
        if not (root / "pyproject.toml").is_file() or "polar-sim" not in (root / "pyproject.toml").read_text():
            continue
        commit = _git(root, "rev-parse", "HEAD")
        if commit:
            dirty = _git(root, "status", "--porcelain", "--untracked-files=no")
            return commit + ("+dirty" if dirty else "")
    return None


def _cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib():
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                return round(int(line.split()[1]) / 2**20, 1)
    except OSError:
        pass
    return None


def provenance() -> dict:
    """A JSON-able record of the software and machine of this process."""
    import polar_sim

    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {
        "polar_sim": polar_sim.__version__,
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "packages": versions,
        "machine": {"platform": platform.platform(), "cpu": _cpu_model(), "cpus": os.cpu_count(),
                    "memory_gib": _memory_gib(), "load_average_1min": load},
        "started": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "env": {k: os.environ[k] for k in ("MUJOCO_GL", "POLAR_SIM_CACHE", "POLAR_SIM_DATA", "RAY_ADDRESS")
                if k in os.environ},
    }
