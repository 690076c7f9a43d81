"""Closed-loop evaluation writes per-episode metrics and a summary."""

import json

import pytest

from polar_sim.cli import main
from polar_sim.envs.evaluate import evaluate, load_policy


# evaluate() scores a policy over seeded episodes and writes CSV + JSON + markdown.
def test_evaluate_writes_summary(tmp_path):
    rows, summary = evaluate("polar_sim/GPISNav-v1", "polar_sim.envs.policies:SDFReactive", episodes=2,
                             env_kwargs={"sdf_source": "truth", "pose_source": "truth", "rooms": 2, "room_size": 4.0,
                                         "clutter": 3},
                             out_dir=tmp_path, progress=False)
    assert len(rows) == 2 and rows[0]["seed"] == 10_000
    assert 0.0 <= summary["success_rate"] <= 1.0
    assert json.loads((tmp_path / "summary.json").read_text())["episodes"] == 2
    assert (tmp_path / "episodes.csv").read_text().count("\n") == 3


# Bad policy specs raise clear errors; the CLI turns them into exit code 1.
def test_bad_policy(capsys):
    with pytest.raises(ValueError, match="module:callable"):
        load_policy("nonsense")
    with pytest.raises(ValueError, match="cannot load"):
        load_policy("polar_sim.envs.policies:Nope")
    assert main(["eval", "polar_sim/GPISNav-v1", "--policy", "nope:nope", "--episodes", "1"]) == 1
