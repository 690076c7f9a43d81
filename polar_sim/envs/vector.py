"""Vector environments for the 2-core case: AsyncVectorEnv workers pinned to CPUs.

``spawn`` and ``forkserver`` workers re-import the script that starts them, so the code that
builds a vector environment must sit under ``if __name__ == "__main__":``::

    import polar_sim.envs
    from polar_sim.envs.vector import make_async_vector_env

    if __name__ == "__main__":
        venv = make_async_vector_env("polar_sim/GPISNav-v1", 2)
        ...

Without the guard, :func:`make_async_vector_env` raises a ``RuntimeError`` that says so (in the
parent, and in every worker, instead of a bare ``ConnectionResetError``).
"""

from __future__ import annotations

import functools
import multiprocessing
import os

import gymnasium as gym
from gymnasium.vector import AutoresetMode

__all__ = ["make_async_vector_env", "MAIN_GUARD_HELP"]

MAIN_GUARD_HELP = (
    "the vector environment's workers ({context}) re-import the script that starts them, and this one builds "
    "vector environments at import time; put that code under `if __name__ == \"__main__\":` (see "
    "https://docs.python.org/3/library/multiprocessing.html#the-spawn-and-forkserver-start-methods)"
)


def _make_pinned(env_id, cpu, kwargs, parent_pid):
    # AsyncVectorEnv also calls the first factory in the parent (to read the spaces): pin only
    # the workers.
    if cpu is not None and os.getpid() != parent_pid:
        os.sched_setaffinity(0, {cpu})
    return gym.make(env_id, **kwargs)


def make_async_vector_env(env_id, num_envs, *, pin_workers=True, context="spawn", autoreset_mode="next_step",
                          **kwargs):
    """``gymnasium.vector.AsyncVectorEnv`` of ``num_envs`` copies of ``env_id`` (``gym.make``
    keyword arguments in ``kwargs``), in ``spawn`` children (a forked child of a parent holding a
    GL context deadlocks).

    ``autoreset_mode`` is gymnasium's (``"next_step"``, ``"same_step"`` or ``"disabled"``), and
    ``venv.metadata["autoreset_mode"]`` states it. With the default ``"next_step"``, the step
    after a sub-environment terminates or truncates resets it (its action is ignored, its reward
    is 0 and its ``terminated``/``truncated`` are False), as gymnasium 1.x does by default.

    With ``pin_workers`` (Linux), worker k runs on the k-th CPU this process may use (round
    robin). An AsyncVectorEnv steps in lockstep, so every worker sleeps while it waits for the
    slowest; on waking, an unpinned worker is often placed on the other core, away from the
    caches that hold its map and model (2 cores with their own L2 here). Pinning measured
    150 -> 179 and 108 -> 194 steps/s for 2 GPISNav-v0 workers (``benchmarks/bench_envs_gpisnav.py``).

    Raises ``RuntimeError`` (saying what to do) when called while a ``spawn``/``forkserver``
    worker imports the main script, i.e. from a script without the ``__main__`` guard.
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs: expected an integer >= 1, got {num_envs!r}")
    if context not in ("spawn", "forkserver", "fork"):
        raise ValueError(f"context: expected 'spawn', 'forkserver' or 'fork', got {context!r}")
    mode = AutoresetMode(_AUTORESET.get(autoreset_mode, autoreset_mode)) if isinstance(autoreset_mode, str) \
        else AutoresetMode(autoreset_mode)
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise RuntimeError(f"make_async_vector_env: {MAIN_GUARD_HELP.format(context=context)}")
    if ":" not in env_id and env_id.startswith("polar_sim/"):
        env_id = "polar_sim.envs:" + env_id  # the children import polar_sim.envs to register the ids
    cpus = sorted(os.sched_getaffinity(0)) if pin_workers and hasattr(os, "sched_getaffinity") else [None]
    fns = [functools.partial(_make_pinned, env_id, cpus[k % len(cpus)], kwargs, os.getpid())
           for k in range(num_envs)]
    try:
        return gym.vector.AsyncVectorEnv(fns, context=context, autoreset_mode=mode)
    except (ConnectionResetError, EOFError, BrokenPipeError) as exc:
        raise RuntimeError(f"make_async_vector_env: a worker died while starting ({exc!r}); if the workers' "
                           f"output above shows an import-time error, {MAIN_GUARD_HELP.format(context=context)}") from exc


_AUTORESET = {"next_step": "NextStep", "same_step": "SameStep", "disabled": "Disabled"}
