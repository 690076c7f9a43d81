"""Long runs: resident memory must level off after a warm-up (issue 17, item 8).

:func:`soak` calls a step function many times and samples the process's resident set size (RSS,
from ``/proc/self/statm``) after a garbage collection. Growth is the median of the last samples
over the median of the first samples after the warm-up, minus one; a run passes when it is at
most ``limit`` (10 %). :func:`soak_env` drives an env with seeded random actions and resets;
:func:`soak_gpis` fuses a loop of scans of a tiled world into one GPIS map over and over (the map
grows with the explored area only, so after the first loop it must stop growing);
:func:`soak_renderers` builds, renders and closes worlds; :func:`vector_workers_closed` checks
that a closed ``AsyncVectorEnv`` leaves no worker process behind.
"""

from __future__ import annotations

import dataclasses
import gc
import os

import numpy as np

__all__ = ["SoakResult", "rss_bytes", "soak", "soak_env", "soak_gpis", "soak_renderers", "vector_workers_closed"]


def rss_bytes() -> int:
    """Resident set size of this process, bytes."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@dataclasses.dataclass
class SoakResult:
    """``steps`` (k,) and ``rss`` (k,) bytes sampled along a run; ``warm`` and ``final`` RSS (bytes,
    medians of the first and last samples after the warm-up); ``growth`` = final / warm - 1."""

    name: str
    n: int
    warmup: int
    steps: np.ndarray
    rss: np.ndarray
    warm: float
    final: float
    growth: float
    limit: float

    @property
    def ok(self) -> bool:
        return self.growth <= self.limit

    def report(self) -> str:
        return (f"{self.name}: {self.n} steps (warm-up {self.warmup}): RSS {self.warm / 2**20:.1f} MiB after "
                f"warm-up -> {self.final / 2**20:.1f} MiB, growth {100 * self.growth:+.1f} % "
                f"(limit {100 * self.limit:.0f} %): {'ok' if self.ok else 'LEAK'}")


def soak(step, n, *, warmup, samples=20, limit=0.10, name="soak"):
    """Call ``step(i)`` for i in 0..n-1 and judge the RSS growth after ``warmup`` calls."""
    if not 0 < warmup < n:
        raise ValueError(f"warmup: expected 0 < warmup < n = {n}, got {warmup}")
    marks = set(np.linspace(warmup, n, samples, dtype=int).tolist())
    steps, rss = [], []
    for i in range(n):
        step(i)
        if i + 1 in marks:
            gc.collect()
            steps.append(i + 1)
            rss.append(rss_bytes())
    rss = np.asarray(rss, np.float64)
    k = max(1, len(rss) // 4)
    warm, final = float(np.median(rss[:k])), float(np.median(rss[-k:]))
    return SoakResult(name, n, warmup, np.asarray(steps), rss, warm, final, final / warm - 1.0, limit)


def soak_env(env_id, n, *, warmup=None, reset_every=200, seed=0, limit=0.10, **kwargs):
    """``n`` seeded random steps of env ``env_id`` with a reset at every episode end and every
    ``reset_every`` steps; returns a :class:`SoakResult`."""
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401  (registers the ids)

    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    episode = [0]

    def step(i):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc or (i + 1) % reset_every == 0:
            episode[0] += 1
            env.reset(seed=seed + episode[0])

    try:
        return soak(step, n, warmup=warmup or max(1, n // 4), limit=limit, name=env_id)
    finally:
        env.close()


def _tiled_scans(n_scans=200, beams=360, tile=4.0, pillar=0.5, radius=6.0, max_range=8.0):
    """A closed loop of exact scans (angles, ranges, pose2d) through a lattice of round pillars
    (one per ``tile`` x ``tile`` m cell): the same ground is covered on every loop."""
    ang = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    centres = np.array([(i * tile + tile / 2, j * tile + tile / 2) for i in range(-4, 4) for j in range(-4, 4)])
    out = []
    for k in range(n_scans):
        phi = 2 * np.pi * k / n_scans
        # a loop between the pillar rows (radius chosen to stay clear of the pillars' discs)
        pose = np.array([radius * np.cos(phi), radius * np.sin(phi), phi + np.pi / 2])
        d = np.stack([np.cos(ang + pose[2]), np.sin(ang + pose[2])], 1)
        o = pose[:2][None, :] - centres                                        # (m, 2)
        b = d @ o.T                                                            # (beams, m)
        disc = b * b - ((o * o).sum(1) - pillar**2)[None, :]
        t = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
        t = np.where((disc >= 0) & (t > 0), t, np.inf).min(1)
        t[t > max_range] = np.inf
        out.append((ang, t, pose))
    return out


def soak_gpis(n, *, loop=200, warmup=None, limit=0.10):
    """``n`` scans into one ``GPISMap2D``, repeating a loop of ``loop`` scans of a tiled world."""
    from polar_sim.gpis import GPISMap2D

    scans = _tiled_scans(loop)
    m = GPISMap2D()

    def step(i):
        a, r, p = scans[i % loop]
        m.update(a, r, p)

    return soak(step, n, warmup=warmup or min(n - 1, 2 * loop), limit=limit, name="GPISMap2D tiled loop")


def soak_renderers(n, *, scene="office2d", warmup=None, limit=0.10):
    """``n`` times: build a ``World``, render its cameras and cast its lidars, close it."""
    from polar_sim.sim import World

    def step(i):
        with World(scene, seed=i % 3, kinematic=True) as w:
            for c in w.cameras:
                w.camera(c, width=64, height=48)
            for lid in w.lidars:
                w.lidar(lid)

    return soak(step, n, warmup=warmup or max(1, n // 3), limit=limit, name=f"World({scene!r}) build/render/close")


def _children():
    """Pids of this process's live (non-zombie) child processes."""
    kids = set()
    for task in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{task}/children") as fh:
                kids |= {int(p) for p in fh.read().split()}
        except OSError:
            pass
    live = set()
    for pid in kids:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().rsplit(")", 1)[1].split()[0] != "Z":
                    live.add(pid)
        except OSError:
            pass
    return live


def vector_workers_closed(env_id, *, n_envs=2, steps=3, seed=0):
    """Run an ``AsyncVectorEnv`` (spawn workers) for a few steps and close it; returns the worker
    pids still alive afterwards (an empty set when nothing leaked)."""
    import gymnasium as gym

    import polar_sim.envs  # noqa: F401

    fns = [lambda: gym.make(f"polar_sim.envs:{env_id}") for _ in range(n_envs)]
    venv = gym.vector.AsyncVectorEnv(fns, context="spawn")
    # the workers themselves (multiprocessing's resource tracker, also a child, lives on by design)
    workers = {p.pid for p in venv.processes}
    assert workers <= _children(), "the worker processes were not found among the children"
    try:
        venv.reset(seed=seed)
        for _ in range(steps):
            venv.step(venv.action_space.sample())
    finally:
        venv.close()
    return workers & _children()
