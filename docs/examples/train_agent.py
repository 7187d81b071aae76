"""Train your own agent on the stiction task and score it with the benchmark (README, "Train your own agent")."""
import os

from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import valve_gym  # noqa: F401  (registers the valve_gym/... ids)
from valve_gym.agents.bench.policies import evaluate, export_policy

steps = int(os.environ.get("TRAIN_STEPS", 500_000))        # configs/rl/ppo.yaml's baseline: ~0.8 M; 2048 to try it
env = VecNormalize(make_vec_env("valve_gym/ValveTankRegulation-v0", n_envs=8, seed=0))
model = PPO("MlpPolicy", env, n_steps=512, batch_size=256, gamma=0.995, seed=0).learn(steps)

export_policy(model, "my_ppo")                                  # my_ppo.safetensors + my_ppo.json (no pickle)
res = evaluate(model, name="my PPO", quick=bool(os.environ.get("QUICK")))   # every classical row + yours
for row in res.summary:
    if row.part == "regulation" and row.band == "sticky+severe" and row.metric == "R":
        print(f"{row.controller:32s} R = {row.estimate.value:6.2f} [{row.estimate.lo:.2f}, {row.estimate.hi:.2f}]")
# or from the shell: valve-gym benchmark --policy my_ppo.json --name "my PPO" --out results
