"""Griffe extension: the reST habits of our numpydoc docstrings, read as Markdown in the API reference.

The docstrings are written for ``help()`` and numpydoc, and the API pages render them as
Markdown. Three reST forms would render wrongly, so they are rewritten before rendering (the
source is not changed):

- roles such as ``:func:`name` `` or ``:class:`~polar_sim.gpis.GPISMap2D` `` become code spans
  (with ``~``, the last component of the path, as Sphinx shows it);
- doctest lines (``>>>`` with their ``...`` continuations and output) become a fenced ``pycon``
  block, where Markdown would read ``>>>`` as three nested quotes;
- a paragraph ending in ``::`` (reST's "a literal block follows") ends in ``:``.
"""

from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:mod|func|class|meth|attr|data|obj|exc|const|ref):`(~?)([^`]+)`")


def _role(match: re.Match) -> str:
    tilde, target = match.groups()
    return f"`{target.rsplit('.', 1)[-1] if tilde else target}`"


def _fence_doctests(lines: list[str]) -> list[str]:
    out, i = [], 0
    while i < len(lines):
        stripped = lines[i].lstrip()
        if not stripped.startswith(">>>"):
            out.append(lines[i])
            i += 1
            continue
        indent = lines[i][: len(lines[i]) - len(stripped)]
        block = []
        while i < len(lines) and lines[i].strip():  # the example runs to the next blank line
            block.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i].lstrip())
            i += 1
        if out and out[-1].strip():
            out.append("")
        out += [indent + "```pycon", *(indent + b for b in block), indent + "```"]
    return out


def markdown_docstring(text: str) -> str:
    """The docstring ``text`` with reST roles, doctest lines and ``::`` rewritten for Markdown."""
    text = _ROLE.sub(_role, text)
    lines = _fence_doctests(text.split("\n"))
    lines = [re.sub(r"(\S)::$", r"\1:", line) for line in lines]
    return "\n".join(lines)


class RstToMarkdown(griffe.Extension):
    """Rewrite every docstring griffe loads (see the module docstring)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown_docstring(obj.docstring.value)
