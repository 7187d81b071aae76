"""Train the SB3 baselines (PPO, SAC, TD3 x seeds) in parallel, one process and one torch thread per run.

    python benchmarks/train_rl_baselines.py --out runs/rl [--seeds 0 1 2 3 4] [--algos ppo sac td3]
        [--timesteps N] [--max-wall-s S] [--tar FILE.tar.gz]

Each run is ``python -m valve_gym.agents.baselines --config configs/rl/<algo>.yaml --seed <s>`` writing
``<out>/<algo>_<s>/`` (curve.csv, policy.safetensors + policy.json, summary.json, log.txt). With
``--tar`` the runs are packed into one archive. ``benchmarks/rl_baselines_report.py`` makes the curves,
the table and the shipped policies from the runs.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tarfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--out", default="runs/rl")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--algos", nargs="+", default=["ppo", "sac", "td3"])
    p.add_argument("--timesteps", type=int, default=None, help="override every config's n_timesteps")
    p.add_argument("--max-wall-s", type=float, default=None, help="stop each training after this many seconds")
    p.add_argument("--tar", default=None, help="pack the runs into this .tar.gz")
    p.add_argument("--deadline-s", type=float, default=None,
                   help="stop runs still going after this many seconds (they write nothing; the rest are packed)")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "NUMBA_NUM_THREADS": "1", "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    procs = []
    t0 = time.perf_counter()
    for algo in a.algos:
        for s in a.seeds:
            run = out / f"{algo}_{s}"
            run.mkdir(parents=True, exist_ok=True)
            cmd = [sys.executable, "-m", "valve_gym.agents.baselines", "--config", str(ROOT / "configs" / "rl" /
                   f"{algo}.yaml"), "--seed", str(s), "--out", str(run)]
            if a.timesteps is not None:
                cmd += ["--timesteps", str(a.timesteps)]
            if a.max_wall_s is not None:
                cmd += ["--max-wall-s", str(a.max_wall_s)]
            log = open(run / "log.txt", "w")
            procs.append((f"{algo}_{s}", subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                                                          cwd=ROOT), log))
    failed = 0
    for name, pr, log in procs:
        left = None if a.deadline_s is None else max(a.deadline_s - (time.perf_counter() - t0), 0.1)
        try:
            rc = pr.wait(timeout=left)
        except subprocess.TimeoutExpired:
            pr.terminate()
            rc = pr.wait()
            print(f"{name}: stopped at the deadline ({a.deadline_s:.0f} s)", flush=True)
        log.close()
        failed += rc != 0
        tail = (out / name / "log.txt").read_text().strip().splitlines()[-1:] or [""]
        print(f"{name}: exit {rc} after {time.perf_counter() - t0:.0f} s: {tail[0]}", flush=True)
    if a.tar:
        with tarfile.open(a.tar, "w:gz") as tf:
            tf.add(out, arcname="rl_runs")
        print(f"wrote {a.tar} ({Path(a.tar).stat().st_size / 1e6:.2f} MB)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
