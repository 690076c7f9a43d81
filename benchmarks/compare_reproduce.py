"""Compare two ``polar-sim reproduce`` output folders: the same trials, the same figures.

    python benchmarks/compare_reproduce.py BEFORE AFTER [--ignore REGEX]

For every experiment folder (one with a ``results.csv``) in either run, the trials are matched by
``trial_key`` and every cell is compared as written, except the timing columns (names containing
``cpu`` or ``_ms``, and ``load``, ``elapsed_s``, ``map_mb``: they measure the machine, not the
code). The checks (``checks.json``) are compared by name and status, except those marked
``timing``. Prints each differing cell (with the relative difference of numbers) and a summary per
experiment; exits 1 on any difference that is not timing, 0 otherwise. This is the evidence for
"behaviour does not change" (issue 34): run ``polar-sim reproduce --quick --out BEFORE`` on the old
code and ``--out AFTER`` on the new, then this.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
from pathlib import Path

TIMING = r"cpu|_ms|^load$|^elapsed_s$|^map_mb$"


def experiments(root):
    """{name: folder} of the experiment folders (with a ``results.csv``) under ``root``."""
    return {p.parent.name: p.parent for p in sorted(Path(root).glob("*/results.csv"))}


def read_trials(folder):
    """{trial_key: row} of an experiment's ``results.csv``."""
    with open(folder / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {r.get("trial_key") or str(i): r for i, r in enumerate(rows)}


def read_checks(folder):
    """{check name: status} of the checks that do not measure time."""
    p = folder / "checks.json"
    checks = json.loads(p.read_text()) if p.exists() else []
    return {c["name"]: c["status"] for c in checks if not c.get("timing")}


def relative(a, b):
    """|a - b| / max(|a|, |b|) of two numbers written as text, or None when either is not a number."""
    try:
        x, y = float(a), float(b)
    except ValueError:
        return None
    if x == y or (math.isnan(x) and math.isnan(y)):
        return 0.0
    return abs(x - y) / max(abs(x), abs(y))


def compare_experiment(before, after, timing):
    """Lines describing every difference between two runs of one experiment (none: identical)."""
    a, b = read_trials(before), read_trials(after)
    out = [f"trial only in {side}: {k}" for side, keys in (("BEFORE", a.keys() - b.keys()),
                                                          ("AFTER", b.keys() - a.keys())) for k in sorted(keys)]
    cells = same = 0
    for key in sorted(a.keys() & b.keys()):
        ra, rb = a[key], b[key]
        for col in sorted(ra.keys() | rb.keys()):
            if timing.search(col):
                continue
            cells += 1
            va, vb = ra.get(col), rb.get(col)
            if va == vb:
                same += 1
                continue
            rel = relative(va, vb) if va is not None and vb is not None else None
            out.append(f"{key} {col}: {va!r} -> {vb!r}" + (f" (relative {rel:.3g})" if rel is not None else ""))
    ca, cb = read_checks(before), read_checks(after)
    out += [f"check {n!r}: {ca.get(n)} -> {cb.get(n)}" for n in sorted(ca.keys() | cb.keys()) if ca.get(n) != cb.get(n)]
    return out, cells, same


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--ignore", default=TIMING, help=f"regex of the columns not compared (default {TIMING!r})")
    args = ap.parse_args(argv)
    timing = re.compile(args.ignore)
    ea, eb = experiments(args.before), experiments(args.after)
    if not ea and not eb:
        print(f"no experiment folders (*/results.csv) in {args.before} or {args.after}", file=sys.stderr)
        return 1
    differ = 0
    for name in sorted(ea.keys() | eb.keys()):
        if name not in ea or name not in eb:
            print(f"{name}: only in {'AFTER' if name not in ea else 'BEFORE'}")
            differ += 1
            continue
        lines, cells, same = compare_experiment(ea[name], eb[name], timing)
        print(f"{name}: {len(read_trials(ea[name]))} trials, {same}/{cells} cells identical"
              + ("" if not lines else f", {len(lines)} differences:"))
        for line in lines:
            print(f"  {line}")
        differ += bool(lines)
    print(f"{differ} experiment(s) differ" if differ else "identical (timing columns and timing checks excluded)")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
