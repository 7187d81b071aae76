"""PPO training throughput: native vector env vs SB3's DummyVecEnv and SubprocVecEnv.

In one run, with the same PPO settings (``configs/ppo_shipped.yaml`` by
default, ``n_envs`` sub-environments), measures

(a) **PPO env-steps/s**: wall-clock env steps per second of
    ``PPO.learn`` (rollout collection + gradient updates) after a warm-up;
(b) **rollout env-steps/s**: the vector env alone stepped through SB3's
    ``VecEnv`` interface (``step_async``/``step_wait``) with random actions,
    no learning,

for the native vector env through the SB3 adapter (one numba kernel call per
step for all loops), SB3's ``DummyVecEnv`` (a Python loop over
``gymnasium.make`` envs) and ``SubprocVecEnv`` (one process per env, fork).
Prints a markdown table with the ratios to DummyVecEnv; ``--json OUT`` also
writes the numbers. ``torch.set_num_threads(1)`` throughout.

Usage::

    python benchmarks/bench_ppo_vecenv.py [--config FILE] [--n-envs N]
        [--steps STEPS] [--kinds native,dummy,subproc] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def rollout_speed(cfg, kind, n_steps):
    """Env-steps/s of the bare VecEnv (random actions), best of 3."""
    from valve_gym.agents.train import make_vec_env

    venv = make_vec_env(cfg.env, cfg.ppo.n_envs, cfg.seed, kind)
    n = venv.num_envs
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, size=(64, n, 1)).astype(np.float32)
    venv.reset()
    reps = max(1, n_steps // n)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(reps):
            venv.step_async(acts[k % 64])
            venv.step_wait()
        best = min(best, time.perf_counter() - t0)
    venv.close()
    return reps * n / best


def ppo_speed(cfg, kind, n_steps):
    """Env-steps/s of ``PPO.learn`` (after one warm-up rollout)."""
    import torch

    from valve_gym.agents.train import build_training_env, make_model

    torch.set_num_threads(1)
    env = build_training_env(cfg, cfg.seed, kind)
    model = make_model(cfg, env, cfg.seed, None)
    per_rollout = cfg.ppo.n_envs * cfg.ppo.n_steps
    model.learn(total_timesteps=per_rollout, progress_bar=False)          # warm-up (JIT, allocations)
    steps = max(per_rollout, (n_steps // per_rollout) * per_rollout)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
    dt = time.perf_counter() - t0
    env.close()
    return steps / dt


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default=str(ROOT / "configs" / "ppo_shipped.yaml"))
    p.add_argument("--n-envs", type=int, default=None, help="override ppo.n_envs")
    p.add_argument("--steps", type=int, default=40960, help="env steps of the timed PPO run")
    p.add_argument("--kinds", default="native,dummy,subproc")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from valve_gym.agents.train import load_train_config

    cfg = load_train_config(args.config)
    if args.n_envs:
        cfg = replace(cfg, ppo=replace(cfg.ppo, n_envs=args.n_envs))
    # keep the batch size a divisor of the rollout
    ro = cfg.ppo.n_envs * cfg.ppo.n_steps
    if ro % cfg.ppo.batch_size:
        cfg = replace(cfg, ppo=replace(cfg.ppo, batch_size=cfg.ppo.n_steps))
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    res = {}
    for kind in kinds:
        print(f"measuring {kind} ...", file=sys.stderr, flush=True)
        res[kind] = {"rollout": rollout_speed(cfg, kind, 20000), "ppo": ppo_speed(cfg, kind, args.steps)}
    ref = res.get("dummy")
    print(f"\nPPO env-steps/s, {cfg.ppo.n_envs} envs, n_steps {cfg.ppo.n_steps}, batch {cfg.ppo.batch_size}, "
          f"{cfg.ppo.n_epochs} epochs, net {list(cfg.ppo.policy_kwargs.net_arch)}, frame_stack "
          f"{cfg.obs.frame_stack}, deltas {cfg.obs.deltas}; {os.cpu_count()} CPUs, "
          f"{platform.processor() or platform.machine()}, torch threads 1\n")
    print("| vec env | PPO env-steps/s | ratio to Dummy | rollout env-steps/s (no learning) | ratio to Dummy |")
    print("|---|---|---|---|---|")
    names = {"native": "native (ValveTankVectorEnv + SB3 adapter)", "dummy": "DummyVecEnv",
             "subproc": "SubprocVecEnv"}
    for kind, r in res.items():
        rp = f"{r['ppo'] / ref['ppo']:.2f}x" if ref else "–"
        rr = f"{r['rollout'] / ref['rollout']:.2f}x" if ref else "–"
        print(f"| {names.get(kind, kind)} | {r['ppo']:.0f} | {rp} | {r['rollout']:.0f} | {rr} |")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"config": args.config, "n_envs": cfg.ppo.n_envs, "results": res}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
