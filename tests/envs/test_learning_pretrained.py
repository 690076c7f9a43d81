"""The shipped policies and the policy file: pretrained(env_id), the one load_policy, and every
bad file refused with a ValueError naming the mismatch."""

import json
import zipfile

import gymnasium as gym
import numpy as np
import pytest

import polar_sim.envs
import polar_sim.envs.shipped
from polar_sim.cli import main
from polar_sim.envs import pretrained, pretrained_ids
from polar_sim.envs.evaluate import load_policy
from polar_sim.envs.mlp_policy import MLPPolicy
from polar_sim.envs.policy_file import POLICY_FORMAT_VERSION, read_policy_file, write_policy_file
from polar_sim.envs.shipped import policy_path

ROOM = "polar_sim/GPISNav-Room-v1"
SHIPPED = ["polar_sim/GPISNav-Room-v2", "polar_sim/GPISNav-Rooms2-v2", "polar_sim/GPISNav-v2",
           "polar_sim/GPISNav-Room-v1", "polar_sim/GPISNav-Rooms2-v1", "polar_sim/GPISNav-v1"]


# The shipped policies are exactly the files in polar_sim/data/policies, one per tier listed.
def test_pretrained_ids_are_the_shipped_files():
    assert pretrained_ids() == sorted(SHIPPED)


# Each shipped policy is a numpy policy (MLP, or map CNN with memory) made for its own id, acting in
# the env's action space on the env made with its env_kwargs (the default slam mode).
@pytest.mark.parametrize("env_id", SHIPPED)
def test_pretrained_policy_acts_in_the_envs_action_space(env_id):
    policy = pretrained(env_id)
    assert policy.env_id == env_id and "pose_source" not in policy.env_kwargs
    assert policy.recipe["name"] in ("dagger", "dagger_map", "dagger_ppo") and policy.recipe["params"]
    env = gym.make(env_id, **policy.env_kwargs)
    obs, _ = env.reset(seed=10_000)
    policy.reset()
    for _ in range(5):
        a = policy(obs)
        assert env.action_space.contains(a)
        obs, *_ = env.step(a)
    assert policy_path(env_id).stat().st_size < 1_500_000  # small enough to ship
    env.close()


# An unknown id names the ids that have a policy.
@pytest.mark.parametrize("bad", ["polar_sim/GPISNav-v0", "polar_sim/Nope-v1", "", None, 3])
def test_pretrained_unknown_id_lists_the_ids(bad):
    with pytest.raises(ValueError, match="GPISNav-Room-v1"):
        pretrained(bad)


def _copy(tmp_path, **change):
    """The Room policy rewritten with ``change`` applied to its header or arrays (digest renewed)."""
    meta, arrays = read_policy_file(policy_path(ROOM))
    meta = {k: v for k, v in meta.items() if k not in ("digest", "format_version")}
    for k, v in change.items():
        (arrays if k in arrays else meta)[k] = v
    p = tmp_path / "p.npz"
    write_policy_file(p, meta, arrays)
    return p


# A tampered file (one weight changed after it was written) fails its digest.
def test_tampered_policy_file_is_refused(tmp_path):
    meta, arrays = read_policy_file(policy_path(ROOM))
    arrays["layer0/W"] = arrays["layer0/W"].copy()
    arrays["layer0/W"][0, 0] += 1e-3
    p = tmp_path / "t.npz"
    np.savez(p, meta=np.array(json.dumps(meta)), **arrays)
    with pytest.raises(ValueError, match="digest mismatch"):
        load_policy(p)


