"""The README's main command: `polar-sim demo` runs every part and writes its pictures, with
progress that moves within each part."""

import io
import sys

import pytest

from polar_sim.demo import DEMOS, run_demo


# The whole demo runs headless, every part succeeds and writes its PNGs.
@pytest.mark.slow
def test_demo_runs(tmp_path):
    assert run_demo(tmp_path) == 0
    names = {p.name for p in tmp_path.glob("*.png")}
    assert {"gpis_office2d.png", "ground_prob.png", "tracking_mug.png", "env_gpisnav.png", "office2d_front.png",
            "office2d_overview.png", "rover_terrain_front.png", "rover_terrain_overview.png"} == names
    assert len(DEMOS) >= 4


# A first run (numba's cache without the GPIS kernels) is announced; a cache that holds them is not.
def test_cold_cache_detected(tmp_path, monkeypatch):
    from polar_sim.demo import _kernels_cached

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not _kernels_cached()
    (tmp_path / "gpis_x").mkdir()
    (tmp_path / "gpis_x" / "_distance.query_kernel-32.py311.nbi").write_bytes(b"")
    assert _kernels_cached()


# The two worker lanes run every part exactly once.
def test_lanes_cover_every_part():
    from polar_sim.demo import _LANES

    names = [n for lane in _LANES for n in lane]
    assert sorted(names) == sorted(n for n, _ in DEMOS)


# workers other than 1 or 2 is refused before anything is written.
@pytest.mark.parametrize("bad", [0, 3, -1])
def test_bad_workers(tmp_path, bad):
    with pytest.raises(ValueError, match="workers"):
        run_demo(tmp_path / "out", workers=bad)
    assert not (tmp_path / "out").exists()


# -- progress: per step, labelled, on stderr, quiet off a terminal ------------------------------
def _count_scans(out, progress):
    progress.stage("fake: mapping", 5, "scan")
    for _ in range(5):
        progress.update()
    return ["five scans"]


def _count_frames(out, progress):
    progress.stage("fake: recording", 3, "frame")
    progress.to(3)
    progress.stage("fake: tracking", 4, "frame")
    for _ in range(4):
        progress.update()
    return ["seven frames"]


def _fail(out, progress):
    progress.stage("fake: failing", 2, "step")
    raise RuntimeError("boom")


FAKE = [("scans", _count_scans), ("frames", _count_frames)]


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal (as a user's is)."""

    def isatty(self):
        return True


# On a terminal every step of a part moves its lane's bar, labelled with the part's stage and unit,
# in this process and from the two worker lanes; the summary lines go to stdout.
@pytest.mark.parametrize("workers", [1, 2])
def test_progress_moves_within_a_part(tmp_path, monkeypatch, capsys, workers):
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    assert run_demo(tmp_path, workers=workers, parts=FAKE, lanes=(("scans",), ("frames",))) == 0
    shown = err.getvalue()
    for k in range(1, 6):
        assert f"fake: mapping: {k}/5 scans" in shown
    for k in range(1, 5):
        assert f"fake: tracking: {k}/4 frames" in shown
    assert "fake: recording: 3/3 frames" in shown
    out = capsys.readouterr().out
    assert "[scans] five scans" in out and "[frames] seven frames" in out
    assert "[scans]" not in shown


# --quiet (progress=False), or a stderr that is not a terminal: no bar, no note, nothing on stderr.
def test_quiet(tmp_path, monkeypatch, capsys):
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    assert run_demo(tmp_path, workers=1, parts=FAKE, progress=False) == 0
    assert err.getvalue() == ""
    monkeypatch.undo()
    assert run_demo(tmp_path, workers=1, parts=FAKE) == 0            # pytest's stderr is not a terminal
    assert capsys.readouterr().err == ""


# A failing part is reported by name and the exit code is 1; the other parts still run.
def test_a_failing_part_is_reported(tmp_path, capsys):
    assert run_demo(tmp_path, workers=1, parts=[("bad", _fail)] + FAKE) == 1
    out = capsys.readouterr().out
    assert "[bad] FAILED: RuntimeError: boom" in out and "[frames] seven frames" in out


# The demo's environment is the current GPISNav (v2): making it raises no DeprecationWarning
# (gymnasium's "out of date" nudge is for the older versions: v0 GPS+compass, v1 wheel physics).
def test_demo_env_is_current():
    import warnings

    import gymnasium as gym

    import polar_sim.envs  # noqa: F401
    from polar_sim.demo import ENV_ID

    assert ENV_ID == "polar_sim/GPISNav-v2"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym.make(ENV_ID, render_mode="rgb_array").close()
