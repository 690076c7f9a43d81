"""Atomic saves: a save killed at any moment leaves the previous file intact, and the next
successful save removes what it left behind, never the temporary file of a save in flight; new
files get the mode the umask gives."""

import os
import stat
import subprocess
import sys
import time

import numpy as np
import pytest

from ci_sizes import size
from polar_sim.fileio import atomic_write, check_destination, check_source, remove_orphans, temp_name, write_text

WRITERS = {
    # a 12 MB recording, re-saved in a loop
    "recording": r"""
import sys, numpy as np
from polar_sim.sim.recorders.recording import Recording
rng = np.random.default_rng(int(sys.argv[2]))
obj = Recording(meta={"gen": int(sys.argv[2])})
for i in range(40):
    obj.append({"depth": rng.uniform(0, 4, (240, 320)).astype(np.float32), "t": float(i)})
""",
    # a GPIS map of a few scans of a circular room
    "gpis": r"""
import sys, numpy as np
from polar_sim.gpis import GPISMap2D
obj = GPISMap2D()
ang = np.deg2rad(np.arange(-135.0, 135.0, 0.5))
for k in range(3 + int(sys.argv[2])):
    obj.update(ang, np.full(ang.shape, 2.0 + 0.1 * k), (0.0, 0.0, 0.3 * k))
""",
}
LOOP = r"""
print("ready", flush=True)
while True:
    obj.save(sys.argv[1])
"""


def _strays(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def _load(kind, path):
    if kind == "recording":
        from polar_sim.sim.recorders.recording import Recording

        rec = Recording.load(path)
        assert len(rec) == 40 and rec.meta["gen"] in (0, 1, 2)
    else:
        from polar_sim.gpis import GPISMap2D

        assert GPISMap2D.load(path).n_updates_ in (3, 4, 5)


# A process re-saving a file is killed (SIGKILL) at random moments: the file on disk always loads
# whole (the old or the new version). The kills leave temporary files (a killed process cannot
# remove them); the next successful save in another process removes every one of them.
@pytest.mark.parametrize("kind, kills", [("recording", size(20, 8)), ("gpis", size(20, 6))])
def test_killed_saves_leave_no_orphans_after_the_next_save(tmp_path, kind, kills):
    path = tmp_path / "target.npz"
    rng = np.random.default_rng(1)
    orphans = 0
    for k in range(kills):
        p = subprocess.Popen([sys.executable, "-c", WRITERS[kind] + LOOP, str(path), str(k % 3)],
                             stdout=subprocess.PIPE, text=True)
        try:
            assert p.stdout.readline().strip() == "ready"
            while not path.exists():
                time.sleep(0.02)
            time.sleep(rng.uniform(0.0, 0.6))
        finally:
            p.kill()
            p.wait()
        _load(kind, path)
        orphans = max(orphans, len(_strays(tmp_path)))
    # the kills left temporary files only if one landed mid-write: force one that did
    p = subprocess.Popen([sys.executable, "-c", WRITERS[kind] + r"""
from polar_sim import fileio
cm = fileio.atomic_write(sys.argv[1]); fh = cm.__enter__(); fh.write(b"partial"); fh.flush()
print("ready", flush=True); sys.stdin.read()
""", str(path), "0"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    p.kill()
    p.wait()
    assert _strays(tmp_path), "a save killed mid-write leaves its temporary file"
    subprocess.run([sys.executable, "-c", WRITERS[kind] + "obj.save(sys.argv[1])", str(path), "1"], check=True)
    _load(kind, path)
    assert _strays(tmp_path) == []
    assert sorted(x.name for x in tmp_path.iterdir()) == ["target.npz"]


# A save in flight in another process keeps its temporary file while this process saves the same
# destination (its lock is held), and then completes: the last save wins, nothing is left behind.
def test_a_concurrent_save_in_flight_is_left_alone(tmp_path):
    path = tmp_path / "f.bin"
    p = subprocess.Popen([sys.executable, "-c", r"""
import sys
from polar_sim.fileio import atomic_write
with atomic_write(sys.argv[1]) as fh:
    fh.write(b"slow writer, part 1; ")
    fh.flush()
    print("writing", flush=True)
    sys.stdin.readline()
    fh.write(b"part 2")
print("done", flush=True)
""", str(path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "writing"
        (inflight,) = _strays(tmp_path)
        write_text(path, "fast writer")                      # a successful save meanwhile
        assert path.read_text() == "fast writer" and _strays(tmp_path) == [inflight]
        assert remove_orphans(path) == [] and _strays(tmp_path) == [inflight]
        p.stdin.write("go\n")
        p.stdin.flush()
        assert p.stdout.readline().strip() == "done"
    finally:
        p.kill()
        p.wait()
    assert path.read_bytes() == b"slow writer, part 1; part 2"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["f.bin"]


# Only the temporary files of the destination being saved are removed: not those of another
# destination whose name starts the same, not a user's file that merely ends in .tmp.
def test_orphan_pattern_is_the_destination_s_own(tmp_path):
    a, ab = tmp_path / "a", tmp_path / "a.b"
    mine = temp_name(a)
    assert mine.name.startswith(".a.") and mine.name.endswith(".tmp") and mine.parent == tmp_path
    others = [temp_name(ab), tmp_path / ".a.notours.tmp", tmp_path / "a.tmp", tmp_path / ".a.0123456789abcdef.tmp.x"]
    for f in [mine] + others:
        f.write_bytes(b"x")
    write_text(a, "new")
    assert not mine.exists() and all(f.exists() for f in others)
    # a destination name too long to take a suffix: its temporary name is still a valid file name
    long = tmp_path / ("n" * 250)
    assert len(temp_name(long).name.encode()) < 255
    temp_name(long).write_bytes(b"x")
    write_text(long, "y")
    assert long.read_text() == "y" and _strays(tmp_path) == sorted(f.name for f in others if f.name.endswith(".tmp"))


# New files get the mode the umask gives (0644 under umask 022), not mkstemp's 0600.
@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_mode_follows_the_umask(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        with atomic_write(tmp_path / "b.npz") as fh:
            fh.write(b"x")
        write_text(tmp_path / "c.txt", "x")
        with open(tmp_path / "ref", "w"):
            pass
    finally:
        os.umask(old)
    for name in ("b.npz", "c.txt", "ref"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


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
    write_text(p, "é\n")
    assert p.read_bytes() == "é\n".encode()
    with pytest.raises(ValueError, match="mode"):
        with atomic_write(p, mode="a"):
            pass


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
    with pytest.raises(ValueError, match="out: cannot write in '/proc/self'"):
        write_text("/proc/self/x.json", "{}", "out")
    with pytest.raises(FileNotFoundError, match="src"):
        check_source(tmp_path / "none", "src")
    with pytest.raises(ValueError, match="regular"):
        check_source("/dev/null")
