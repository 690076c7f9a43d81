"""The recorded-input cache: one key, one file; built once under a lock; corrupt entries rebuilt."""

import multiprocessing as mp

import numpy as np
import pytest

from polar_sim.sim.recorders import sequences
from polar_sim.sim.recorders.recording import Recording


def _build(n=3, seed=0):
    rng = np.random.default_rng(seed)
    rec = Recording(meta={"n": n})
    for i in range(n):
        rec.append({"x": rng.normal(size=4), "t": float(i)})
    return rec


# The first call builds and saves, the second reads the same frames without building.
def test_cached_builds_once(tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    calls = []
    build = lambda: calls.append(1) or _build()  # noqa: E731
    a = sequences.cached("toy", {"scene": "s", "seed": 1}, build)
    b = sequences.cached("toy", {"seed": 1, "scene": "s"}, build)      # key order does not matter
    assert calls == [1] and len(a) == len(b) == 3
    np.testing.assert_array_equal(a.stack("x"), _build().stack("x"))
    assert b.meta["cache_key"]["key"] == {"scene": "s", "seed": 1}
    assert sequences.cached("toy", {"scene": "s", "seed": 1}, build, version=2) is not None and calls == [1, 1]
    assert a.path.parent == tmp_path / "toy"


# A corrupt cache file is rebuilt, not trusted.
def test_corrupt_entry_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    r = sequences.cached("toy", {"seed": 2}, _build)
    r.close()
    r.path.write_bytes(r.path.read_bytes()[:50])
    again = sequences.cached("toy", {"seed": 2}, _build)
    assert len(again) == 3


def _worker(args):
    root, out = args
    import os
    import time

    os.environ["POLAR_SIM_CACHE"] = root

    def slow():
        with open(out, "a") as fh:
            fh.write("built\n")
        time.sleep(0.5)
        return {"v": np.arange(5)}

    return int(sequences.cached_arrays("toy_arrays", {"seed": 3}, slow)["v"].sum())


# Parallel processes that need the same missing entry wait for one builder.
def test_lock_builds_once_across_processes(tmp_path):
    log = tmp_path / "log.txt"
    with mp.get_context("spawn").Pool(3) as pool:
        sums = pool.map(_worker, [(str(tmp_path / "cache"), str(log))] * 3)
    assert sums == [10, 10, 10] and log.read_text().count("built") == 1


# Bad kinds, keys and builders are refused by name.
def test_bad_input(tmp_path, monkeypatch):
    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    with pytest.raises(ValueError, match="kind"):
        sequences.cached("../escape", {}, _build)
    with pytest.raises(TypeError, match="key"):
        sequences.cached("toy", {"f": object()}, _build)
    with pytest.raises(TypeError, match="build"):
        sequences.cached("toy", {"seed": 9}, lambda: {"x": 1})
    with pytest.raises(TypeError, match="object"):
        sequences.cached_arrays("toy", {"seed": 9}, lambda: {"x": np.array([None])})
