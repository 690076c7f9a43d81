"""How a learned policy's output becomes the env's action (numpy and gymnasium only, no torch).

A recipe names its action parametrisation in ``recipe["action"]``: ``None`` (the env's own
normalised ``(v, omega)`` in ``Box(-1, 1, (2,))``, the output clipped to it) or ``{"name":
"forward_drive", "kwargs": {...}}`` (:class:`ForwardDriveAction`). :func:`wrap_action` applies it
to an env for training; :func:`env_action` maps one output for evaluation.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

__all__ = ["ForwardDriveAction", "ACTION_WRAPPERS", "wrap_action", "env_action", "check_action"]


def _check_min_drive(m):
    if isinstance(m, bool) or not isinstance(m, (int, float, np.integer, np.floating)) or not (0.0 <= m < 1.0):
        raise ValueError(f"min_drive: expected a number in [0, 1), got {m!r}")
    return float(m)


class ForwardDriveAction(gym.ActionWrapper):
    """The policy's action ``b`` in ``Box(-1, 1, (2,))`` mapped to the env's normalised
    ``(v, omega)``: ``v = min_drive + (1 - min_drive) * (b0 + 1) / 2`` (forward only, in
    ``[min_drive, 1]`` of ``max_speed``) and ``omega = b1``; ``b`` is first clipped to the box.

    A zero action then drives at ``(1 + min_drive) / 2`` of ``max_speed`` instead of standing
    still, so a freshly initialised Gaussian policy (mean 0) explores by driving: the progress
    term of the reward is seen from the first rollout. The env (its action space, reward and
    dynamics) is unchanged; only the learner's parametrisation is.

    Parameters
    ----------
    env : gymnasium.Env
        An env whose action space is ``Box(-1, 1, (2,))`` (normalised speed and yaw rate).
    min_drive : float, default=0.0
        The forward speed at ``b0 = -1``, as a fraction of ``max_speed``, in [0, 1).

    Examples
    --------
    >>> ForwardDriveAction.map_action([0.0, 0.5])
    array([0.5, 0.5], dtype=float32)
    """

    def __init__(self, env, min_drive=0.0):
        sp = env.action_space
        if not (isinstance(sp, gym.spaces.Box) and sp.shape == (2,) and np.all(sp.low == -1) and np.all(sp.high == 1)):
            raise ValueError(f"env: expected an action space Box(-1, 1, (2,)), got {sp!r}")
        self.min_drive = _check_min_drive(min_drive)
        super().__init__(env)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    @staticmethod
    def map_action(b, min_drive=0.0):
        """The env action (2,) float32 of the policy action ``b`` (2,)."""
        m = _check_min_drive(min_drive)
        b = np.clip(np.asarray(b, np.float64).reshape(2), -1.0, 1.0)
        return np.array([m + (1.0 - m) * (b[0] + 1.0) / 2.0, b[1]], np.float32)

    def action(self, action):
        return self.map_action(action, self.min_drive)


#: Action wrappers a recipe may name (``recipe["action"]``).
ACTION_WRAPPERS = {"forward_drive": ForwardDriveAction}


def check_action(action):
    """``action`` if it is a valid parametrisation (None, or ``{"name": ..., "kwargs": {...}}``
    with a name of :data:`ACTION_WRAPPERS`), else ``ValueError``."""
    if action is None:
        return None
    if not isinstance(action, dict) or action.get("name") not in ACTION_WRAPPERS \
            or not isinstance(action.get("kwargs", {}), dict) or set(action) - {"name", "kwargs"}:
        raise ValueError(f"action: expected None or {{'name': one of {sorted(ACTION_WRAPPERS)}, 'kwargs': {{...}}}}, "
                         f"got {action!r}")
    ACTION_WRAPPERS[action["name"]].map_action(np.zeros(2), **action.get("kwargs", {}))  # checks the kwargs
    return action


def wrap_action(env, action):
    """``env`` wrapped as ``action`` says (a recipe's ``"action"``, see :func:`check_action`)."""
    if check_action(action) is None:
        return env
    return ACTION_WRAPPERS[action["name"]](env, **action.get("kwargs", {}))


def env_action(action, b):
    """The env action (2,) float32 of the policy output ``b`` under the parametrisation ``action``
    (None: ``b`` clipped to [-1, 1])."""
    if check_action(action) is None:
        return np.clip(np.asarray(b, np.float64), -1.0, 1.0).astype(np.float32)
    return ACTION_WRAPPERS[action["name"]].map_action(b, **action.get("kwargs", {}))
