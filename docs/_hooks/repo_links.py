"""MkDocs hook: links from a page to repository files outside ``docs/``.

A page links any file of the repository with an ordinary relative link, which works wherever the
markdown is read on its own (GitHub, an editor). The site holds only ``docs/``, so at build time:

- a link to a file that a page of the site includes whole (``README.md`` is the home page,
  ``benchmarks/RESULTS.md`` the benchmarks page, through ``{% include-markdown %}``) points at that
  page, its anchor kept (the strict build checks the anchor);
- a link to any other file or folder outside ``docs/`` (a test, an example, a benchmark script),
  or to a file that ``exclude_docs`` keeps out of the site, becomes the path, as a code span: the
  reader can open it in the repository;
- a link to a path that does not exist is a warning, which ``mkdocs build --strict`` turns into a
  failed build, like a broken link inside ``docs/``.

Links inside code blocks and code spans are left alone.
"""

from __future__ import annotations

import logging
import os
import re

from mkdocs.plugins import event_priority

log = logging.getLogger("mkdocs.hooks.repo_links")

_LINK = re.compile(r"(!?)\[((?:[^\[\]]|\[[^\]]*\])*)\]\(([^()\s]+)((?:\s+\"[^\"]*\")?)\)")
_CODE_SPAN = re.compile(r"(`+).+?\1")
_FENCE = re.compile(r"^\s*(```|~~~)")
_INCLUDE = re.compile(r"\{%\s*include-markdown\s+\"([^\"]+)\"")

_included: dict[str, str] = {}  # repository path of an included file -> src path of the page including it


def _repo_root(config) -> str:
    return os.path.dirname(os.path.abspath(config.config_file_path))


def on_files(files, config):
    """Find the pages that include a file from outside docs/ whole."""
    _included.clear()
    root, docs = _repo_root(config), os.path.abspath(config.docs_dir)
    for f in files.documentation_pages():
        with open(f.abs_src_path, encoding="utf-8") as fh:
            for target in _INCLUDE.findall(fh.read()):
                path = os.path.normpath(os.path.join(os.path.dirname(f.abs_src_path), target))
                if not path.startswith(docs + os.sep):
                    _included[os.path.relpath(path, root)] = f.src_path
    return files


def _rewrite(match, page, config):
    bang, text, target, title = match.groups()
    if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith(("#", "/")):
        return match.group(0)
    path_part, _, anchor = target.partition("#")
    here = os.path.dirname(page.file.abs_src_path)
    path = os.path.normpath(os.path.join(here, path_part))
    docs, root = os.path.abspath(config.docs_dir), _repo_root(config)
    if path == docs or path.startswith(docs + os.sep):
        excluded = config.exclude_docs is not None and config.exclude_docs.match_file(os.path.relpath(path, docs))
        if not os.path.isdir(path) and not excluded:
            return match.group(0)  # a page or a file of the site: MkDocs checks it
        for index in ("index.md", "README.md"):  # a folder: its index page, if it has one
            if os.path.isfile(os.path.join(path, index)):
                new = os.path.relpath(os.path.join(path, index), here).replace(os.sep, "/")
                return f"{bang}[{text}]({new}{'#' + anchor if anchor else ''}{title})"
    rel = os.path.relpath(path, root)
    if rel.startswith(".."):
        log.warning("%s: the link '%s' leaves the repository", page.file.src_path, target)
        return match.group(0)
    if rel in _included:
        page_dir = os.path.dirname(page.file.src_path)
        new = os.path.relpath(_included[rel], page_dir or ".").replace(os.sep, "/")
        return f"{bang}[{text}]({new}{'#' + anchor if anchor else ''}{title})"
    if not os.path.exists(path):
        log.warning("%s: the link '%s' points at '%s', which does not exist", page.file.src_path, target, rel)
        return match.group(0)
    if bang:
        log.warning("%s: the image '%s' lies outside docs/ and cannot be shown", page.file.src_path, target)
        return match.group(0)
    shown = rel.replace(os.sep, "/") + ("/" if os.path.isdir(path) else "")
    named = text.strip("`").rstrip("/")
    if named and ("/" + shown.rstrip("/")).endswith("/" + named):   # the text is the path, or its tail
        return f"`{shown}`"
    return f"{text} (`{shown}`)"


def _rewrite_line(line, page, config):
    spans = [m.span() for m in _CODE_SPAN.finditer(line)]

    def outside_code(m):
        if any(a <= m.start() < b for a, b in spans):
            return m.group(0)
        return _rewrite(m, page, config)

    return _LINK.sub(outside_code, line)


@event_priority(-100)  # after include-markdown has put the included files in and rebased their links
def on_page_markdown(markdown, page, config, files):
    out, fence = [], None
    for line in markdown.split("\n"):
        m = _FENCE.match(line)
        if m:
            fence = None if fence == m.group(1) else (fence or m.group(1))
            out.append(line)
        elif fence:
            out.append(line)
        else:
            out.append(_rewrite_line(line, page, config))
    return "\n".join(out)
