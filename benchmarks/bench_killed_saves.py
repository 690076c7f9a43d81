"""Saves killed mid-write (issue 34): temporary files left behind, and after the next save.

A subprocess re-saves one destination in a loop (a 12 MB ``Recording``, or a ``GPISMap2D``) and is
SIGKILLed at a random (seeded) moment, ``--kills`` times, each kill followed by a check that the
destination still loads. Reported per kind: kills that left a temporary file, temporary files
present after the last kill, and after one more successful save in a new process (the clean-up of
``polar_sim.fileio.atomic_write``; it must be 0). The mode of the destination is printed too
(the umask's, 0644 under umask 022; ``mkstemp`` gave 0600).

    python benchmarks/bench_killed_saves.py [--kills 20] [--kind recording|gpis]
"""

from __future__ import annotations

import argparse
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BUILD = {
    "recording": r"""
import sys, numpy as np
from polar_sim.sim.recorders.recording import Recording
rng = np.random.default_rng(int(sys.argv[2]))
obj = Recording(meta={"gen": int(sys.argv[2])})
for i in range(40):
    obj.append({"depth": rng.uniform(0, 4, (240, 320)).astype(np.float32), "t": float(i)})
""",
    "gpis": r"""
import sys, numpy as np
from polar_sim.gpis import GPISMap2D
obj = GPISMap2D()
ang = np.deg2rad(np.arange(-135.0, 135.0, 0.25))
for k in range(20 + int(sys.argv[2])):
    obj.update(ang, np.full(ang.shape, 2.0 + 0.05 * k), (0.0, 0.0, 0.3 * k))
""",
}
LOOP = 'print("ready", flush=True)\nwhile True:\n    obj.save(sys.argv[1])\n'
LOAD = {"recording": "from polar_sim.sim.recorders.recording import Recording as C\nC.load(sys.argv[1])\n",
        "gpis": "from polar_sim.gpis import GPISMap2D as C\nC.load(sys.argv[1])\n"}


def _strays(folder):
    return sorted(p.name for p in Path(folder).iterdir() if p.name.endswith(".tmp"))


def run(kind, kills, seed=0):
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "target.npz"
        left = 0
        for k in range(kills):
            before = len(_strays(d))
            p = subprocess.Popen([sys.executable, "-c", BUILD[kind] + LOOP, str(path), str(k % 3)],
                                 stdout=subprocess.PIPE, text=True)
            assert p.stdout.readline().strip() == "ready"
            while not path.exists():
                time.sleep(0.02)
            time.sleep(rng.uniform(0.0, 1.0))
            p.kill()
            p.wait()
            subprocess.run([sys.executable, "-c", "import sys\n" + LOAD[kind], str(path)], check=True)
            left += len(_strays(d)) > before
        after_kills = len(_strays(d))
        subprocess.run([sys.executable, "-c", BUILD[kind] + "obj.save(sys.argv[1])", str(path), "0"], check=True)
        return {"kind": kind, "kills": kills, "kills_leaving_a_temp_file": left, "temp_files_after_kills": after_kills,
                "temp_files_after_next_save": len(_strays(d)), "mode": oct(stat.S_IMODE(path.stat().st_mode))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--kind", choices=sorted(BUILD), nargs="*", default=sorted(BUILD))
    args = ap.parse_args()
    for kind in args.kind:
        print(run(kind, args.kills), flush=True)


if __name__ == "__main__":
    main()
