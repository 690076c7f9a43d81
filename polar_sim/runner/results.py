"""The results table: one CSV row per finished trial, appended as trials finish.

Each row holds the trial's parameters, ``seed``, ``split``, ``size``, ``status`` ("ok" or
"error"), ``error``, ``elapsed_s``, ``trial_key`` and its metrics. Numbers are written with
``repr`` precision, so a float reads back bit for bit.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import re
from pathlib import Path

from polar_sim.fileio import atomic_write

__all__ = ["ResultsFile", "trial_key", "trial_dir", "RESERVED"]

#: Column names the runner writes; a trial's metrics may not reuse them.
RESERVED = frozenset({"seed", "split", "size", "status", "error", "elapsed_s", "trial_key"})


def trial_key(params, seed):
    """A stable string identifying one trial."""
    return json.dumps({"params": params, "seed": int(seed)}, sort_keys=True, default=str)


def trial_dir(out_dir, key) -> Path:
    """The artefact folder of the trial with ``trial_key`` ``key`` inside run folder ``out_dir``."""
    d = json.loads(key)
    slug = "_".join(f"{k}-{v}" for k, v in sorted(d["params"].items()))
    slug = re.sub(r"[^A-Za-z0-9._=-]+", "-", slug)[:100]
    digest = hashlib.sha1(key.encode()).hexdigest()[:10]
    return Path(out_dir) / "trials" / f"{slug}_seed-{d['seed']}_{digest}"


def _parse(value):
    if value == "":
        return None
    for conv in (int, float):
        try:
            return conv(value)
        except ValueError:
            pass
    if value in ("True", "False"):
        return value == "True"
    return value


def _cell(v):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return repr(v) if isinstance(v, float) else v


class ResultsFile:
    """``results.csv`` of a run: append-only; the header grows when new metric columns appear.

    A file that cannot be parsed raises ``ValueError`` naming it, and is never overwritten.
    """

    def __init__(self, path):
        self.path = Path(path)

    def read(self):
        """All rows as dicts with numbers parsed back."""
        if not self.path.is_file():
            return []
        try:
            with open(self.path, newline="") as fh:
                reader = csv.reader(fh)
                header = next(reader, None)
                if header is None:
                    return []
                if "trial_key" not in header or len(set(header)) != len(header):
                    raise ValueError("no trial_key column, or repeated column names")
                rows = []
                for line, cells in enumerate(reader, start=2):
                    if len(cells) != len(header):
                        raise ValueError(f"line {line} has {len(cells)} fields, the header {len(header)}")
                    row = {k: _parse(v) for k, v in zip(header, cells)}
                    if not isinstance(row["trial_key"], str):
                        raise ValueError(f"line {line} has no trial key")
                    rows.append(row)
        except (csv.Error, UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f"results: {self.path} is corrupt ({exc}); move it away or choose another "
                             "--out (it was left as it is)") from None
        return rows

    def done_keys(self, size=None, split=None):
        """The keys of the finished trials. With ``size`` and ``split``, a file holding rows of
        another size or split (a folder whose config.json was lost) raises ``ValueError``
        instead: a trial's key does not include them, so its rows would mix."""
        rows = self.read()
        if size is not None or split is not None:
            other = sorted({(r.get("size"), r.get("split")) for r in rows} - {(size, split)}, key=str)
            if other:
                raise ValueError(f"results: {self.path} holds rows of size/split {other[0][0]}/{other[0][1]}, not "
                                 f"{size}/{split}; choose another --out (it was left as it is)")
        return {r["trial_key"] for r in rows if r.get("status") == "ok"}

    def append(self, row):
        rows = self.read()
        fields = list(rows[0].keys()) if rows else []
        new = [k for k in row if k not in fields]
        if rows and not new:
            with open(self.path, "a", newline="") as fh:
                csv.DictWriter(fh, fieldnames=fields).writerow({k: _cell(row.get(k)) for k in fields})
            return
        # First row, or a metric seen for the first time: rewrite with the wider header, atomically.
        fields += new
        with atomic_write(self.path, "results", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields)
            w.writeheader()
            for r in rows + [row]:
                w.writerow({k: _cell(r.get(k)) for k in fields})
