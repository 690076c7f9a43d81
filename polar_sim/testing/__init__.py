"""One hostile battery for every module and environment (after scikit-learn's ``check_estimator``
and gymnasium's ``check_env``).

>>> from polar_sim.gpis import GPISMap2D
>>> from polar_sim.testing import check_module, check_polar_env, run_battery
>>> for check in check_module(GPISMap2D()):       # small named checks; each raises AssertionError
...     check()
>>> for check in check_polar_env("polar_sim/GPISNav-v1"):
...     check()
>>> counts = run_battery("GPISMap2D.update", n=200)   # the full-size battery of one entry point

**Entry points** (:data:`ENTRY_POINTS`) are the public calls of the contract: those of every
module class derived from its signature and ``TAGS`` (:mod:`polar_sim.testing.derive`: the GPIS
maps, ``GroundVO``, ``ObjectTracker``, the baselines), and hand-written ones for ``World`` and its
sensors, ``localize``, the metrics, ``Recording``, every env and the CLI. Each knows how to build its target, a valid call, and the
*kind* of every argument. :func:`bad_inputs` turns a kind and a valid value into hostile inputs
(seeded, so a worker process regenerates the same ones): wrong shapes and dtypes (int, bool,
complex, object, str), NaN/inf, empty arrays, 1e300, negative ranges, non-SE(3) matrices (scaled,
sheared, reflected, NaN), wrong lengths, None, unicode and very long paths, missing, truncated and
foreign files. Every input is marked ``refuse`` (must raise a clear error) or ``either`` (a clear
error or a graceful answer: NaN in ranges means "no return", an int array is a valid array).

**Outcomes** of one call: ``clear`` (``ValueError``/``TypeError``, or ``FileNotFoundError`` for a
path, whose message names the argument, and the target's state unchanged), ``graceful`` (an
``either`` input accepted), ``unclear`` (another exception type, or a message that does not name
the argument), ``accepted`` (a ``refuse`` input accepted silently), ``state`` (refused, but the
target changed), ``crash`` (the interpreter died) and ``hang`` (over the time limit). Risky calls
run in a worker subprocess (:func:`run_battery` with ``isolate=True``): a crash or hang kills the
worker, is recorded against the input that caused it, and a new worker goes on from the next.

**Module checks** (:func:`check_module`, :mod:`polar_sim.testing.contract`): take an instance and
run on its clones the checks its class's :class:`~polar_sim.params.Tags` make applicable:
parameters stored and returned by ``get_params()``; no ``_``-suffixed attributes before the first
update; a query before any update raises ``NotUpdatedError`` (or answers, if it needs none);
queries leave the state unchanged and return arrays that do not share memory with the inputs; the
same seed gives the same output, in one process and across processes; ``reset()`` then replay
equals a fresh clone; a deep copy taken mid-sequence continues alike; saved files load with
``allow_pickle=False``; plus the hostile battery of each of its entry points.

**Env checks** (:func:`check_polar_env`): gymnasium's ``check_env``; seeded resets give the same
observations, rewards and truth (also across processes); observations lie in their spaces; truth
is in ``info``; a rejected ``step``/``reset`` leaves the env as it was; double ``close()`` is
safe; the hostile battery of ``reset``, ``step`` and the constructor's keyword arguments.
"""

from polar_sim.testing.battery import FAILURES, OUTCOMES, Counts, EntryPoint, generate, run_battery
from polar_sim.testing.checks import Check, check_entry_points, check_module, check_polar_env, env_ids
from polar_sim.testing.digest import state_digest
from polar_sim.testing.entries import ENTRY_POINTS, entry_point_names, entry_points_of
from polar_sim.testing.inputs import BadInput, bad_inputs
from polar_sim.testing.soak import SoakResult, rss_bytes, soak, soak_env, soak_gpis, soak_renderers, vector_workers_closed

__all__ = [
    "BadInput", "EntryPoint", "Check", "Counts", "OUTCOMES", "FAILURES",
    "bad_inputs", "generate", "state_digest", "run_battery", "check_module", "check_polar_env",
    "ENTRY_POINTS", "check_entry_points", "env_ids", "entry_points_of", "entry_point_names",
    "SoakResult", "rss_bytes", "soak", "soak_env", "soak_gpis", "soak_renderers", "vector_workers_closed",
]
