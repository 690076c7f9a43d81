"""Ctrl-C during a run keeps the finished rows: results.csv stays readable, and running again
into the same folder runs only the trials that had not finished."""

import signal
import subprocess
import sys
import textwrap
import time

from polar_sim.runner.results import ResultsFile

# A sweep of 8 trials, defined in a script so it can run in a subprocess. With "block", the third
# trial sleeps until it is interrupted, so the test does not depend on how fast this machine is.
SCRIPT = textwrap.dedent("""
    import signal, sys, time
    from polar_sim.runner import Experiment, run_experiment

    # A terminal's Ctrl-C raises KeyboardInterrupt; a parent such as a pytest-xdist worker may
    # start this process with SIGINT ignored, which Python then keeps.
    signal.signal(signal.SIGINT, signal.default_int_handler)

    started = []

    def trial(params, seed, ctx):
        started.append(seed)
        time.sleep(600 if sys.argv[2] == "block" and len(started) > 2 else 0.05)
        return {"value": params["a"] * 100 + seed}

    exp = Experiment("slow_toy", "eight slow trials", grid={"a": [1, 2]}, trial=trial,
                     splits={"dev": {"seeds": [0, 1, 2, 3]}}, sizes={"full": {}})
    res = run_experiment(exp, out=sys.argv[1], progress=False)
    print("TRIALS_RUN", len(res.table))
""")


def test_ctrl_c_keeps_finished_rows(tmp_path):
    script = tmp_path / "slow_toy.py"
    script.write_text(SCRIPT)
    out = tmp_path / "run"
    p = subprocess.Popen([sys.executable, str(script), str(out), "block"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    csv = out / "results.csv"
    deadline = time.monotonic() + 300
    try:
        while not (csv.exists() and len(csv.read_text().splitlines()) >= 3):   # two finished rows
            assert p.poll() is None and time.monotonic() < deadline, p.communicate()[1][-2000:]
            time.sleep(0.05)
        p.send_signal(signal.SIGINT)                                           # then Ctrl-C
        _, err = p.communicate(timeout=60)
    finally:
        p.kill()          # a child that ignored Ctrl-C must not sleep on after a failed test
    assert p.returncode != 0 and "KeyboardInterrupt" in err
    kept = ResultsFile(csv).read()
    assert len(kept) == 2
    assert all(r["status"] == "ok" and r["value"] == r["a"] * 100 + r["seed"] for r in kept)

    # Resume: the finished trials are kept as they were, and only the others run.
    r = subprocess.run([sys.executable, str(script), str(out), "fast"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = ResultsFile(csv).read()
    assert sorted((x["a"], x["seed"]) for x in rows) == [(a, s) for a in (1, 2) for s in range(4)]
    assert [x for x in rows if x["trial_key"] in {k["trial_key"] for k in kept}] == kept
