"""The layers as enforced contracts: import-linter (pyproject.toml [tool.importlinter]), private
names across packages, and the modules importing without mujoco or gymnasium installed."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Contracts of pyproject.toml that hold on this branch. The others are written as they must be
# and listed in the issue-17 report (their violations are in files other helpers are changing):
# "private-modules-stay-home" (gpis.localize imports baselines._common) and "no-package-cycles"
# (gpis -> baselines -> gpis). Add an id here once its contract holds.
KEPT_CONTRACTS = ["sim-knows-no-module", "modules-take-arrays", "shared-layer-imports-nothing-above",
                  "private-modules-stay-home", "no-package-cycles"]

# Every package: none uses a private name of another package (see test_no_private_names...).
CLEAN_PACKAGES = ["polar_sim.sim", "polar_sim.gpis", "polar_sim.baselines", "polar_sim.metrics", "polar_sim.registration",
                  "polar_sim.experiments", "polar_sim.ground", "polar_sim.tracking", "polar_sim.envs", "polar_sim.runner",
                  "polar_sim.testing", "polar_sim.cli", "polar_sim.fileio", "polar_sim._validation",
                  "polar_sim.geometry", "polar_sim.demo", "polar_sim.datasets", "polar_sim.control", "polar_sim.params",
                  "polar_sim.errors"]


def _lint(*contracts):
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    args = [a for c in contracts for a in ("--contract", c)]
    return subprocess.run([sys.executable, "-c", code, "--no-cache", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


# Every contract of pyproject.toml that is declared kept is kept (lint-imports exits 0).
@pytest.mark.parametrize("contract", KEPT_CONTRACTS)
def test_import_contract_kept(contract):
    r = _lint(contract)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "KEPT" in r.stdout and "BROKEN" not in r.stdout


# A contract breaks when the code breaks it: a forbidden import planted in a copy is found.
def test_contract_detects_a_violation(tmp_path):
    import shutil

    pkg = tmp_path / "polar_sim"
    shutil.copytree(ROOT / "polar_sim", pkg, ignore=shutil.ignore_patterns("__pycache__", "data"))
    (pkg / "metrics" / "planted.py").write_text("import polar_sim.sim.world\n")
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    r = subprocess.run([sys.executable, "-c", code, "--no-cache", "--contract", "modules-take-arrays"],
                       capture_output=True, text=True, cwd=tmp_path, timeout=300,
                       env={"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin"})
    assert r.returncode != 0 and "polar_sim.metrics.planted -> polar_sim.sim.world" in r.stdout, r.stdout[-2000:]


def _package_of(module):
    """``polar_sim.X`` for ``polar_sim.X[.Y...]``; a top-level module is its own package."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _private_uses(path, module):
    """(line, imported module, name) of private names of other packages used in ``path``."""
    tree = ast.parse(path.read_text(), str(path))
    home = _package_of(module)
    bound = {}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("polar_sim"):
            src = node.module
            for a in node.names:
                if _package_of(src) != home and a.name.startswith("_") and not a.name.startswith("__"):
                    out.append((node.lineno, src, a.name))
                bound[a.asname or a.name] = f"{src}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("polar_sim"):
                    bound[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                and isinstance(node.value, ast.Name) and node.value.id in bound):
            target = bound[node.value.id]
            if target.startswith("polar_sim.") and _package_of(target) != home:
                out.append((node.lineno, target, node.attr))
    return out


def _modules():
    for p in sorted((ROOT / "polar_sim").rglob("*.py")):
        rel = p.relative_to(ROOT).with_suffix("")
        yield p, ".".join(rel.parts).removesuffix(".__init__")
    for p in sorted((ROOT / "experiments").glob("*.py")):
        yield p, "polar_sim.experiments." + p.stem


# No package uses another package's private names (_x): they are not part of its contract.
@pytest.mark.parametrize("package", CLEAN_PACKAGES)
def test_no_private_names_across_packages(package):
    bad = [(str(p.relative_to(ROOT)), *u) for p, m in _modules() if _package_of(m) == package
           for u in _private_uses(p, m)]
    assert not bad, "\n".join(f"{f}:{ln}: {src}.{name}" for f, ln, src, name in bad)


# The private-name scan finds what it must: a planted use is reported.
def test_private_name_scan_detects(tmp_path):
    p = tmp_path / "x.py"
    p.write_text("from polar_sim._validation import _as_float_array\nfrom polar_sim.runner import run\n"
                 "run._trial_dir\nfrom polar_sim.gpis import _io\n")
    found = {(src, name) for _, src, name in _private_uses(p, "polar_sim.gpis.x")}
    assert found == {("polar_sim._validation", "_as_float_array"), ("polar_sim.runner.run", "_trial_dir")}


_BLOCK = """
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('mujoco', 'gymnasium'):
            raise ImportError(f'{name} is blocked: a core install has no MuJoCo and no gymnasium')
        return None
sys.meta_path.insert(0, Block())
import importlib
importlib.import_module(sys.argv[1])
loaded = sorted(m for m in sys.modules if m.split('.')[0] in ('mujoco', 'gymnasium'))
assert not loaded, loaded
print('ok')
"""


# The modules import (and so run on real logs) with mujoco and gymnasium absent.
@pytest.mark.parametrize("module", ["polar_sim.gpis", "polar_sim.ground", "polar_sim.tracking", "polar_sim.baselines",
                                    "polar_sim.metrics", "polar_sim.geometry", "polar_sim.gpis.localize",
                                    "polar_sim.sim.recorders.recording"])
def test_modules_import_without_mujoco_or_gymnasium(module):
    r = subprocess.run([sys.executable, "-c", _BLOCK, module], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-3000:]


# The blocker works: importing the simulator with mujoco blocked fails.
def test_import_blocker_blocks():
    r = subprocess.run([sys.executable, "-c", _BLOCK, "polar_sim.sim.world"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode != 0 and "blocked" in r.stderr


# allow_pickle is never switched on anywhere in the package.
def test_no_allow_pickle_true():
    hits = [str(p) for p, _ in _modules() if "allow_pickle=True" in p.read_text()]
    assert not hits, hits
