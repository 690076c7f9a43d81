"""Helpers for experiment summaries: tables, grouped statistics, figures, and values with units.

Findings and check figures carry their units (:func:`length`, :func:`percent`, :func:`duration`,
:func:`number`): "3.48 cm", "99.7 %", "2.81 ms", never a raw ``0.03483``.

>>> length(0.03483), length(0.0044, "cm", decimals=2), percent(0.997), duration(0.00281), number(12345.6)
('3.48 cm', '0.44 cm', '99.7 %', '2.81 ms', '12346')
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["markdown_table", "nonempty_columns", "is_empty", "group_rows", "fmt", "cell", "savefig", "write_csv_table",
           "number", "length", "percent", "duration"]


def number(x, digits=3, decimals=None) -> str:
    """``x`` to ``digits`` significant digits, in plain notation (no ``e-05``): ``0.0123``,
    ``12346``; or with a fixed number of ``decimals`` (figures set side by side)."""
    x = float(x)
    if not math.isfinite(x):
        return str(x)
    if decimals is None:
        decimals = 0 if x == 0 else max(0, digits - 1 - math.floor(math.log10(abs(x))))
    return f"{x:.{decimals}f}"


_LENGTH_UNITS = {"um": 1e-6, "mm": 1e-3, "cm": 1e-2, "m": 1.0, "km": 1e3}


def length(metres, unit=None, digits=3, decimals=None) -> str:
    """A length given in metres, as text with its unit: ``length(0.03483)`` is ``"3.48 cm"``.

    ``unit``: ``"um"``, ``"mm"``, ``"cm"``, ``"m"`` or ``"km"``; by default the one that reads best
    (mm below 1 cm, cm below 1 m, m below 1 km). Give one unit (and ``decimals``) to figures
    that are compared.
    """
    x = float(metres)
    if unit is None:
        a = abs(x)
        unit = "um" if 0 < a < 1e-3 else "mm" if a < 1e-2 else "cm" if a < 1 else "m" if a < 1e3 else "km"
    if unit not in _LENGTH_UNITS:
        raise ValueError(f"unit: expected one of {', '.join(_LENGTH_UNITS)}, got {unit!r}")
    return f"{number(x / _LENGTH_UNITS[unit], digits, decimals)} {'µm' if unit == 'um' else unit}"


def percent(fraction, digits=1) -> str:
    """A fraction (0..1) as a percentage with ``digits`` decimals: ``percent(0.997)`` is ``"99.7 %"``."""
    return f"{100 * float(fraction):.{digits}f} %"


def duration(seconds, unit=None, digits=3, decimals=None) -> str:
    """A time given in seconds, as text with its unit: ``duration(0.00281)`` is ``"2.81 ms"``.
    ``unit``: ``"us"``, ``"ms"``, ``"s"`` or ``"min"``; by default the one that reads best."""
    x = float(seconds)
    scale = {"us": 1e-6, "ms": 1e-3, "s": 1.0, "min": 60.0}
    if unit is None:
        a = abs(x)
        unit = "us" if 0 < a < 1e-3 else "ms" if a < 1 else "s" if a < 120 else "min"
    if unit not in scale:
        raise ValueError(f"unit: expected one of {', '.join(scale)}, got {unit!r}")
    return f"{number(x / scale[unit], digits, decimals)} {'µs' if unit == 'us' else unit}"


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
