"""Speed of the envs built on the shared task module and Plant against the envs before them, in one run.

``valve_gym/envs/task.py`` (the level-control task written once) and the envs'
use of :class:`valve_gym.plant.Plant` replaced per-env task code. This script
loads the envs as they were before (``git show REF:valve_gym/envs/...``, default
``REF = e8f7925``, the last commit before the change; it needs the repository's
git history), checks that old and new envs give bit-for-bit the same episodes
(single and vector; direct and residual actions; stem observation with a
``du`` reward weight), then times both interleaved in one process (CPU time of
the calling thread, best of ``--repeats``) and prints new/old env-steps/s.
The project's bar is >= 0.95.

Usage::

    python benchmarks/bench_env_task.py [--repeats 7] [--ref e8f7925]
"""
from __future__ import annotations

import argparse
import importlib.util
import pathlib
import subprocess
import sys
import tempfile
from typing import Any

import gymnasium as gym
import numpy as np

import valve_gym  # noqa: F401  (registers the env ids)
from valve_gym.envs import ValveTankEnv, ValveTankVectorEnv

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_env_speed import single_runner  # noqa: E402  (the same timed loop over gymnasium.make)
from bench_kernel import timed as best  # noqa: E402  (best thread CPU time, repeats interleaved)


def load_old(ref: str):
    """The pre-change ``valve_tank`` and ``vector`` modules of ``ref`` as ``old_valve_tank``, ``old_vector``."""
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="valve_gym_old_envs_"))
    mods = {}
    for name in ("valve_tank", "vector"):
        try:
            src = subprocess.run(["git", "-C", str(ROOT), "show", f"{ref}:valve_gym/envs/{name}.py"],
                                 check=True, capture_output=True, text=True).stdout
        except (OSError, subprocess.CalledProcessError) as e:
            raise SystemExit(f"cannot read valve_gym/envs/{name}.py at {ref} from git ({e}); run this in a git "
                             f"clone of valve_gym with its history, or pass --ref") from None
        src = src.replace("from .. import core", "from valve_gym import core").replace("from ..", "from valve_gym.")
        src = src.replace("from .valve_tank import", "from old_valve_tank import")
        path = tmp / f"old_{name}.py"
        path.write_text(src, encoding="utf-8")
        spec = importlib.util.spec_from_file_location(f"old_{name}", path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[f"old_{name}"] = mod
        spec.loader.exec_module(mod)
        mods[name] = mod
    return mods["valve_tank"], mods["vector"]


def vector_runner(env, n_steps):
    n = env.num_envs
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = [rng.uniform(-1, 1, (n, 1)).astype(np.float32) for _ in range(64)]
    step = env.step

    def run():
        for i in range(n_steps):
            step(acts[i % 64])
    return run


old_valve_tank: Any = None   # set by main()
old_vector: Any = None


def equal_check():
    for cfg in (None, {"action_mode": "residual"}, {"measure_stem": True, "reward": {"du": 0.5}}):
        a, b = ValveTankEnv(cfg), old_valve_tank.ValveTankEnv(cfg)
        ra, rb = a.reset(seed=5), b.reset(seed=5)
        rng = np.random.default_rng(1)
        for k in range(1300):
            act = rng.uniform(-1.2, 1.2, 1).astype(np.float32)
            ra, rb = a.step(act), b.step(act)
            assert np.array_equal(ra[0], rb[0]) and ra[1] == rb[1] and ra[4] == rb[4], (cfg, k)
            if k % 600 == 599:
                ra, rb = a.reset(), b.reset()
                assert np.array_equal(ra[0], rb[0]) and ra[1] == rb[1]
        va, vb = ValveTankVectorEnv(5, cfg), old_vector.ValveTankVectorEnv(5, cfg)
        oa, _ = va.reset(seed=3, options={"z_max": [0.1, np.nan, 0.3, np.nan, 0.01]})
        ob, _ = vb.reset(seed=3, options={"z_max": [0.1, np.nan, 0.3, np.nan, 0.01]})
        assert np.array_equal(oa, ob)
        for k in range(1300):
            act = rng.uniform(-1.2, 1.2, (5, 1)).astype(np.float32)
            sa, sb = va.step(act), vb.step(act)
            for x, y in zip(sa[:4], sb[:4]):
                assert np.array_equal(x, y), (cfg, k)
            assert set(sa[4]) == set(sb[4])
            for key in sa[4]:
                assert np.array_equal(sa[4][key], sb[4][key]), key
    print("equal: old and new envs agree bit for bit (single, vector; direct, residual, stem+du)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--ref", default="e8f7925", help="git revision of the envs to compare against")
    a = ap.parse_args(argv)
    if a.repeats < 1:
        raise SystemExit("--repeats must be at least 1")
    global old_valve_tank, old_vector
    old_valve_tank, old_vector = load_old(a.ref)
    gym.register(id="old/ValveTank-v0", entry_point="old_valve_tank:ValveTankEnv", max_episode_steps=600)
    equal_check()
    reps = a.repeats
    n1 = 20_000
    t = best({"new": single_runner("valve_gym/ValveTank-v0", n1), "old": single_runner("old/ValveTank-v0", n1),
              "new_res": single_runner("valve_gym/ValveTank-v0", n1, config={"action_mode": "residual"}),
              "old_res": single_runner("old/ValveTank-v0", n1, config={"action_mode": "residual"})}, reps)
    print(f"single direct:   new {n1 / t['new']:,.0f} /s  old {n1 / t['old']:,.0f} /s  ratio new/old "
          f"{t['old'] / t['new']:.3f}")
    print(f"single residual: new {n1 / t['new_res']:,.0f} /s  old {n1 / t['old_res']:,.0f} /s  ratio new/old "
          f"{t['old_res'] / t['new_res']:.3f}")
    for n, steps in ((1, 20_000), (64, 3000), (1024, 400)):
        fns = {"new": vector_runner(ValveTankVectorEnv(n), steps),
               "old": vector_runner(old_vector.ValveTankVectorEnv(n), steps),
               "new_res": vector_runner(ValveTankVectorEnv(n, {"action_mode": "residual"}), steps),
               "old_res": vector_runner(old_vector.ValveTankVectorEnv(n, {"action_mode": "residual"}), steps)}
        t = best(fns, max(reps - 2, 2))
        print(f"vector N={n:5d} direct:   new {n * steps / t['new']:,.0f}  old {n * steps / t['old']:,.0f} "
              f"env-steps/s  ratio {t['old'] / t['new']:.3f}")
        print(f"vector N={n:5d} residual: new {n * steps / t['new_res']:,.0f}  old {n * steps / t['old_res']:,.0f} "
              f"env-steps/s  ratio {t['old_res'] / t['new_res']:.3f}")


    return 0


if __name__ == "__main__":
    sys.exit(main())
