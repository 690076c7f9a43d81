"""Read the code in the Markdown pages (README.md and docs/) and run it as a reader would paste it.

The rules a page follows (docs/contributing-docs.md):

- Every ```` ```python ```` block runs. The blocks of one page run in order in one namespace, in a
  fresh temporary folder, with ``__name__ == "__main__"``, as if pasted into one session.
- A block whose first line starts with ``# Fragment`` is shown to the reader as a fragment and is
  only compiled, not run.
- A ```` ```text title="Output" ```` block right after a Python block is what that block prints:
  the test compares it with the captured stdout (doctest's ``...`` elides any text).
- A block that is slow at the size shown carries a CI size: an HTML comment right before it,
  ``<!-- ci-size: OLD -> NEW -->`` (one replacement per line; each OLD must occur exactly once in
  the block). CI runs the block with the replacements, ``POLAR_SIM_FULL=1`` runs it as shown.
  A block with a shown output runs at its shown size.
- Shell blocks (```` ```bash ````) are not run, but each ``polar-sim`` command in them, and in
  inline code, must parse, and name a known experiment, scene or environment; each ``python
  path.py`` names an existing file; each ``pip install ".[extra]"`` names a declared extra.
"""

from __future__ import annotations

import contextlib
import doctest
import io
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

from markdown_it import MarkdownIt

REPO = Path(__file__).resolve().parents[1]
# Generated run folders: reports written by the runner, not pages a person wrote.
GENERATED = ("docs/results/", "docs/reproduce_full/", "docs/reproduce_quick/")
_CI_SIZE = re.compile(r"^<!--\s*ci-size\b[^\n]*?:?\s*(.*?)-->\s*$", re.S)
_SHELL = ("bash", "sh", "shell", "console")


def doc_pages():
    """README.md and every hand-written page under docs/, as paths relative to the repository."""
    pages = [Path("README.md")] + sorted(p.relative_to(REPO) for p in (REPO / "docs").rglob("*.md"))
    return [p for p in pages if not str(p).startswith(GENERATED)]


@dataclass
class Block:
    """One fenced Python block of a page."""

    page: Path
    line: int                 # 0-based line of the opening fence
    code: str
    output: str | None = None  # what it prints, from the Output block after it
    ci_size: list[tuple[str, str]] = field(default_factory=list)

    @property
    def fragment(self) -> bool:
        return self.code.lstrip().lower().startswith("# fragment")

    def where(self) -> str:
        return f"{self.page}:{self.line + 1}"

    def source(self, full: bool) -> str:
        """The code to run: as shown with ``full``, else with its CI-size replacements."""
        code = self.code
        if not full:
            for old, new in self.ci_size:
                n = code.count(old)
                if n != 1:
                    raise AssertionError(f"{self.where()}: ci-size '{old}' occurs {n} times in the block, not once")
                code = code.replace(old, new)
        return code


def _tokens(path: Path):
    return MarkdownIt("commonmark").parse((REPO / path).read_text(encoding="utf-8"))


def _ci_size(html: str):
    m = _CI_SIZE.match(html.strip())
    if not m:
        return None
    pairs = [tuple(s.strip() for s in line.split(" -> ", 1)) for line in m.group(1).splitlines() if " -> " in line]
    if not pairs:
        raise AssertionError(f"a ci-size comment without an 'OLD -> NEW' line: {html.strip()!r}")
    return pairs


