"""Speed of the regulation env for RL, side by side with CartPole-v1 in the same run.

    python benchmarks/bench_rl_speed.py [--quick] [--json OUT]

(a) steps/s of ``gymnasium.make("valve_gym/ValveTankRegulation-v0")`` and of ``gymnasium.make("CartPole-v1")``
    (default wrappers), random actions, resets inside the timed loop;
(b) env-steps/s of the native regulation vector env through the SB3 adapter
    (:class:`valve_gym.envs.sb3.SB3RegulationVecEnv`) at N = 1024, resets included (one per 1800 steps; a
    reset runs the reward's two reference loops per sub-env), and of Gymnasium's native ``CartPoleVectorEnv``
    at N = 1024; then both over 200 steps without a reset;
(c) SB3 PPO training throughput (env steps/s of ``learn``) on the regulation adapter and on CartPole-v1
    (``make_vec_env``, DummyVecEnv), same ``n_envs``, ``n_steps``, batch, epochs and network.

Each figure is the best of the repeats, interleaved so that a change of machine load hits both alike.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_env_speed import _best  # noqa: E402  (best time of each callable, repeats interleaved)


def single(env_id: str, n: int):
    import gymnasium as gym

    import valve_gym  # noqa: F401

    env = gym.make(env_id)
    env.reset(seed=0)
    env.action_space.seed(0)
    acts = [env.action_space.sample() for _ in range(n)]

    def run():
        for a in acts:
            _, _, te, tr, _ = env.step(a)
            if te or tr:
                env.reset()
    return run


def vector_reg(N: int, steps: int):
    from valve_gym.envs.sb3 import SB3RegulationVecEnv

    venv = SB3RegulationVecEnv(N)
    venv.seed(0)
    venv.reset()
    a = np.random.default_rng(0).uniform(-1, 1, (N, 2)).astype(np.float32)

    def run():
        for _ in range(steps):
            venv.step(a)
    return run


def vector_cartpole(N: int, steps: int):
    import gymnasium as gym

    venv = gym.make_vec("CartPole-v1", num_envs=N, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    a = np.random.default_rng(0).integers(0, 2, N)

    def run():
        for _ in range(steps):
            venv.step(a)
    return run


def ppo(kind: str, total: int, n_envs: int):
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    torch.set_num_threads(1)
    if kind == "regulation":
        from valve_gym.envs.sb3 import SB3RegulationVecEnv

        venv = SB3RegulationVecEnv(n_envs)
        venv.seed(0)
    else:
        venv = make_vec_env("CartPole-v1", n_envs=n_envs, seed=0)
    kw: dict = dict(n_steps=256, batch_size=256, n_epochs=4, policy_kwargs={"net_arch": [64, 64]}, device="cpu", seed=0)

    def run():
        PPO("MlpPolicy", venv, **kw).learn(total)
    return run


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    rep = 2 if a.quick else 3
    n1 = 3600 if a.quick else 18000
    res = {}
    t = _best({"reg": single("valve_gym/ValveTankRegulation-v0", n1), "cp": single("CartPole-v1", n1)}, rep)
    res["single_regulation_steps_s"], res["single_cartpole_steps_s"] = n1 / t["reg"], n1 / t["cp"]
    N, vs = 1024, (40 if a.quick else 1800)   # full: one reset (with its reference runs) per timed run
    t = _best({"reg": vector_reg(N, vs), "cp": vector_cartpole(N, vs)}, rep)
    res["vector1024_regulation_sb3_steps_s"], res["vector1024_cartpole_steps_s"] = N * vs / t["reg"], N * vs / t["cp"]
    t = _best({"reg": vector_reg(N, 200), "cp": vector_cartpole(N, 200)}, rep)    # 200 steps: no reset
    res["vector1024_noreset_regulation_sb3_steps_s"] = N * 200 / t["reg"]
    res["vector1024_noreset_cartpole_steps_s"] = N * 200 / t["cp"]
    tot, ne = (8192, 8) if a.quick else (65536, 16)
    t = _best({"reg": ppo("regulation", tot, ne), "cp": ppo("cartpole", tot, ne)}, 1 if a.quick else 2)
    res["ppo_regulation_steps_s"], res["ppo_cartpole_steps_s"] = tot / t["reg"], tot / t["cp"]
    print("| measure | regulation | CartPole-v1 | ratio |\n|---|---|---|---|")
    for name, r, c in (("gymnasium.make, one env [steps/s]", "single_regulation_steps_s", "single_cartpole_steps_s"),
                       ("native vector env, N = 1024 (regulation through the SB3 adapter), resets included "
                        "[env-steps/s]", "vector1024_regulation_sb3_steps_s", "vector1024_cartpole_steps_s"),
                       ("the same, 200 steps without a reset [env-steps/s]",
                        "vector1024_noreset_regulation_sb3_steps_s", "vector1024_noreset_cartpole_steps_s"),
                       (f"SB3 PPO learn, {ne} envs [env-steps/s]", "ppo_regulation_steps_s", "ppo_cartpole_steps_s")):
        print(f"| {name} | {res[r]:,.0f} | {res[c]:,.0f} | {res[r] / res[c]:.2f}x |")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(res, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
