"""A feed-forward policy evaluated in numpy: what the shipped policies are, and what the
imitation and PPO recipes export (torch is needed to train, not to act)."""

from __future__ import annotations

import numpy as np

from polar_sim.envs.action_head import check_head, decode, head_outputs
from polar_sim.envs.action_maps import check_action, env_action
from polar_sim.envs.features import stencil_vector
from polar_sim.envs.policy_file import check_observation_space, read_policy_file, write_policy_file

__all__ = ["MLPPolicy", "ACTIVATIONS", "check_dense", "dense_forward"]

ACTIVATIONS = {"tanh": np.tanh, "relu": lambda x: np.maximum(x, 0.0)}


def check_dense(weights, biases, fan_in, n_out=2):
    """Check a stack of dense layers: W_i (out_i, in_i) and b_i (out_i,) finite, in_0 = ``fan_in``,
    each layer feeding the next, and ``n_out`` outputs (2: v, omega; or the bins of an action head,
    :mod:`polar_sim.envs.action_head`); ``ValueError`` naming the layer."""
    if not weights or len(weights) != len(biases):
        raise ValueError(f"weights, biases: expected equal, non-zero numbers of layers, got "
                         f"{len(weights)} and {len(biases)}")
    for i, (w, b) in enumerate(zip(weights, biases)):
        if w.ndim != 2 or w.shape[1] != fan_in or b.shape != (w.shape[0],):
            raise ValueError(f"weights: layer {i} has W {w.shape} and b {b.shape}; expected W (out, {fan_in}) "
                             f"and b (out,)")
        if not (np.isfinite(w).all() and np.isfinite(b).all()):
            raise ValueError(f"weights: layer {i} holds NaN or inf")
        fan_in = w.shape[0]
    if fan_in != n_out:
        what = "(v, omega)" if n_out == 2 else "(the action head's bins)"
        raise ValueError(f"weights: the last layer outputs {fan_in} values, expected {n_out} {what}")


def dense_forward(weights, biases, activation, h):
    """The output of the dense stack on input ``h`` (in_0,): ``activation`` (a name of
    :data:`ACTIVATIONS`) after every layer but the last."""
    act = ACTIVATIONS[activation]
    for i, (w, b) in enumerate(zip(weights, biases)):
        h = w @ h + b
        if i < len(weights) - 1:
            h = act(h)
    return h


