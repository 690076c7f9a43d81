"""Helpers for experiment summaries: tables, grouped statistics, figures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["markdown_table", "nonempty_columns", "is_empty", "group_rows", "fmt", "cell", "savefig", "write_csv_table"]


def fmt(x, digits=4):
    """Compact number formatting for tables."""
    if x is None:
        return ""
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if math.isnan(x):
            return "nan"
        if x != 0 and (abs(x) < 1e-3 or abs(x) >= 1e5):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}g}"
    return str(x)


def cell(x):
    """A value formatted for a markdown table cell: ``|`` escaped, no line breaks."""
    return fmt(x).replace("|", "\\|").replace("\n", " ")


def is_empty(x):
    """True for a value a table cell would show as nothing: None, an empty string or NaN."""
    if x is None or (isinstance(x, str) and not x.strip()):
        return True
    return isinstance(x, (float, np.floating)) and math.isnan(x)


def nonempty_columns(rows, columns, headers=None):
    """``columns`` (and their ``headers``) without those that are empty (:func:`is_empty`) in every
    row: a quick run's table shows only what exists at its size (e.g. no 100 m KITTI segment on a
    60 m route). With no rows, or when every column is empty, nothing is dropped."""
    headers = list(headers or columns)
    keep = [i for i, c in enumerate(columns) if any(not is_empty(r.get(c)) for r in rows)]
    if not keep:
        return list(columns), headers
    return [columns[i] for i in keep], [headers[i] for i in keep]


def markdown_table(rows, columns, headers=None, *, drop_empty=True):
    """A markdown table of ``rows`` (dicts) restricted to ``columns``; ``|`` in cells is escaped.

    ``drop_empty``: leave out the columns that are empty (None, "" or NaN) in every row.
    """
    if headers is not None and len(headers) != len(columns):
        raise ValueError(f"headers: expected {len(columns)} headers, one per column, got {len(headers)}")
    rows = list(rows)
    if drop_empty:
        columns, headers = nonempty_columns(rows, list(columns), headers)
    headers = headers or columns
    out = ["| " + " | ".join(cell(h) for h in headers) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        out.append("| " + " | ".join(cell(r.get(c)) for c in columns) + " |")
    return "\n".join(out)


def write_csv_table(rows, columns, path):
    """The same table as CSV, every column kept: a data file keeps one schema at every size."""
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([r.get(c, "") for c in columns])


def group_rows(rows, by, metrics, stats=("mean",)):
    """Aggregate metrics over rows sharing the values of ``by``.

    ``stats`` names numpy reductions: "mean", "median", "std", "min", "max", "p90", "p99", "n".
    Returns a list of dicts ``{by..., f"{metric}_{stat}": value}`` in first-seen order.
    """
    groups = {}
    for r in rows:
        key = tuple(r.get(b) for b in by)
        groups.setdefault(key, []).append(r)
    out = []
    for key, rs in groups.items():
        d = dict(zip(by, key))
        for m in metrics:
            vals = np.array([r[m] for r in rs if isinstance(r.get(m), (int, float)) and r.get(m) is not None], float)
            for s in stats:
                name = f"{m}_{s}" if len(stats) > 1 or s != "mean" else m
                if s == "n":
                    d[name] = int(len(vals))
                elif len(vals) == 0:
                    d[name] = float("nan")
                elif s.startswith("p"):
                    d[name] = float(np.percentile(vals, float(s[1:])))
                else:
                    d[name] = float(getattr(np, s)(vals))
        out.append(d)
    return out


def savefig(fig, out_dir, name):
    """Save a matplotlib figure as PNG into ``out_dir`` and return the markdown image line."""
    path = Path(out_dir) / f"{name}.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return f"![{name}]({path.name})"
