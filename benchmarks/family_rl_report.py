"""PPO and SAC trained on the randomised family, beside ``learned`` on the plants they never saw.

    python benchmarks/family_rl_report.py [--heldout-only | --gen-only] [--jobs 1]
    python benchmarks/family_rl_report.py --ship runs/rl_family     (copy the trained runs into the package)

Two measurements of the shipped policies ``valve_gym/agents/policies/rl_family/{ppo,sac}_seed{0,1}``
(trained by ``valve-gym train --config configs/rl/{ppo,sac}_family.yaml``) and, for contrast, the seed-0
policies of the regulation-env baselines (``valve_gym/agents/policies/rl/``, trained on the benchmark tank):

1. the held-out second family (``benchmarks/learned_unseen_check.py``: plants and valves coded there alone),
   printed first;
2. the benchmark's generalisation part (:func:`valve_gym.agents.bench.generalisation.run_generalisation`,
   full family, every registered controller at default settings, the learned blocks included); each policy
   row gets the loop's ``Kc``, ``Ti`` and scan as every other block
   (:meth:`~valve_gym.agents.bench.policies.PolicyBlock.for_loop`).

Every policy file is read through the safe loader (safetensors + JSON). Wall times are printed.

``--ship RUNS`` copies ``RUNS/{ppo,sac}_{0,1}/policy.{safetensors,json}`` (written by ``valve-gym train``) to
``valve_gym/agents/policies/rl_family/<algo>_seed<s>.*`` and their learning curves (the policy's median ``R``,
travel / frictionless PI and LC share on the trainer's fixed evaluation loops against env steps) to
``rl_family/curves.csv``, and prints each run's env steps and training wall time.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:            # the policies and the hooks of this checkout, whatever is installed
    sys.path.insert(0, str(ROOT))
POL = ROOT / "valve_gym" / "agents" / "policies"
ROWS = {f"{a.upper()} family s{s}": POL / "rl_family" / f"{a}_seed{s}.json" for a in ("ppo", "sac") for s in (0, 1)}
ROWS.update({f"{a.upper()} regulation s0": POL / "rl" / f"{a}_seed0.json" for a in ("ppo", "sac")})


def heldout() -> None:
    """The held-out second family, through its own script (``--policy LABEL=FILE``)."""
    cmd = [sys.executable, str(ROOT / "benchmarks" / "learned_unseen_check.py")]
    for label, f in ROWS.items():
        cmd += ["--policy", f"{label}={f}"]
    print("$ " + " ".join(str(c).replace(str(ROOT) + "/", "") for c in cmd), flush=True)
    t0 = time.perf_counter()
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env = {**os.environ, "PYTHONPATH": path}
    subprocess.run(cmd, check=True, cwd=ROOT, env=env)     # this checkout's valve_gym, whatever is installed
    print(f"(held-out family: {time.perf_counter() - t0:.0f} s wall)\n", flush=True)


def generalisation(jobs: int) -> None:
    """The benchmark's generalisation part with the policy rows."""
    from valve_gym.agents.bench.config import BenchConfig
    from valve_gym.agents.bench.generalisation import GenFamily, generalisation_markdown, run_generalisation
    from valve_gym.agents.bench.pipeline import print_progress
    from valve_gym.agents.bench.policies import load_policy_block

    cfg = BenchConfig()
    pols = {label: load_policy_block(f, name=label) for label, f in ROWS.items()}
    t0 = time.perf_counter()
    res = run_generalisation(cfg, GenFamily(), jobs=jobs, progress=print_progress, policies=pols)
    print(generalisation_markdown(res, cfg))
    print(f"(generalisation part: {time.perf_counter() - t0:.0f} s wall, jobs {jobs})", flush=True)


def ship(runs: Path) -> None:
    """Copy the trained runs' exports and learning curves into the package (atomic writes)."""
    import csv
    import io
    import json

    from valve_gym._io import write_atomic

    dest = POL / "rl_family"
    dest.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    for algo in ("ppo", "sac"):
        for seed in (0, 1):
            d = runs / f"{algo}_{seed}"
            meta = json.loads((d / "policy.json").read_text())
            data = (d / "policy.safetensors").read_bytes()
            write_atomic(dest / f"{algo}_seed{seed}.safetensors", lambda f, b=data: f.write(b))
            text = json.dumps(meta, indent=1).encode()
            write_atomic(dest / f"{algo}_seed{seed}.json", lambda f, b=text: f.write(b))
            with open(d / "curve.csv", newline="") as fh:
                rows += [{"algorithm": algo, "seed": seed, **r} for r in csv.DictReader(fh)]
            print(f"{algo} seed {seed}: {meta['env_steps']} env steps, {meta['train_wall_s']:.0f} s wall; "
                  f"{meta['train_command']}")
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    write_atomic(dest / "curves.csv", lambda f: f.write(buf.getvalue().encode()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--heldout-only", action="store_true")
    g.add_argument("--gen-only", action="store_true")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--ship", default=None, metavar="RUNS", help="copy the trained runs into the package, then stop")
    a = ap.parse_args(argv)
    if a.ship:
        ship(Path(a.ship))
        return 0
    missing = [str(f) for f in ROWS.values() if not f.is_file()]
    if missing:
        print(f"family_rl_report: policy file(s) missing: {', '.join(missing)}; train and ship them first "
              "(docs/rl.md)", file=sys.stderr)
        return 2
    if not a.gen_only:
        heldout()
    if not a.heldout_only:
        generalisation(a.jobs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
