"""Every registered id through the ecosystem's helpers: Gymnasium, Stable-Baselines3, rl-zoo3's import hook."""
from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import valve_gym  # noqa: F401  (registers the ids)
from valve_gym._registration import ENV_IDS, MAX_EPISODE_STEPS_BY_ID

sb3 = pytest.importorskip("stable_baselines3")

from stable_baselines3.common.env_checker import check_env as sb3_check_env  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _steps(venv, n_steps: int = 3) -> np.ndarray:
    """Reset an SB3 VecEnv and step it with random actions; returns the last observations."""
    obs = venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(n_steps):
        act = rng.uniform(-1, 1, (venv.num_envs,) + venv.action_space.shape).astype(np.float32)
        obs, rew, done, infos = venv.step(act)
        assert rew.shape == (venv.num_envs,) and np.all(np.isfinite(rew))
        assert len(infos) == venv.num_envs
    assert obs.shape == (venv.num_envs,) + venv.observation_space.shape
    return obs


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_make_and_time_limit(env_id):
    env = gym.make(env_id)
    assert env.spec is not None and env.spec.max_episode_steps == MAX_EPISODE_STEPS_BY_ID[env_id]
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    obs, r, term, trunc, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs) and isinstance(r, float)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("mode", ["vector_entry_point", "sync"])
def test_gymnasium_make_vec(env_id, mode):
    venv = gym.make_vec(env_id, num_envs=3, vectorization_mode=mode)
    obs, info = venv.reset(seed=[1, 2, 3])
    assert obs.shape == (3,) + venv.single_observation_space.shape
    assert not np.array_equal(obs[0], obs[1]) or env_id.endswith("Fixed-v0")
    obs, r, term, trunc, info = venv.step(venv.action_space.sample())
    assert r.shape == (3,) and term.shape == (3,) and trunc.shape == (3,)
    venv.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_vector_entry_point_equals_sync(env_id):
    """The native vector env and Gymnasium's SyncVectorEnv of the same id give the same first steps."""
    a = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    b = gym.make_vec(env_id, num_envs=2, vectorization_mode="sync")
    oa, _ = a.reset(seed=[5, 6])
    ob, _ = b.reset(seed=[5, 6])
    np.testing.assert_array_equal(oa, ob)
    rng = np.random.default_rng(1)
    for _ in range(5):
        act = rng.uniform(-1, 1, a.action_space.shape).astype(np.float32)
        oa, ra, *_ = a.step(act)
        ob, rb, *_ = b.step(act)
        np.testing.assert_allclose(oa, ob, rtol=0, atol=1e-6)
        np.testing.assert_allclose(ra, rb, rtol=1e-9, atol=1e-9)
    a.close()
    b.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_make_vec_env_passes_render_mode(env_id):
    """SB3's ``make_vec_env`` creates each env with ``render_mode='rgb_array'``: it must be accepted."""
    venv = make_vec_env(env_id, n_envs=2, seed=0)
    _steps(venv)
    frames = venv.get_images()
    assert len(frames) == 2 and frames[0].shape == (200, 160, 3) and frames[0].dtype == np.uint8
    venv.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_dummy_vec_env_and_vec_normalize(env_id):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(env_id) for _ in range(2)]))
    _steps(venv, 5)
    assert venv.obs_rms.count > 1
    venv.close()


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_subproc_vec_env(env_id):
    """A spawned worker has not run ``import valve_gym``: the ``valve_gym:`` prefix makes ``gym.make`` import it
    (a script that imports valve_gym at the top needs no prefix: its workers re-import the main module)."""
    venv = make_vec_env("valve_gym:" + env_id, n_envs=2, seed=0, vec_env_cls=SubprocVecEnv,
                        vec_env_kwargs={"start_method": "spawn"})
    try:
        _steps(venv)
    finally:
        venv.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_and_sb3_checkers(env_id):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")       # the checkers must have nothing to warn about
        check_env(gym.make(env_id).unwrapped, skip_render_check=False)
        sb3_check_env(gym.make(env_id), warn=True)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_bad_render_mode_is_one_clear_error(env_id):
    with pytest.raises(ValueError, match="render_mode must be None or one of"):
        gym.make(env_id, render_mode="ansi").unwrapped


def test_import_valve_gym_registers_every_id_like_rl_zoo3_gym_packages():
    """rl-zoo3's ``--gym-packages valve_gym`` does ``importlib.import_module('valve_gym')``: that must register."""
    code = ("import importlib, gymnasium as gym; importlib.import_module('valve_gym'); "
            "from valve_gym._registration import ENV_IDS; "
            "[gym.make(i).reset(seed=0) for i in ENV_IDS]; print('ok', len(ENV_IDS))")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == f"ok {len(ENV_IDS)}"


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("vector", [False, True])
def test_env_class_docstring_has_gymnasium_sections(env_id, vector):
    env = (gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point") if vector
           else gym.make(env_id).unwrapped)
    doc = type(env).__doc__ or ""
    for section in ("## Description", "## Action Space", "## Observation Space", "## Rewards",
                    "## Starting State", "## Episode End", "## Arguments", "## Version History"):
        assert section in doc, (type(env).__name__, section)


def test_sb3_regulation_adapter_equals_dummy_vec_env():
    from valve_gym.envs.sb3 import SB3RegulationVecEnv

    cfg = {"episode_s": 20.0}
    a = SB3RegulationVecEnv(3, cfg)
    b = DummyVecEnv([lambda: gym.make("valve_gym/ValveTankRegulation-v0", config=cfg, max_episode_steps=20)
                     for _ in range(3)])
    a.seed(4)
    b.seed(4)
    np.testing.assert_array_equal(a.reset(), b.reset())
    rng = np.random.default_rng(0)
    for t in range(45):
        act = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        oa, ra, da, ia = a.step(act)
        ob, rb, db, ib = b.step(act)
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_allclose(ra, rb, rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(da, db)
        for x, y in zip(ia, ib):
            if "terminal_observation" in y:
                np.testing.assert_array_equal(x["terminal_observation"], y["terminal_observation"])
                assert x["TimeLimit.truncated"] is True
    assert VecNormalize(a).reset().shape == (3, 14)
