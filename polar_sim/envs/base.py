"""``PolarMujocoEnv``: the shared base of polar_sim's gymnasium environments.

It owns the :class:`~polar_sim.sim.World` (built lazily at ``reset``, from a layout seed drawn
from ``self.np_random``), the control period (one ``step`` is one ``World.step``), action
checking, rendering and ``close``. Subclasses implement ``_make_world``, ``_reset_scene``,
``_apply_action``, ``_get_obs``, ``_get_info`` and ``_get_reward``.
"""

from __future__ import annotations

import inspect

import gymnasium as gym
import numpy as np

from polar_sim._validation import as_image_size, check_options

__all__ = ["PolarMujocoEnv", "check_kwargs", "check_seed", "ACTION_TOLERANCE", "MAX_RENDER_SIZE"]

#: Largest ``render_size`` side, pixels (the scenes' offscreen buffers are smaller still: a size
#: beyond a scene's raises when rendered).
MAX_RENDER_SIZE = 4096
#: Actions up to this far outside the action box are taken as the bound (float32 round-off);
#: further out they raise ``ValueError``.
ACTION_TOLERANCE = 1e-6


def check_kwargs(cls, unknown):
    """Raise ``TypeError`` listing the valid keyword arguments of ``cls`` if any are unknown."""
    if unknown:
        valid = [p for c in type.mro(cls) if "__init__" in c.__dict__
                 for p, v in inspect.signature(c.__init__).parameters.items()
                 if v.kind == v.KEYWORD_ONLY]
        raise TypeError(f"{cls.__name__}: unknown argument(s) {sorted(unknown)}; valid: {sorted(set(valid))}")


def check_seed(seed):
    """``seed`` for ``reset``: None or an integer >= 0 (a numpy integer is taken as ``int``);
    anything else raises ``TypeError``/``ValueError`` naming ``seed`` before any state changes."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed: expected None or an integer >= 0, got {_short(seed)}")
    if seed < 0:
        raise ValueError(f"seed: expected None or an integer >= 0, got {_short(seed)}")
    return int(seed)


def _short(x, n=80):
    r = repr(x)
    return r if len(r) <= n else r[:n] + "..."


class PolarMujocoEnv(gym.Env):
    """Base class: a World per episode, seeded through ``reset(seed=...)``.

    Every episode's scene layout is drawn from ``self.np_random``, so ``reset(seed=s)`` rebuilds
    the same world and replays bit for bit.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    #: The keys ``reset(options=...)`` takes (none: any key is refused by name).
    RESET_OPTIONS = ()

    def __init__(self, *, render_mode=None, render_size=(480, 480)):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode: expected one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self._render_size = as_image_size(render_size, "render_size", maximum=MAX_RENDER_SIZE)
        self._world = None
        self._closed = False
        self._needs_reset = True

    # -- subclass hooks -------------------------------------------------------------------
    def _make_world(self, layout_seed):
        """The World of an episode with layout ``layout_seed``: a new one, or ``self.world`` given
        that layout in place (the base closes the previous world if it is not returned)."""
        raise NotImplementedError

    def _reset_scene(self):
        """Episode state after the world is built (modules, counters)."""

    def _apply_action(self, action):
        """Advance the world by one control period for a checked action."""
        raise NotImplementedError

    def _get_obs(self):
        raise NotImplementedError

    def _get_info(self):
        raise NotImplementedError

    def _get_reward(self):
        """Return (reward, terminated, reward terms dict)."""
        raise NotImplementedError

    # -- gymnasium API --------------------------------------------------------------------
    @property
    def world(self):
        """The current episode's World (None before the first reset)."""
        return self._world

    def reset(self, *, seed=None, options=None):
        self._reset_state(seed, options)
        obs = self._get_obs()
        return obs, self._get_info()

    def check_reset(self, seed, options):
        """``reset``'s arguments, checked before any state changes: the seed (None or an int >= 0)
        and the options (None or a dict with keys among :attr:`RESET_OPTIONS`, each checked by
        :meth:`_check_option_values`). Returns (seed, options dict)."""
        seed = check_seed(seed)
        options = check_options(options, self.RESET_OPTIONS)
        self._check_option_values(options)
        return seed, options

    def _check_option_values(self, options):
        """Check the values of the options a subclass takes (raise before any state changes)."""

    def _take_options(self, options):
        """Keep the checked options of the episode that starts (the world is not built yet)."""

    def _reset_state(self, seed, options):
        """Everything of :meth:`reset` but the observation and the info."""
        seed, options = self.check_reset(seed, options)
        if self._closed:
            raise RuntimeError(f"{type(self).__name__}: reset() after close()")
        self._take_options(options)
        super().reset(seed=seed)
        layout_seed = int(self.np_random.integers(0, 2**31 - 1))
        world = self._make_world(layout_seed)  # may be the previous one, given the new layout
        if self._world is not None and self._world is not world:
            self._world.close()
        self._world = world
        self._reset_scene()
        space = self.action_space  # its bounds and tolerances, once (every step checks against them)
        self._bounds = (space.low, space.high, space.low - ACTION_TOLERANCE, space.high + ACTION_TOLERANCE)
        self._needs_reset = False

    def step(self, action):
        """One control period. A rejected action (``ValueError``) leaves the environment as it was."""
        reward, terminated, info = self._step_state(action)
        return self._get_obs(), reward, terminated, False, info

    def _step_state(self, action):
        """Everything of :meth:`step` but the observation: (reward, terminated, info). A module
        environment asks for the raw observation only if its module reads it."""
        if self._closed:
            raise RuntimeError(f"{type(self).__name__}: step() after close()")
        if self._needs_reset:
            raise RuntimeError(f"{type(self).__name__}: call reset() before step()")
        a = self._check_action(action)
        self._apply_action(a)
        reward, terminated, terms = self._get_reward()
        info = self._get_info()
        info["reward_terms"] = terms
        if terminated:
            self._needs_reset = True
        return float(reward), bool(terminated), info

    def _check_action(self, action):
        if type(action) is np.ndarray:
            a = action
        else:
            try:
                a = np.asarray(action)
            except (TypeError, ValueError):
                a = np.asarray(None, dtype=object)
        if a.dtype.kind not in "iuf":
            # bool, complex, str, object: never a velocity command
            raise ValueError(f"action: expected a real numeric array of shape {self.action_space.shape}, got "
                             f"{_short(action)}")
        a = a.astype(np.float64)
        space = self.action_space
        if a.shape != space.shape:
            raise ValueError(f"action: expected shape {space.shape}, got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action: contains NaN or inf: {a.tolist()}")
        lo, hi, lo_tol, hi_tol = self._bounds
        if (a < lo_tol).any() or (a > hi_tol).any():
            raise ValueError(f"action: {a.tolist()} is outside the action space [{lo.tolist()}, {hi.tolist()}]; "
                             "it is never clipped silently")
        # Within the tolerance (float32 round-off of a bound) the action is the bound itself, so
        # that nothing downstream (the rover's own limits) can reject what was accepted here.
        return np.minimum(np.maximum(a, lo), hi)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render(): no render_mode was set; use gym.make(..., render_mode='rgb_array')")
            return None
        if self._world is None:
            raise RuntimeError(f"{type(self).__name__}: call reset() before render()")
        return self._render_frame()

    def _render_frame(self):
        w, h = self._render_size
        return self._world.render_view(width=w, height=h)

    def close(self):
        if self._world is not None:
            self._world.close()
            self._world = None
        self._closed = True
        self._needs_reset = True
