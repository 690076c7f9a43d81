"""The README's main command: `polar-sim demo` runs every part and writes its pictures."""

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
