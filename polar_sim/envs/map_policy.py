"""A policy with a map memory, evaluated in numpy: the remembered map (:class:`MapMemory`) read as
egocentric crops by a small CNN, beside the masked stencil, through dense layers to the action.
What the ``dagger_map`` recipe exports (:mod:`polar_sim.envs.imitation_map`) and the multi-room
tiers ship (torch is needed to train, not to act)."""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from polar_sim.envs.action_head import check_head, decode, head_outputs
from polar_sim.envs.action_maps import env_action
from polar_sim.envs.features import stencil_vector
from polar_sim.envs.map_memory import MAP_CHANNELS, MapMemory
from polar_sim.envs.mlp_policy import ACTIVATIONS, check_dense, dense_forward
from polar_sim.envs.observers import SDFStencil
from polar_sim.envs.policy_file import check_observation_space, read_policy_file, write_policy_file

__all__ = ["MapCNNPolicy", "conv2d"]


def conv2d(x, w, b, stride):
    """Cross-correlation of ``x`` (C, H, W) with ``w`` (O, C, k, k) plus ``b`` (O,), zero padding
    (k - 1) / 2, ``stride``: torch's ``Conv2d`` (O, ceil(H / stride), ceil(W / stride))."""
    k = w.shape[-1]
    xp = np.pad(x, ((0, 0), (k // 2, k // 2), (k // 2, k // 2)))
    win = sliding_window_view(xp, (k, k), axis=(1, 2))[:, ::stride, ::stride]  # (C, H', W', k, k)
    return np.einsum("chwij,ocij->ohw", win, w, optimize=True) + b[:, None, None]


class MapCNNPolicy:
    """``policy(obs) -> action`` with memory: each call adds the observation to the policy's
    :class:`~polar_sim.envs.map_memory.MapMemory`, reads its egocentric crops through ReLU
    convolutions (3x3, zero padding 1, each with its stride), flattens them, appends the
    normalised masked stencil (``clip((x - mean) / std, -clip, clip)`` of
    :func:`~polar_sim.envs.features.stencil_vector`), and maps the result through dense layers
    (``activation`` between them, none after the last) to the 2 action values or the logits of
    ``head``'s bins, decoded (:mod:`polar_sim.envs.action_head`) and clipped to the env's
    ``Box(-1, 1, (2,))``. ``reset()`` clears the memory: call it at every episode start.

    Parameters
    ----------
    convs : list of (ndarray, ndarray, int)
        Per convolution ``W`` (out, in, 3, 3) (torch's ``Conv2d`` layout), ``b`` (out,), stride.
    weights, biases : list of ndarray
        The dense layers, ``W`` (out_i, in_i) and ``b`` (out_i,); the first takes the flattened
        last convolution followed by the stencil features, the last outputs 2 values (or the bins
        of ``head``).
    memory : dict
        :class:`MapMemory`'s parameters plus ``stencil_rays`` and ``stencil_radii`` (the env's).
    obs_keys, obs_shapes, mean, std, clip, activation, known_var
        The stencil features, as for :class:`~polar_sim.envs.mlp_policy.MLPPolicy`.
    env_id, env_kwargs, recipe
        The env id, the ``gym.make`` arguments it acts with, how it was trained.
    head : dict or None, default=None
        The action head (:func:`polar_sim.envs.action_head.check_head`; None: regression).
    """

    def __init__(self, convs, weights, biases, *, memory, obs_keys, obs_shapes, mean, std, clip=10.0,
                 activation="tanh", known_var=0.5, env_id=None, env_kwargs=None, recipe=None, head=None):
        self.convs = [(np.asarray(w, np.float64), np.asarray(b, np.float64), int(s)) for w, b, s in convs]
        self.weights = [np.asarray(w, np.float64) for w in weights]
        self.biases = [np.asarray(b, np.float64) for b in biases]
        self.memory_params = dict(memory)
        try:
            stencil = SDFStencil(self.memory_params["stencil_rays"], self.memory_params["stencil_radii"])
            self.memory = MapMemory(stencil.points_robot, **{k: v for k, v in self.memory_params.items()
                                                             if not k.startswith("stencil_")})
        except (KeyError, TypeError) as exc:
            raise ValueError(f"memory: expected MapMemory's parameters with stencil_rays and stencil_radii, got "
                             f"{self.memory_params!r} ({exc})") from None
        self.obs_keys = list(obs_keys)
        self.obs_shapes = {k: tuple(int(n) for n in obs_shapes[k]) for k in self.obs_keys}
        self.mean, self.std = np.asarray(mean, np.float64), np.asarray(std, np.float64)
        self.clip, self.activation = float(clip), activation
        self.known_var = None if known_var is None else float(known_var)
        self.env_id, self.env_kwargs, self.recipe = env_id, dict(env_kwargs or {}), dict(recipe or {})
        self.head = check_head(head)
        self._check()

    @property
    def image_shape(self):
        """(channels, n, n) of the memory's crops."""
        n = self.memory.scales[0][0]
        return (len(MAP_CHANNELS) * len(self.memory.scales), n, n)

    def _check(self):
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation: expected one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
        if len({n for n, _ in self.memory.scales}) != 1:
            raise ValueError(f"memory: every crop must have the same number of cells, got {self.memory.scales}")
        n_vec = sum(int(np.prod(s)) for s in self.obs_shapes.values())
        if self.mean.shape != (n_vec,) or self.std.shape != (n_vec,) or not (self.std > 0).all():
            raise ValueError(f"mean, std: expected shape ({n_vec},) (the features of {self.obs_keys}) and std > 0, "
                             f"got {self.mean.shape} and {self.std.shape}")
        c, h, _ = self.image_shape
        if not self.convs:
            raise ValueError("convs: expected at least one convolution")
        for i, (w, b, s) in enumerate(self.convs):
            if w.ndim != 4 or w.shape[1] != c or w.shape[2:] != (3, 3) or b.shape != (w.shape[0],) or s not in (1, 2):
                raise ValueError(f"convs: layer {i} has W {w.shape}, b {b.shape}, stride {s}; expected W (out, {c}, 3, 3),"
                                 f" b (out,), stride 1 or 2")
            if not (np.isfinite(w).all() and np.isfinite(b).all()):
                raise ValueError(f"convs: layer {i} holds NaN or inf")
            c, h = w.shape[0], -(-h // s)
        check_dense(self.weights, self.biases, c * h * h + n_vec, head_outputs(self.head))

    # -- acting ----------------------------------------------------------------------------
    def observe(self, obs):
        """Add ``obs`` to the memory and return the inputs: the crops (C, n, n) and the
        normalised stencil features (n_features,)."""
        try:
            x = stencil_vector(obs, self.obs_keys, self.known_var)
        except KeyError as exc:
            raise ValueError(f"obs: the policy reads {self.obs_keys}; {exc} is missing") from None
        if x.shape != self.mean.shape:
            raise ValueError(f"obs: {x.size} features from {self.obs_keys}, expected {self.mean.size}")
        self.memory.update(obs)
        return self.memory.crops(), np.clip((x - self.mean) / self.std, -self.clip, self.clip)

    def act(self, image, vector):
        """The action (2,) float32 for the inputs of :meth:`observe` (the memory is not touched)."""
        h = np.asarray(image, np.float64)
        for w, b, s in self.convs:
            h = np.maximum(conv2d(h, w, b, s), 0.0)
        h = np.concatenate([h.reshape(-1), np.asarray(vector, np.float64)])
        return env_action(None, decode(self.head, dense_forward(self.weights, self.biases, self.activation, h)))

    def __call__(self, obs):
        return self.act(*self.observe(obs))

    def reset(self):
        """Forget the map: call at the start of every episode."""
        self.memory.reset()

    def check_env(self, env, name="env"):
        """Raise ``ValueError`` unless ``env`` observes every key this policy and its memory read,
        shaped as trained."""
        shapes = dict(self.obs_shapes)
        shapes.setdefault("pose", (3,))
        check_observation_space(shapes, env.observation_space, name)

    # -- the file --------------------------------------------------------------------------
    def save(self, path):
        """Write the policy to ``path`` (.npz, :mod:`polar_sim.envs.policy_file`, kind ``"mapcnn"``)."""
        meta = {"kind": "mapcnn", "obs_keys": self.obs_keys, "obs_shapes": self.obs_shapes, "clip": self.clip,
                "activation": self.activation, "env_id": self.env_id, "env_kwargs": self.env_kwargs,
                "recipe": self.recipe, "layers": len(self.weights), "strides": [s for _, _, s in self.convs],
                "known_var": self.known_var, "memory": self.memory_params, "head": self.head}
        # The weights as float32: torch trains them in float32, so this loses nothing and halves the file.
        def single(a):
            return a.astype(np.float32) if np.array_equal(a.astype(np.float32), a) else a

        arrays = {"obs_mean": self.mean, "obs_std": self.std}
        for i, (w, b, _) in enumerate(self.convs):
            arrays[f"conv{i}/W"], arrays[f"conv{i}/b"] = single(w), single(b)
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            arrays[f"layer{i}/W"], arrays[f"layer{i}/b"] = single(w), single(b)
        write_policy_file(path, meta, arrays)
        return path

    @classmethod
    def load(cls, path, env=None, name="path"):
        """The policy in ``path``; with ``env``, also checked against its observation space."""
        meta, arrays = read_policy_file(path, name)
        if meta["kind"] != "mapcnn":
            raise ValueError(f"{name}: a policy of kind {meta['kind']!r}, expected 'mapcnn'")
        return cls.from_file(meta, arrays, env, name)

    @classmethod
    def from_file(cls, meta, arrays, env=None, name="path"):
        """The policy of a checked header and arrays (:func:`read_policy_file`)."""
        try:
            convs = [(arrays[f"conv{i}/W"], arrays[f"conv{i}/b"], s) for i, s in enumerate(meta["strides"])]
            n = int(meta["layers"])
            policy = cls(convs, [arrays[f"layer{i}/W"] for i in range(n)], [arrays[f"layer{i}/b"] for i in range(n)],
                         memory=meta["memory"], obs_keys=meta["obs_keys"], obs_shapes=meta["obs_shapes"],
                         mean=arrays["obs_mean"], std=arrays["obs_std"], clip=meta["clip"],
                         activation=meta["activation"], known_var=meta["known_var"], env_id=meta["env_id"],
                         env_kwargs=meta["env_kwargs"], recipe=meta["recipe"], head=meta.get("head"))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{name}: the policy file lacks or garbles {exc}") from None
        if env is not None:
            policy.check_env(env)
        return policy