class MLPPolicy:
    """``policy(obs) -> action``: the observation keys ``obs_keys`` flattened and concatenated,
    normalised as ``clip((x - mean) / std, -clip, clip)``, through dense layers
    ``h <- activation(W h + b)`` (none after the last), mapped to the env's action by ``action``.

    Parameters
    ----------
    weights, biases : list of ndarray
        Layer ``i`` has ``W`` of shape (out_i, in_i) (torch's ``nn.Linear`` layout) and ``b`` of
        shape (out_i,); the last layer outputs the 2 action values, or the logits of ``head``'s bins.
    obs_keys : sequence of str
        The observation keys read, in order.
    obs_shapes : dict
        key -> shape of each key read, checked against an env's observation space.
    mean, std : ndarray of shape (n_features,)
        The feature normalisation (std > 0).
    clip : float, default=10.0
        Bound of the normalised features.
    activation : {"tanh", "relu"}
    action : dict or None
        The action parametrisation (:func:`polar_sim.envs.action_maps.env_action`).
    env_id : str, optional
        The env id the policy was made for.
    env_kwargs : dict, optional
        The ``gym.make`` arguments it acts with (e.g. ``{"obs_mode": "stencil"}``).
    recipe : dict, optional
        How it was trained (recipe name and parameters, splits, steps); informational.
    known_var : float, optional
        Mask the stencil's unknown space before normalising
        (:func:`polar_sim.envs.features.stencil_vector`); ``obs_keys`` must then hold ``sdf_var``.
    head : dict or None, default=None
        The action head (:mod:`polar_sim.envs.action_head`): None regresses (v, omega), a bins
        head classifies over action bins.
    """

    def __init__(self, weights, biases, *, obs_keys, obs_shapes, mean, std, clip=10.0, activation="tanh",
                 action=None, env_id=None, env_kwargs=None, recipe=None, known_var=None, head=None):
        self.weights = [np.asarray(w, np.float64) for w in weights]
        self.biases = [np.asarray(b, np.float64) for b in biases]
        self.obs_keys = list(obs_keys)
        self.obs_shapes = {k: tuple(int(n) for n in obs_shapes[k]) for k in self.obs_keys}
        self.mean = np.asarray(mean, np.float64)
        self.std = np.asarray(std, np.float64)
        self.clip = float(clip)
        self.activation = activation
        self.action = check_action(action)
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.recipe = dict(recipe or {})
        self.known_var = None if known_var is None else float(known_var)
        self.head = check_head(head)
        self._check()

    def _check(self):
        if self.known_var is not None and (not self.known_var > 0 or "sdf_var" not in self.obs_keys):
            raise ValueError(f"known_var: expected None, or a variance > 0 with 'sdf_var' among the obs_keys; got "
                             f"{self.known_var!r} with {self.obs_keys}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation: expected one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
        n = sum(int(np.prod(s)) for s in self.obs_shapes.values())
        if self.mean.shape != (n,) or self.std.shape != (n,) or not (self.std > 0).all():
            raise ValueError(f"mean, std: expected shape ({n},) (the features of {self.obs_keys}) and std > 0, "
                             f"got {self.mean.shape} and {self.std.shape}")
        check_dense(self.weights, self.biases, n, head_outputs(self.head))

    def features(self, obs):
        """The normalised feature vector (n_features,) of one observation dict."""
        try:
            x = stencil_vector(obs, self.obs_keys, self.known_var)
        except KeyError as exc:
            raise ValueError(f"obs: the policy reads {self.obs_keys}; {exc} is missing") from None
        if x.shape != self.mean.shape:
            raise ValueError(f"obs: {x.size} features from {self.obs_keys}, expected {self.mean.size}")
        return np.clip((x - self.mean) / self.std, -self.clip, self.clip)

    def raw_output(self, obs):
        """The last layer's output (2, or the head's bins) before the head and the action map."""
        return dense_forward(self.weights, self.biases, self.activation, self.features(obs))

    def act(self, features):
        """The env action (2,) float32 of normalised ``features`` (:meth:`features`)."""
        return env_action(self.action, decode(self.head, dense_forward(self.weights, self.biases, self.activation,
                                                                       features)))

    def __call__(self, obs):
        return self.act(self.features(obs))

    def reset(self):
        """Nothing to forget: the policy is memoryless (the map in the observation is the memory)."""

    def check_env(self, env, name="env"):
        """Raise ``ValueError`` unless ``env`` observes every key this policy reads, shaped as trained."""
        check_observation_space(self.obs_shapes, env.observation_space, name)

    # -- the file --------------------------------------------------------------------------
    def save(self, path):
        """Write the policy to ``path`` (.npz, :mod:`polar_sim.envs.policy_file`)."""
        meta = {"kind": "mlp", "obs_keys": self.obs_keys, "obs_shapes": self.obs_shapes, "clip": self.clip,
                "activation": self.activation, "action": self.action, "env_id": self.env_id,
                "env_kwargs": self.env_kwargs, "recipe": self.recipe, "layers": len(self.weights),
                "known_var": self.known_var, "head": self.head}
        arrays = {"obs_mean": self.mean, "obs_std": self.std}
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            arrays[f"layer{i}/W"], arrays[f"layer{i}/b"] = w, b
        write_policy_file(path, meta, arrays)
        return path

    @classmethod
    def load(cls, path, env=None, name="path"):
        """The policy in ``path``; with ``env``, also checked against its observation space."""
        meta, arrays = read_policy_file(path, name)
        if meta["kind"] != "mlp":
            raise ValueError(f"{name}: a policy of kind {meta['kind']!r}, expected 'mlp'")
        try:
            n = int(meta["layers"])
            policy = cls([arrays[f"layer{i}/W"] for i in range(n)], [arrays[f"layer{i}/b"] for i in range(n)],
                         obs_keys=meta["obs_keys"], obs_shapes=meta["obs_shapes"], mean=arrays["obs_mean"],
                         std=arrays["obs_std"], clip=meta["clip"], activation=meta["activation"],
                         action=meta["action"], env_id=meta["env_id"], env_kwargs=meta["env_kwargs"],
                         recipe=meta["recipe"], known_var=meta.get("known_var"), head=meta.get("head"))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{name}: the policy file lacks or garbles {exc}") from None
        if env is not None:
            policy.check_env(env)
        return policy
