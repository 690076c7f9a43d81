"""What the hostile battery calls: an :class:`EntryPoint` (a public call, its valid arguments and
their kinds), and :class:`Graceful`, an outcome its documentation names as acceptable. Apart from
:mod:`polar_sim.testing.battery`, which runs them, so that :mod:`polar_sim.testing.entries` can
declare entry points without importing the runner (and the runner find them without a cycle)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

__all__ = ["EntryPoint", "Graceful"]


@dataclasses.dataclass
class EntryPoint:
    """A public call under test.

    ``setup(tmp) -> target`` builds what the call acts on (None for a plain function);
    ``args(target, tmp) -> dict`` gives a valid call's arguments by name; ``call(target, args)``
    makes it; ``kinds`` maps each argument to its kind for :func:`bad_inputs`; ``names`` lists
    other names an error may use for an argument (``scan`` may be reported as ``ranges``);
    ``state(target)`` fingerprints the target (default :func:`state_digest`). A call that accepts
    an input may move the target on, so the target is rebuilt after every accepted call.
    """

    name: str
    setup: Callable
    args: Callable
    call: Callable
    kinds: dict
    names: dict = dataclasses.field(default_factory=dict)
    state: Callable | None = None
    ignore: tuple = ()
    timeout: float = 60.0
    pure: bool = False          # an accepted call leaves the target as it was (a query)
    graceful: dict = dataclasses.field(default_factory=dict)   # arg -> labels documented as valid input
    extra: Callable | None = None   # extra(target, tmp, rng) -> more BadInputs (e.g. tampered files)


class Graceful(Exception):
    """Raised by an entry point's ``call`` for an outcome its documentation names as graceful."""
