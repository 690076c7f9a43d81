"""GPIS map files at full size (issue 17, "Saved state"): kills mid-save and tampered files.

    python benchmarks/bench_gpis_io.py                  # 20 kills, every tamper case
    python benchmarks/bench_gpis_io.py --kills 5 --json out.json

1. A subprocess re-saves a ~9 MB 3D map over one path in a loop and is SIGKILLed at a random
   (seeded) moment, ``--kills`` times; after each kill the file must load and answer queries
   bit for bit like the reference map.
2. Every tampered copy of a valid 2D default, 2D legacy and 3D map (tests/gpis/iofaults.py,
   re-saved with np.savez so zip checksums are valid) is loaded (and, if accepted, updated and
   queried) in worker subprocesses with a time limit. Outcomes: clear (ValueError naming the
   file), unclear, accepted (silently), crash, hang.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from tests.gpis import iofaults  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    out = {}
    with tempfile.TemporaryDirectory() as td:
        td = Path(td)
        from gpis.test_behaviour import _map3d

        ref = td / "ref.npz"
        _map3d(3).save(ref)
        t0 = time.perf_counter()
        res = iofaults.kill_mid_save(ref, td / "target.npz", args.kills, dim=3, seed=args.seed)
        out["kills"] = {"n": len(res), "intact": sum(r[1] for r in res), "mid_write": sum(r[3] for r in res),
                        "file_bytes": ref.stat().st_size,
                        "failures": [r for r in res if not r[1]], "seconds": round(time.perf_counter() - t0, 1)}
        print(f"kill mid-save: {out['kills']['intact']}/{len(res)} intact, {out['kills']['mid_write']} landed "
              f"mid-write ({ref.stat().st_size} bytes)", flush=True)
        names = iofaults.write_bases(td, n2=3, n3=1)
        cases = iofaults.all_cases(td, names)
        t0 = time.perf_counter()
        r = iofaults.run_tampered(td, names)
        cnt = collections.Counter(r.values())
        per = collections.Counter(cases[i][0] for i in r)
        out["tamper"] = {"n": len(r), "per_base": dict(per), **{k: cnt.get(k, 0) for k in
                         ("clear", "unclear", "accepted", "crash", "hang")},
                         "not_clear": {f"{cases[i][0]}:{cases[i][1]}": o for i, o in r.items() if o != "clear"},
                         "seconds": round(time.perf_counter() - t0, 1)}
        print("tampered files:", json.dumps({k: v for k, v in out["tamper"].items()}), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
