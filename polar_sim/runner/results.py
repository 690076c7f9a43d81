"""The results table: one CSV row per finished trial, appended as trials finish."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

__all__ = ["ResultsFile", "trial_key"]


def trial_key(params, seed):
    """A stable string identifying one trial."""
    return json.dumps({"params": params, "seed": int(seed)}, sort_keys=True, default=str)


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


class ResultsFile:
    """``results.csv`` of a run: append-only, header grows when new metric columns appear.

    Each row holds the trial's parameters, ``seed``, ``status`` ("ok" or "error"), ``error``,
    ``elapsed_s``, ``trial_key`` and its metrics.
    """

    def __init__(self, path):
        self.path = Path(path)

    def read(self):
        """All rows as dicts with numbers parsed back."""
        if not self.path.is_file():
            return []
        with open(self.path, newline="") as fh:
            return [{k: _parse(v) for k, v in row.items()} for row in csv.DictReader(fh)]

    def done_keys(self):
        return {r["trial_key"] for r in self.read() if r.get("status") == "ok"}

    def append(self, row):
        for k, v in row.items():
            if isinstance(v, float) and math.isnan(v):
                row[k] = ""
        rows = self.read()
        fields = list(rows[0].keys()) if rows else []
        new = [k for k in row if k not in fields]
        if new and rows:
            # Rewrite with the wider header; rare (a metric seen for the first time).
            fields += new
            tmp = self.path.with_suffix(".csv.part")
            with open(tmp, "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=fields)
                w.writeheader()
                for r in rows + [row]:
                    w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in fields})
            tmp.replace(self.path)
            return
        if not rows:
            fields = list(row)
        with open(self.path, "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields)
            if not rows:
                w.writeheader()
            w.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in fields})