def python_blocks(path: Path) -> list[Block]:
    """The page's Python blocks in order, with their shown outputs and CI sizes attached."""
    blocks, prev, pending = [], None, None
    for tok in _tokens(path):
        if tok.type == "html_block":
            pending = _ci_size(tok.content) or pending
            prev = tok
            continue
        if tok.type != "fence":
            prev = tok
            continue
        lang, _, attrs = tok.info.strip().partition(" ")
        if lang in ("python", "py"):
            blocks.append(Block(path, tok.map[0], tok.content, ci_size=pending or []))
            pending = None
        elif lang == "text" and 'title="Output"' in attrs:
            last = blocks[-1] if blocks else None
            if last is None or prev is None or prev.type != "fence" or prev.map[0] != last.line:
                raise AssertionError(f"{path}:{tok.map[0] + 1}: an Output block must follow a python block")
            if last.ci_size:
                raise AssertionError(f"{last.where()}: a block with a shown output runs at its shown size (no ci-size)")
            last.output = tok.content
        elif pending:
            raise AssertionError(f"{path}:{tok.map[0] + 1}: a ci-size comment must stand right before a python block")
        prev = tok
    if pending:
        raise AssertionError(f"{path}: a ci-size comment with no python block after it")
    return blocks


def run_block(block: Block, namespace: dict, full: bool) -> str:
    """Run one block in ``namespace``; return what it printed. Tracebacks name the page's lines."""
    source = "\n" * (block.line + 1) + block.source(full)
    code = compile(source, str(REPO / block.page), "exec")
    if block.fragment:
        return ""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(code, namespace)
    return out.getvalue()


def run_page(page: Path, full: bool, log=None) -> None:
    """Run a page's blocks in order in one namespace; raise AssertionError on a wrong shown output.

    ``log``, a text stream, receives what each block printed.
    """
    namespace = {"__name__": "__main__"}
    for block in python_blocks(page):
        printed = run_block(block, namespace, full)
        if log is not None:
            print(f"--- {block.where()}{' (fragment, not run)' if block.fragment else ''}\n{printed}", file=log)
        if block.output is not None and not output_matches(block.output, printed):
            raise AssertionError(f"{block.where()}: the shown output is not what the block prints:\n"
                                 f"--- shown\n{block.output}--- printed\n{printed}")


def output_matches(want: str, got: str) -> bool:
    """doctest's comparison with ELLIPSIS (``...`` stands for any text), trailing blanks ignored."""
    def norm(s):
        return "\n".join(line.rstrip() for line in s.strip("\n").splitlines()) + "\n"
    return doctest.OutputChecker().check_output(norm(want), norm(got), doctest.ELLIPSIS)


# --- shell commands ------------------------------------------------------------------------------

@dataclass
class Command:
    """One command shown in a shell block or an inline code span."""

    where: str
    argv: list[str]
    synopsis: bool = False    # an inline span that names a command's form, e.g. `polar-sim run`


def _split_commands(text: str, where: str, synopsis_ok: bool):
    text = re.sub(r"\\\n", " ", text)
    for line in text.splitlines():
        try:
            tokens = shlex.split(line, comments=True)
        except ValueError:
            continue
        cmd = []
        for tok in tokens + [";"]:
            if tok in ("&&", "||", ";", "|"):
                while cmd and re.match(r"^[A-Z_][A-Z0-9_]*=", cmd[0]):   # VAR=value before a command
                    cmd.pop(0)
                if cmd:
                    synopsis = synopsis_ok and (len(cmd) <= 2 or any(t.startswith("[") and "--" in t for t in cmd))
                    yield Command(where, cmd, synopsis)
                cmd = []
            else:
                cmd.append(tok)


def shell_commands(path: Path) -> list[Command]:
    """Commands in the page's shell blocks, and in inline code spans that start with a command."""
    found = []
    for tok in _tokens(path):
        if tok.type == "fence" and tok.info.strip().split(" ")[0] in _SHELL:
            found += _split_commands(tok.content, f"{path}:{tok.map[0] + 1}", False)
        elif tok.type == "inline":
            for child in tok.children or []:
                if child.type == "code_inline" and re.match(r"^(polar-sim|python|pip) ", child.content):
                    found += _split_commands(child.content, f"{path}:{tok.map[0] + 1}", True)
    return found


