"""Long runs at CI size (the full size is benchmarks/bench_soak.py): RSS after warm-up stays within
10 % for every env, a GPIS map over loops of a tiled world, and world build/render/close cycles;
closed vector envs leave no worker behind; and the detector catches a deliberate leak."""

import json
import subprocess
import sys

import pytest

from ci_sizes import size

ENV_STEPS = size(20_000, 150)
GPIS_SCANS = size(10_000, 600)


def _in_subprocess(expr):
    """Run a soak in a fresh interpreter (a small, clean baseline RSS); returns its result dict."""
    code = ("import json, dataclasses; import numpy as np; from polar_sim.testing.soak import *; r = " + expr + "; "
            "print(json.dumps({'ok': r.ok, 'growth': r.growth, 'report': r.report()}))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


# The detector works: 1 MiB kept per step is a leak; 1 MiB allocated and freed per step is not.
# Both run in a fresh interpreter: growth is relative to the process's RSS, and a test worker
# that has imported everything has a baseline large enough to hide 120 MiB.
def test_detector_catches_a_leak():
    leak = _in_subprocess("soak((lambda kept: lambda i: kept.append(np.ones(2**17)))([]), 150, warmup=30, "
                          "name='leaky dummy')")
    assert not leak["ok"] and leak["growth"] > 0.10, leak["report"]
    flat = _in_subprocess("soak(lambda i: np.ones(2**17).sum(), 150, warmup=30, name='flat dummy')")
    assert flat["ok"], flat["report"]


def _env_ids():
    from polar_sim.envs import ENV_IDS

    return list(ENV_IDS)


# Every registered env: seeded random steps with resets, RSS flat after warm-up.
@pytest.mark.parametrize("env_id", _env_ids())
def test_env_soak(env_id):
    r = _in_subprocess(f"soak_env({env_id!r}, {ENV_STEPS}, warmup={ENV_STEPS // 3}, reset_every=50)")
    assert r["ok"], r["report"]


# One GPIS map over repeated loops of a tiled world: it stops growing after the first loops.
def test_gpis_soak():
    r = _in_subprocess(f"soak_gpis({GPIS_SCANS}, loop=200)")
    assert r["ok"], r["report"]


# Building, rendering and closing worlds frees their renderers.
def test_renderer_soak():
    r = _in_subprocess(f"soak_renderers({size(200, 12)})")
    assert r["ok"], r["report"]


# A closed AsyncVectorEnv leaves no live worker process.
def test_vector_workers_closed():
    from polar_sim.testing.soak import vector_workers_closed

    assert vector_workers_closed("polar_sim/LidarNav-v0", n_envs=2, steps=2) == set()
