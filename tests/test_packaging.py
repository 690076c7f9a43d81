"""Packaging: every package directory is listed in pyproject, and the scenes ship as package data."""

import ast
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


# The package finds its MJCF scenes and experiments through importlib.resources, in a source checkout
# (polar_sim/scenes and polar_sim/experiments are links to the top-level folders) and in an install
# (pyproject maps the same folders into the package): one import path either way.
def test_scenes_and_experiments_are_package_data():
    scenes = resources.files("polar_sim.scenes")
    files = {p.name for p in scenes.iterdir()}
    assert {"rover_terrain.xml", "rover_flat.xml", "office2d.xml"} <= files
    exps = {p.name for p in resources.files("polar_sim.experiments").iterdir()}
    assert "sensors.py" in exps


# The links in the source tree point at the top-level folders that pyproject maps into the package.
def test_source_links_match_the_package_mapping():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    mapping = cfg["tool"]["setuptools"]["package-dir"]
    for sub in ("scenes", "experiments"):
        link = ROOT / "polar_sim" / sub
        assert link.is_symlink() and link.resolve() == (ROOT / mapping[f"polar_sim.{sub}"]).resolve(), link


# A source checkout on PYTHONPATH, without any install, imports the experiments the same way.
def test_source_checkout_imports_experiments(tmp_path):
    import subprocess
    import sys

    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); "
            "import polar_sim, polar_sim.experiments as e, pathlib; "
            "from polar_sim.runner.registry import list_experiments; "
            "print(pathlib.Path(polar_sim.__file__).parent, pathlib.Path(e.__path__[0]).resolve(), "
            "len(list_experiments()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    pkg, path, n = out.stdout.split()
    assert Path(pkg) == ROOT / "polar_sim"          # the checkout, not an installed copy
    assert Path(path) == (ROOT / "experiments").resolve() and int(n) >= 16


def mujoco_imports(path):
    """(line, statement) of every import of mujoco in a Python file: ``import mujoco[.x]``,
    ``from mujoco[.x] import ...`` and ``importlib.import_module("mujoco...")`` / ``__import__``,
    found in its syntax tree (so strings and comments that mention them do not count)."""
    tree = ast.parse(Path(path).read_text(), str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, f"import {a.name}") for a in node.names if a.name.split(".")[0] == "mujoco"]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0 \
                and node.module.split(".")[0] == "mujoco":
            out.append((node.lineno, f"from {node.module} import ..."))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str) and node.args[0].value.split(".")[0] == "mujoco":
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name in ("import_module", "__import__"):
                out.append((node.lineno, f"{name}({node.args[0].value!r})"))
    return out


def _python_files():
    """Every .py file of the repository but those under polar_sim/sim/ (and hidden or build folders)."""
    skip = {".git", "build", "dist", "__pycache__", ".venv", "venv", "node_modules"}
    for p in sorted(ROOT.rglob("*.py")):
        rel = p.relative_to(ROOT)
        if any(part in skip or part.startswith(".") or part.endswith(".egg-info") for part in rel.parts[:-1]):
            continue
        if rel.parts[:2] == ("polar_sim", "sim"):
            continue
        yield p


# Nothing outside polar_sim/sim/ imports mujoco: not the modules, the metrics, the envs, the runner,
# nor the experiments, benchmarks, examples or tests (they go through polar_sim.sim).
def test_layering():
    files = list(_python_files())
    tops = {p.relative_to(ROOT).parts[0] for p in files}
    assert {"polar_sim", "experiments", "benchmarks", "examples", "tests"} <= tops, tops   # the scan sees them all
    bad = [f"{p.relative_to(ROOT)}:{line}: {stmt}" for p in files for line, stmt in mujoco_imports(p)]
    assert not bad, ("only polar_sim/sim/ may import mujoco; use the polar_sim.sim API (or add a function "
                     "there) in:\n  " + "\n  ".join(bad))


# The scan finds every form of the import, and ignores strings and comments that mention one.
def test_layering_scan_detects(tmp_path):
    p = tmp_path / "x.py"
    p.write_text("import os, mujoco.viewer as v\nfrom mujoco import mj_step\nimport importlib\n"
                 "importlib.import_module('mujoco')\n__import__('mujoco.renderer')\ndef f():\n    import mujoco\n"
                 "s = 'import mujoco'  # import mujoco\nfrom mujocox import y\nfrom .mujoco import z\n")
    assert [ln for ln, _ in mujoco_imports(p)] == [1, 2, 4, 5, 7]
