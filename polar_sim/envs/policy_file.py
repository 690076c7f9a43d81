"""The policy file: one ``.npz`` of named arrays and a JSON header, no pickle.

The header (``meta``) holds the format version, the kind of policy (``"mlp"``: a numpy
feed-forward policy, :class:`~polar_sim.envs.mlp_policy.MLPPolicy`; ``"mapcnn"``: a numpy policy
with a map memory, :class:`~polar_sim.envs.map_policy.MapCNNPolicy`; ``"sb3"``: the state dict
of a stable-baselines3 policy, :func:`polar_sim.envs.learning.load_model`), the recipe it was
trained with, the env id and ``gym.make`` arguments it is meant for, the observation keys and
shapes it reads, and a SHA-256 digest of the arrays and the rest of the header. A file that was
changed after it was written (the digest), of another format version, or not a policy file at
all raises ``ValueError`` naming the mismatch.
"""

from __future__ import annotations

import hashlib
import json
import zipfile

import numpy as np

from polar_sim.fileio import atomic_write, check_source

__all__ = ["POLICY_FORMAT_VERSION", "POLICY_KINDS", "write_policy_file", "read_policy_file", "check_observation_space"]

#: v2: the header's kind, env id, observation shapes and digest (v1: SB3 state dicts, no digest).
POLICY_FORMAT_VERSION = 2
POLICY_KINDS = ("mlp", "mapcnn", "sb3")


def _digest(meta, arrays):
    """SHA-256 over the header (without its digest) and every array's name, dtype, shape and bytes."""
    h = hashlib.sha256(json.dumps({k: v for k, v in meta.items() if k != "digest"}, sort_keys=True).encode())
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        h.update(f"{k}|{a.dtype.str}|{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def write_policy_file(path, meta, arrays):
    """Write ``arrays`` (name -> ndarray, numeric) and the JSON-able ``meta`` to ``path``
    atomically; ``meta`` gains ``format_version`` and ``digest``. Returns the header written."""
    if meta.get("kind") not in POLICY_KINDS:
        raise ValueError(f"meta: 'kind' must be one of {POLICY_KINDS}, got {meta.get('kind')!r}")
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    bad = [k for k, a in arrays.items() if a.dtype.kind not in "fiub" or k == "meta"]
    if bad:
        raise ValueError(f"arrays: {bad} are not numeric arrays (or use the reserved name 'meta')")
    meta = json.loads(json.dumps({**meta, "format_version": POLICY_FORMAT_VERSION}))
    meta["digest"] = _digest(meta, arrays)
    with atomic_write(path) as fh:
        np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)
    return meta


def read_policy_file(path, name="path"):
    """``(meta, arrays)`` of a file written by :func:`write_policy_file`, checked: a readable
    ``.npz`` without pickled objects, a JSON header, this format version, an intact digest."""
    p = check_source(path, name)
    if not zipfile.is_zipfile(p):
        raise ValueError(f"{name}: {p} is not a readable .npz policy file (not a zip archive)")
    try:
        with np.load(p, allow_pickle=False) as f:
            if "meta" not in f.files:
                raise ValueError(f"{name}: {p} is not a policy file (no 'meta' header)")
            meta = json.loads(str(f["meta"]))
            arrays = {k: f[k] for k in f.files if k != "meta"}
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise ValueError(f"{name}: {p} is not a readable .npz policy file ({exc})") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{name}: the header of {p} is not JSON ({exc.msg})") from None
    except ValueError as exc:  # object arrays (pickles) refused by allow_pickle=False
        raise ValueError(f"{name}: {p}: {exc}") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{name}: the header of {p} is not a JSON object")
    if meta.get("format_version") != POLICY_FORMAT_VERSION:
        raise ValueError(f"{name}: policy format version {meta.get('format_version')!r}, expected "
                         f"{POLICY_FORMAT_VERSION} (re-export the policy with this version of polar_sim)")
    if meta.get("kind") not in POLICY_KINDS:
        raise ValueError(f"{name}: unknown policy kind {meta.get('kind')!r}; expected one of {POLICY_KINDS}")
    if meta.get("digest") != _digest(meta, arrays):
        raise ValueError(f"{name}: digest mismatch: {p} was changed after it was written (tampered or corrupt)")
    return meta, arrays


def check_observation_space(obs_shapes, space, name="env"):
    """Raise ``ValueError`` unless the ``Dict`` observation ``space`` has every key of
    ``obs_shapes`` (key -> shape) with that shape."""
    spaces = getattr(space, "spaces", None)
    if not isinstance(spaces, dict):
        raise ValueError(f"{name}: the policy reads a Dict observation with keys {sorted(obs_shapes)}; "
                         f"the env observes {space!r}")
    for k, shape in obs_shapes.items():
        if k not in spaces:
            raise ValueError(f"{name}: observation mismatch: the policy reads {k!r}, which the env does not "
                             f"observe (keys {sorted(spaces)}); make the env with the policy's env_kwargs")
        if tuple(spaces[k].shape) != tuple(shape):
            raise ValueError(f"{name}: observation mismatch: {k!r} has shape {tuple(spaces[k].shape)} in the env, "
                             f"{tuple(shape)} in the policy; make the env with the policy's env_kwargs")
