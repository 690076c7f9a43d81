"""Vector environments: the stated autoreset mode, and the error a script without the __main__
guard gets."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import polar_sim.envs  # noqa: F401
from polar_sim.envs.vector import make_async_vector_env


# metadata["autoreset_mode"] states gymnasium's next-step autoreset, and it behaves so: the step
# after an episode ends resets that worker (reward 0, not done) and its next observation is a
# fresh episode's.
def test_autoreset_mode_is_stated_and_next_step():
    with pytest.raises(ValueError, match="num_envs"):
        make_async_vector_env("polar_sim/GPISNav-v1", 0)
    venv = make_async_vector_env("polar_sim/GPISNav-Room-v1", 2, pose_source="truth", sdf_source="truth")
    try:
        assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
        venv.reset(seed=[0, 1])
        ram = np.tile(np.float32([1.0, 0.0]), (2, 1))  # full speed ahead until something is hit
        for _ in range(300):
            obs, r, term, trunc, info = venv.step(ram)
            if term.any() or trunc.any():
                break
        k = int(np.flatnonzero(term | trunc)[0])
        obs, r, term, trunc, info = venv.step(ram)
        assert r[k] == 0.0 and not term[k] and not trunc[k]
        assert abs(float(obs["pose"][k][0])) < 1e-6  # a new episode starts at its start pose
    finally:
        venv.close()


# A script that builds a spawn vector env without `if __name__ == "__main__":` fails with a
# message that says to add the guard (in the parent, not only in the workers' output).
def test_missing_main_guard_says_what_to_do(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text(textwrap.dedent("""
        import polar_sim.envs
        from polar_sim.envs.vector import make_async_vector_env
        venv = make_async_vector_env("polar_sim/GPISNav-Room-v1", 2, pose_source="truth")
        venv.close()
    """))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "MUJOCO_GL": "egl"})
    assert out.returncode != 0
    last = out.stderr.strip().splitlines()[-1]
    assert last.startswith("RuntimeError: make_async_vector_env") and 'if __name__ == "__main__":' in last
