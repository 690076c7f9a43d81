"""Packaging: every package directory is listed in pyproject, and the scenes ship as package data."""

import tomllib
from importlib import resources
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


# pyproject lists every package under polar_sim/ (the list is explicit because of mapped folders).
def test_packages_listed():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(cfg["tool"]["setuptools"]["packages"])
    found = {"polar_sim"} | {
        "polar_sim." + ".".join(p.relative_to(ROOT / "polar_sim").parts)
        for p in (ROOT / "polar_sim").rglob("*") if p.is_dir() and (p / "__init__.py").is_file()
    }
    assert found <= listed, found - listed


# The installed package finds its MJCF scenes and experiments through importlib.resources.
def test_scenes_are_package_data():
    import polar_sim

    try:
        scenes = resources.files("polar_sim.scenes")
    except ModuleNotFoundError:   # a source checkout on PYTHONPATH shadows the installed package
        raise AssertionError(f"polar_sim is imported from {polar_sim.__file__}, not from an install "
                             "(scenes/ is mapped into the package by pip install); unset PYTHONPATH") from None
    files = {p.name for p in scenes.iterdir()}
    assert {"rover_terrain.xml", "rover_flat.xml", "office2d.xml"} <= files
    exps = {p.name for p in resources.files("polar_sim.experiments").iterdir()}
    assert "sensors.py" in exps


# No module outside polar_sim/sim imports mujoco (the modules run on plain numpy).
def test_layering():
    for p in (ROOT / "polar_sim").rglob("*.py"):
        if "sim" in p.relative_to(ROOT / "polar_sim").parts[:1]:
            continue
        text = p.read_text()
        assert "import mujoco" not in text and "from mujoco" not in text, p
