"""Progress bars: on stderr only when it is a terminal, never with POLAR_SIM_QUIET=1; a tabletop
recording (minutes at full length) counts its frames."""

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios

import pytest

SCRIPT = r"""
from polar_sim.sim.recorders.tabletop_sequences import record_sequence
rec = record_sequence("mug_touch", seed=0, n_frames=3, width=64, height=48)
print("frames", len(rec))
"""


def _run(stderr_tty, quiet):
    """Run SCRIPT with stderr on a pseudo-terminal (or a pipe); return (stdout, stderr text)."""
    env = dict(os.environ, MUJOCO_GL="egl")
    env.pop("POLAR_SIM_QUIET", None)
    if quiet:
        env["POLAR_SIM_QUIET"] = "1"
    if not stderr_tty:
        r = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=300)
        return r.stdout, r.stderr
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))   # a 100-column terminal
    p = subprocess.Popen([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, stderr=slave, env=env, text=True)
    os.close(slave)
    err = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:             # the child closed the terminal
            break
        if not chunk:
            break
        err += chunk
    out = p.stdout.read()
    p.wait(timeout=300)
    os.close(master)
    return out, err.decode(errors="replace")


# On a terminal the recording shows a bar of its frames; piped, or with POLAR_SIM_QUIET=1, nothing.
@pytest.mark.parametrize("tty, quiet, shown", [(True, False, True), (False, False, False), (True, True, False)])
def test_recording_progress(tty, quiet, shown):
    out, err = _run(tty, quiet)
    assert "frames 3" in out
    assert ("recording mug_touch" in err and "3/3" in err and "frame" in err) == shown, err[-500:]


# The switch itself: quiet() follows the variable, and enabled=False turns a bar off.
def test_progress_switch(monkeypatch):
    from polar_sim.progress import QUIET_ENV, progress_bar, quiet

    monkeypatch.setenv(QUIET_ENV, "1")
    assert quiet() and progress_bar(range(3)).disable
    monkeypatch.delenv(QUIET_ENV)
    assert not quiet() and progress_bar(range(3), enabled=False).disable
    assert list(progress_bar(range(3), enabled=False)) == [0, 1, 2]