def _extras():
    import tomllib

    return set(tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"])


def check_command(cmd: Command) -> str | None:
    """What is wrong with a shown command, or None."""
    prog, args = cmd.argv[0], cmd.argv[1:]
    if prog == "polar-sim":
        return _check_polar_sim(args, cmd.synopsis)
    if prog in ("python", "python3"):
        if args[:2] == ["-m", "pip"]:
            return _check_pip(args[2:])
        if args and args[0] == "-m":
            import importlib.util

            mod = args[1] if len(args) > 1 else ""
            if mod.startswith("polar_sim") and importlib.util.find_spec(mod) is None:
                return f"python -m {mod}: no such module"
            return None
        if args and args[0].endswith(".py") and not (REPO / args[0]).is_file():
            return f"python {args[0]}: no such file in the repository"
        return None
    if prog == "pip":
        return _check_pip(args)
    return None


def _check_pip(args):
    if args[:1] != ["install"]:
        return None
    for a in args[1:]:
        m = re.match(r"^\.\[([^\]]*)\]$", a)
        if m:
            unknown = set(m.group(1).split(",")) - _extras()
            if unknown:
                return f"pip install {a}: no extra {sorted(unknown)} in pyproject.toml"
    return None


def _check_polar_sim(args, synopsis):
    from polar_sim.cli import build_parser

    parser = build_parser()
    subcommands = parser._subparsers._group_actions[0].choices
    if not args or args[0] not in subcommands:
        return f"polar-sim {' '.join(args)}: no subcommand {args[:1]}; there are {sorted(subcommands)}"
    if synopsis:
        return None
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            ns = parser.parse_args(args)
    except SystemExit:
        return f"polar-sim {' '.join(args)}: {err.getvalue().strip().splitlines()[-1]}"
    return _check_names(ns)


def _placeholder(name):
    return name is None or name.isupper()     # DIR, RUN_A, EXPERIMENT


def _check_names(ns):
    """The experiment, scene or environment a command names exists (placeholders such as DIR pass)."""
    if ns.command in ("run", "list") and not _placeholder(getattr(ns, "experiment", getattr(ns, "name", None))):
        from polar_sim.runner import list_experiments

        name = ns.experiment if ns.command == "run" else ns.name
        if name not in list_experiments():
            return f"polar-sim {ns.command} {name}: no such experiment"
    if ns.command == "reproduce" and ns.only:
        from polar_sim.runner import list_experiments

        unknown = set(ns.only) - set(list_experiments())
        if unknown:
            return f"polar-sim reproduce --only: no experiment {sorted(unknown)}"
    if ns.command == "render" and not _placeholder(ns.scene) and not ns.scene.endswith(".xml"):
        from polar_sim.sim import list_scenes

        if ns.scene not in list_scenes():
            return f"polar-sim render {ns.scene}: no such scene"
    if ns.command == "eval" and not _placeholder(ns.env_id):
        from polar_sim.envs import ENV_IDS

        if ns.env_id not in ENV_IDS:
            return f"polar-sim eval {ns.env_id}: no such environment id"
    if ns.command == "eval" and ":" in ns.policy and not _placeholder(ns.policy):
        try:
            resolve(ns.policy.replace(":", "."))
        except (ImportError, AttributeError):
            return f"polar-sim eval --policy {ns.policy}: cannot import it"
    return None


if __name__ == "__main__":
    # One page in a fresh interpreter, as a reader pastes it: python tests/docs_snippets.py PAGE
    import os
    import sys

    run_page(Path(sys.argv[1]), os.environ.get("POLAR_SIM_FULL", "") == "1", log=sys.stdout)


def dotted_names(path: Path):
    """``(where, name)`` for every ``polar_sim.x.y`` a page names in inline code (not in quotes, and
    not a placeholder in capitals)."""
    for tok in _tokens(path):
        if tok.type == "inline":
            for child in tok.children or []:
                if child.type == "code_inline":
                    for name in re.findall(r"(?<![\w./:\"'])polar_sim(?:\.[A-Za-z_]\w*)+", child.content):
                        if not any(part.isupper() for part in name.split(".")):   # PACKAGE.MODULE
                            yield f"{path}:{tok.map[0] + 1}", name


def resolve(name: str):
    """The object a dotted name names: the longest importable module, then attributes."""
    import importlib

    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(name)
