"""Usage: python benchmarks/bench_envs_battery.py N [ENV_ID ...]

Run check_polar_env(env_id, n_bad=N) over polar_sim.envs.ENV_IDS; print pass/fail per check."""
import sys
import time
import json
from polar_sim.envs import ENV_IDS
from polar_sim.testing import check_polar_env
n = int(sys.argv[1])
ids = sys.argv[2:] or list(ENV_IDS)
summary = {}
for env_id in ids:
    t = time.time()
    fails = []
    for check in check_polar_env(env_id, n_bad=n):
        try:
            check()
            print("PASS", check.name, flush=True)
        except BaseException as e:
            fails.append(check.name)
            print("FAIL", check.name, type(e).__name__, str(e)[:3000], flush=True)
    summary[env_id] = {"failed": fails, "wall_s": round(time.time() - t)}
    print("SUMMARY", env_id, json.dumps(summary[env_id]), flush=True)
print("ALL", json.dumps(summary))
