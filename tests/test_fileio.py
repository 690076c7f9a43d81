"""Atomic saves: a save killed at any moment leaves the previous file intact and no temporary file."""

import subprocess
import sys
import time

import numpy as np
import pytest

from polar_sim.fileio import atomic_write, check_destination, check_source

WRITER = r"""
import sys, numpy as np
from polar_sim.sim.recording import Recording
rng = np.random.default_rng(int(sys.argv[2]))
rec = Recording(meta={"gen": int(sys.argv[2])})
for i in range(40):
    rec.append({"depth": rng.uniform(0, 4, (240, 320)).astype(np.float32), "t": float(i)})
print("ready", flush=True)
while True:
    rec.save(sys.argv[1])
"""


# 20 times: a process re-saving a 12 MB recording is killed at a random moment; the file on disk
# always loads whole (the old or the new version), and no temporary file is left beside it.
def test_killed_mid_save_keeps_the_old_file(tmp_path):
    from polar_sim.sim.recording import Recording

    path = tmp_path / "rec.npz"
    rng = np.random.default_rng(1)
    for k in range(20):
        p = subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(k % 3)], stdout=subprocess.PIPE, text=True)
        assert p.stdout.readline().strip() == "ready"
        if not path.exists():
            while not path.exists():
                time.sleep(0.05)
        time.sleep(rng.uniform(0.0, 1.5))
        p.kill()
        p.wait()
        rec = Recording.load(path)
        assert len(rec) == 40 and rec.meta["gen"] in (0, 1, 2)
        for stray in tmp_path.glob(".*.tmp"):
            stray.unlink()            # a SIGKILL cannot clean up; the destination is what matters
    assert [x.name for x in tmp_path.iterdir()] == ["rec.npz"]


# An exception inside the block leaves the destination as it was and removes the temporary file.
def test_error_leaves_destination(tmp_path):
    p = tmp_path / "a.bin"
    p.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_write(p) as fh:
            fh.write(b"new partial")
            raise RuntimeError("disk on fire")
    assert p.read_bytes() == b"old" and [x.name for x in tmp_path.iterdir()] == ["a.bin"]
    with atomic_write(p) as fh:
        fh.write(b"new")
    assert p.read_bytes() == b"new"


# Destinations and sources: integers, NUL bytes, directories and devices are refused by name.
def test_destination_checks(tmp_path):
    with pytest.raises(TypeError, match="out"):
        check_destination(3, "out")
    with pytest.raises(TypeError):
        check_destination(True)
    with pytest.raises(ValueError, match="not a file path"):
        check_destination("a\x00b")
    with pytest.raises(ValueError, match="directory"):
        check_destination(tmp_path)
    with pytest.raises(ValueError, match="regular"):
        check_destination("/dev/zero")
    with pytest.raises(ValueError, match="cannot"):
        with atomic_write(tmp_path / ("x" * 300) / "f.npz") as fh:
            fh.write(b"")
    with pytest.raises(FileNotFoundError, match="src"):
        check_source(tmp_path / "none", "src")
    with pytest.raises(ValueError, match="regular"):
        check_source("/dev/null")
