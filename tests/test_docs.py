"""The documentation's code runs as shown: every Python block of README.md and docs/ executes, each
shown output is what its block prints, every shell command shown parses and names what exists,
and the API reference covers every public module. The rules: ``docs_snippets`` and
docs/contributing-docs.md. The site itself is built by ``mkdocs build --strict`` (.ci/run).
"""

import os
import re
import subprocess
import sys

import pytest

import docs_snippets as ds

PAGES = [p for p in ds.doc_pages() if ds.python_blocks(p)]


# Each page runs as one session in a fresh interpreter: its blocks in order, in one namespace,
# in an empty folder, so that nothing it registers or leaves behind reaches the other tests.
@pytest.mark.parametrize("page", PAGES, ids=str)
def test_page_runs_as_shown(page, tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(ds.REPO / "tests" / "docs_snippets.py"), str(page)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, f"{page} does not run as shown:\n{proc.stderr[-6000:]}"


# Fragments are few, marked for the reader, and still valid Python.
def test_fragments_are_marked_and_compile():
    fragments = [b for p in ds.doc_pages() for b in ds.python_blocks(p) if b.fragment]
    for b in fragments:
        compile(b.code, b.where(), "exec")
    assert len(fragments) <= 5, [b.where() for b in fragments]


# Every command shown in a shell block or inline code parses, and names what exists.
def test_shell_commands_parse():
    commands = [c for p in ds.doc_pages() for c in ds.shell_commands(p)]
    assert any(c.argv[0] == "polar-sim" for c in commands)
    errors = [f"{c.where}: {e}" for c in commands if (e := ds.check_command(c))]
    assert not errors, "\n".join(errors)


# The README's test commands are exactly what CI runs (.ci/run holds nothing else but comments).
def test_ci_runs_the_readme_commands():
    ci = [ln for ln in (ds.REPO / ".ci" / "run").read_text().splitlines()
          if ln.strip() and not ln.startswith(("#", "set ", "cd "))]
    readme = (ds.REPO / "README.md").read_text()
    for line in ci:
        shown = re.sub(r" --durations=\d+", "", line)   # CI also lists the slowest tests
        assert shown in readme, f".ci/run runs a command the README does not show: {shown}"


def _public_modules():
    """Dotted names of the modules under polar_sim/ with no private (_name) part, from the files."""
    names = set()
    for path in (ds.REPO / "polar_sim").rglob("*.py"):
        parts = path.relative_to(ds.REPO).with_suffix("").parts
        parts = parts[:-1] if parts[-1] == "__init__" else parts
        if not any(p.startswith("_") for p in parts):
            names.add(".".join(parts))
    return names


# Every public module is on an API reference page, and every page's module exists.
def test_api_reference_covers_every_public_module():
    shown = set()
    for page in (ds.REPO / "docs" / "api").glob("*.md"):
        shown |= set(re.findall(r"^::: ([\w.]+)", page.read_text(), re.M))
    public = _public_modules()
    assert not public - shown, f"public modules missing from docs/api/: {sorted(public - shown)}"
    assert not shown - public, f"docs/api/ names modules that do not exist: {sorted(shown - public)}"


# The rules themselves can fail: a wrong shown output, a ci-size that does not match once, an
# output block after no code, and fragments that are compiled but not run.
def test_snippet_rules_are_enforced(tmp_path):
    page = tmp_path / "page.md"

    def run(text):
        page.write_text(text)
        ds.run_page(page, full=False)

    out = '```python\nprint("a"); print("b")\n```\n\n```text title="Output"\n{}\n```\n'
    run(out.format("a\nb"))
    run(out.format("a\n..."))
    with pytest.raises(AssertionError, match="not what the block prints"):
        run(out.format("a\nc"))
    with pytest.raises(AssertionError, match="occurs 2 times"):
        run('<!-- ci-size: x -> y -->\n```python\nx = 1; x = 2\n```\n')
    with pytest.raises(AssertionError, match="must follow a python block"):
        run('Text.\n\n```text title="Output"\na\n```\n')
    run('```python\n# Fragment: needs a map m\nm.query(points)\n```\n')
    with pytest.raises(SyntaxError):
        run('```python\n# Fragment: not even Python\nm.query(\n```\n')
    page.write_text('<!-- ci-size: range(1000) -> range(3) -->\n```python\nn = len(range(1000))\n```\n')
    assert ds.python_blocks(page)[0].source(full=False) == "n = len(range(3))\n"
    assert ds.python_blocks(page)[0].source(full=True) == "n = len(range(1000))\n"


# The command checks catch an unknown experiment, option, env id, script and extra.
def test_command_checks_catch_mistakes():
    def error(line):
        return ds.check_command(ds.Command("test", line.split()))

    assert error("polar-sim run localisation --quick") is None
    assert error("polar-sim reproduce --report-only --out DIR") is None
    assert error("python examples/train_ppo_gpisnav.py --tier room") is None
    assert "no such experiment" in error("polar-sim run localization --quick")
    assert "unrecognized arguments" in error("polar-sim run localisation --fast")
    assert "no such environment" in error("polar-sim eval polar_sim/GPISNav-v9 --policy random")
    assert "cannot import" in error("polar-sim eval polar_sim/GPISNav-v1 --policy polar_sim.envs.policies:Nope")
    assert "no such scene" in error("polar-sim render office3d")
    assert "no such file" in error("python benchmarks/bench_nothing.py")
    assert "no extra" in error('pip install .[tests]')


# Every polar_sim.x.y a page names in inline code exists (a renamed module or class fails here).
def test_dotted_names_resolve():
    errors = []
    for page in ds.doc_pages():
        for where, name in ds.dotted_names(page):
            try:
                ds.resolve(name)
            except (ImportError, AttributeError) as exc:
                errors.append(f"{where}: {name}: {exc}")
    assert not errors, "\n".join(errors)
