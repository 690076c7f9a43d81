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
