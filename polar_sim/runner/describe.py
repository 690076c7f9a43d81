"""What ``--set`` can change in an experiment, as ``polar-sim list`` shows it: the grid axes and
protocol params of a full run on the default split, then what the other sizes and splits change,
every value written the way ``--set`` takes it."""

from __future__ import annotations

import json

__all__ = ["describe_experiment"]


def _show(v, full=False, limit=60):
    """A value as ``--set`` takes it: bare words and numbers, lists as ``[a, b]``; long lists cut
    to their first items and their count unless ``full``."""
    if isinstance(v, str):
        bare = v and not any(ch.isspace() or ch in ',;[]{}"\'' for ch in v) and v not in ("true", "false", "null")
        try:
            json.loads(v)
            bare = False   # "3" or "1.5" would come back as a number
        except ValueError:
            pass
        return v if bare else json.dumps(v)
    if isinstance(v, (list, tuple, range)):
        items = [_show(x, True) for x in v]
        text = "[" + ", ".join(items) + "]"
        if full or len(text) <= limit:
            return text
        head = []
        for it in items:
            if len(", ".join(head + [it])) > limit - 15 and head:
                break
            head.append(it)
        return "[" + ", ".join(head) + f", ... {len(items)} values]"
    if isinstance(v, dict):
        return json.dumps(v)
    return json.dumps(v) if v is None or isinstance(v, bool) else repr(v)


def _seeds_text(seeds, split=None):
    seeds = [int(s) for s in seeds]
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        text = f"{seeds[0]}..{seeds[-1]}"
    else:
        text = ", ".join(map(str, seeds[:4])) + (f", ... {len(seeds)} seeds" if len(seeds) > 4 else "")
    return f"seed {text}" + (f" ({split} split)" if split else "")


def _wrap(label, items, width=110):
    """``label`` and ``items`` joined by "; ", wrapped at ``width`` under the first item."""
    lines, cur = [], f"{label:<7} "
    for i, it in enumerate(items):
        piece = it + (";" if i < len(items) - 1 else "")
        if len(cur) + len(piece) > width and cur.strip() != label:
            lines.append(cur.rstrip())
            cur = " " * 8
        cur += piece + " "
    lines.append(cur.rstrip())
    return lines


def describe_experiment(exp, full=False):
    """Lines saying what ``--set`` can change in ``exp``: its grid axes and protocol params (the
    values of a full-size run on the default split), then what the other sizes and splits change.
    Lists longer than a line are cut unless ``full``."""
    split = exp.pick_split(None)
    grid, seeds = exp.resolve("full", split)
    params = exp.resolve_params("full", split)
    items = [f"{k}={_show(v, full)}" + (f" ({exp.methods[k]} methods)" if k in exp.methods else "")
             for k, v in grid.items()]
    lines = _wrap("grid:", items + [_seeds_text(seeds, split)])
    if params:
        lines += _wrap("params:", [f"{k}={_show(v, full)}" for k, v in params.items()])
    for size, spec in exp.sizes.items():
        if size == "full":
            continue
        changes = [f"{k}={_show(v, full)}" for k, v in exp.resolve_params(size, split).items() if params.get(k) != v]
        sg, sseeds = exp.resolve(size, split)
        changes += [f"{k}={_show(v, full)}" for k, v in sg.items() if grid.get(k) != v]
        if sseeds != seeds:
            changes.append(_seeds_text(sseeds))
        lines += _wrap(f"{size}:", changes or ["as full"])
    for other in exp.splits:
        if other == split:
            continue
        og, oseeds = exp.resolve("full", other)
        changes = [f"{k}={_show(v, full)}" for k, v in exp.resolve_params("full", other).items() if params.get(k) != v]
        changes += [f"{k}={_show(v, full)}" for k, v in og.items() if grid.get(k) != v]
        lines += _wrap(f"{other}:", changes + [_seeds_text(oseeds)])
    return lines
