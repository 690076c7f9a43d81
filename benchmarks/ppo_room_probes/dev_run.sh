#!/bin/bash
# usage: run.sh TAG PARAMS_JSON SEED  -> polar_sim_out/ppo2_dev/TAG_sSEED.log, TAG/seedSEED/
cd /work/wt/ppo2
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONPATH=/work/wt/ppo2 MUJOCO_GL=egl
exec nice -n 2 .venv/bin/python -c "
import json, sys, os
from polar_sim.envs.recipes import train
_, s = train('ppo', 'polar_sim/GPISNav-Room-v2', params=json.loads(sys.argv[2]), seed=int(sys.argv[3]), out=sys.argv[1] + '/seed' + sys.argv[3], progress=False)
for r in s['curve']: print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}))
print('wall', round(s['wall_s']), 'cpu', round(s['cpu_s']), 'load', os.getloadavg())
" polar_sim_out/ppo2_dev/$1 "$2" $3 > polar_sim_out/ppo2_dev/$1_s$3.log 2>&1