# Another format version, an unknown kind, a header that is not JSON, not a zip, no header, pickled
# objects: each a ValueError naming what is wrong.
def test_other_versions_and_broken_files_are_refused(tmp_path):
    meta, arrays = read_policy_file(policy_path(ROOM))
    for version in (1, POLICY_FORMAT_VERSION + 1, "2"):
        p = tmp_path / f"v{version}.npz"
        np.savez(p, meta=np.array(json.dumps({**meta, "format_version": version})), **arrays)
        with pytest.raises(ValueError, match="format version"):
            load_policy(p)
    p = tmp_path / "k.npz"
    np.savez(p, meta=np.array(json.dumps({**meta, "kind": "onnx"})), **arrays)
    with pytest.raises(ValueError, match="kind"):
        load_policy(p)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a readable"):
        load_policy(tmp_path / "junk.npz")
    np.savez(tmp_path / "nohead.npz", w=np.ones(3))
    with pytest.raises(ValueError, match="not a policy file"):
        load_policy(tmp_path / "nohead.npz")
    np.savez(tmp_path / "json.npz", meta=np.array("{oops"))
    with pytest.raises(ValueError, match="not JSON"):
        load_policy(tmp_path / "json.npz")
    np.savez(tmp_path / "pickle.npz", meta=np.array(json.dumps(meta)), obj=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError):
        load_policy(tmp_path / "pickle.npz")
    with zipfile.ZipFile(tmp_path / "pickle.npz") as z:  # the refusal is not a half-read
        assert "obj.npy" in z.namelist()


# A policy made for another observation space is refused by name of the key that does not match:
# the grid observation lacks the stencil, and a wider stencil has other shapes.
def test_policy_for_other_observation_spaces_is_refused(tmp_path, monkeypatch):
    p = policy_path(ROOM)
    with pytest.raises(ValueError, match="observation mismatch.*'sdf'"):
        load_policy(p, gym.make(ROOM, obs_mode="grid"))
    with pytest.raises(ValueError, match="observation mismatch.*'sdf'.*shape"):
        load_policy(p, gym.make(ROOM, stencil_rays=8))
    with pytest.raises(ValueError, match="mean, std"):  # shapes that do not fit its own weights
        MLPPolicy.load(_copy(tmp_path, obs_shapes={"goal": [3], "sdf": [64], "sdf_grad": [128], "sdf_var": [64], "twist": [2]}))
    renamed = _copy(tmp_path, env_id="polar_sim/GPISNav-v1")  # another tier's file under Room's name
    MLPPolicy.load(renamed)  # intact as a file
    monkeypatch.setattr(polar_sim.envs.shipped, "policy_path", lambda env_id: renamed)
    with pytest.raises(ValueError, match="made for 'polar_sim/GPISNav-v1'"):
        pretrained(ROOM)


# `polar-sim eval ENV --policy pretrained` scores the shipped policy on the env made with its
# env_kwargs; a policy file path works the same way.
def test_cli_eval_pretrained(tmp_path, capsys):
    assert main(["eval", ROOM, "--policy", "pretrained", "--episodes", "1", "--out", str(tmp_path / "a")]) == 0
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["episodes"] == 1 and 0.0 <= summary["success_rate"] <= 1.0
    assert main(["eval", ROOM, "--policy", str(policy_path(ROOM)), "--episodes", "1", "--out",
                 str(tmp_path / "b")]) == 0
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["mean_return"] == summary["mean_return"]
    assert main(["eval", "polar_sim/GPISNav-v0", "--policy", "pretrained", "--episodes", "1"]) == 1
    assert "policies ship for" in capsys.readouterr().err


# `polar-sim train` runs a recipe in one command and writes the policy; bad recipes exit 1 with
# the reason, before any training.
def test_cli_train(tmp_path, capsys):
    params = json.dumps({"rounds": 1, "steps_per_round": 100, "epochs": 1})
    assert main(["train", "dagger", "--env", ROOM, "--params", params, "--quiet", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "policy.npz").exists() and "dagger on" in capsys.readouterr().out
    assert main(["train", "dagger", "--params", '{"rounds": -1}', "--out", str(tmp_path / "x")]) == 1
    assert "rounds" in capsys.readouterr().err and not (tmp_path / "x").exists()
    assert main(["train", "nope"]) == 1
    assert main(["train", "dagger", "--params", "{oops"]) == 1
