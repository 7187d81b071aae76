"""PPO and SAC trained on the randomised family, beside ``learned_adaptive`` on the plants they never saw.

    python benchmarks/family_rl_report.py [--heldout-only | --gen-only] [--jobs 1]

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
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
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
    subprocess.run(cmd, check=True, cwd=ROOT)
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--heldout-only", action="store_true")
    g.add_argument("--gen-only", action="store_true")
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
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
