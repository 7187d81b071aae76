"""Tests of the Stable-Baselines3 adapter: equal to DummyVecEnv of gymnasium.make envs, subprocess pickling."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv  # noqa: E402

import valve_gym  # noqa: E402,F401  (registers the ids)
from valve_gym.envs import ValveTankVectorEnv  # noqa: E402
from valve_gym.envs.sb3 import SB3VecEnv  # noqa: E402

ID = "valve_gym/ValveTank-v0"
SHORT = {"episode_seconds": 15.0, "setpoint": {"interval": [4.0, 8.0]}, "load": {"interval": [3.0, 6.0]}}


def dummy(n, cfg):
    return DummyVecEnv([lambda: gym.make(ID, config=cfg, max_episode_steps=15) for _ in range(n)])


def assert_infos_equal(ia, ib):
    assert len(ia) == len(ib)
    for a, b in zip(ia, ib):
        assert set(a) == set(b), (set(a) ^ set(b))
        for k in a:
            if k == "terminal_observation":
                assert np.array_equal(a[k], b[k]) and a[k].dtype == b[k].dtype
            else:
                assert a[k] == b[k], (k, a[k], b[k])


@pytest.mark.parametrize("mode", ["direct", "residual"])
def test_equals_dummy_vec_env_step_for_step(mode):
    cfg = {**SHORT, "action_mode": mode}
    n = 3
    a, b = SB3VecEnv(n, cfg), dummy(n, cfg)
    a.seed(21)
    b.seed(21)
    oa, ob = a.reset(), b.reset()
    assert np.array_equal(oa, ob) and oa.dtype == ob.dtype
    assert_infos_equal(a.reset_infos, b.reset_infos)
    rng = np.random.default_rng(2)
    n_done = 0
    for t in range(50):
        act = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        oa, ra, da, ia = a.step(act)
        ob, rb, db, ib = b.step(act)
        assert np.array_equal(oa, ob), t
        assert np.array_equal(ra, rb) and ra.dtype == rb.dtype
        assert np.array_equal(da, db)
        assert_infos_equal(ia, ib)
        assert_infos_equal(a.reset_infos, b.reset_infos)
        n_done += int(da.sum())
        for i in np.flatnonzero(da):
            assert ia[i]["TimeLimit.truncated"] is True
    assert n_done == 3 * n  # three episode ends per env in 50 steps of 15-step episodes


def test_options_attributes_and_render():
    venv = SB3VecEnv(2, render_mode="rgb_array")
    venv.seed(0)
    venv.set_options([{"z_max": 0.25}, {}])
    venv.reset()
    assert venv.reset_infos[0]["z_max"] == 0.25 and venv.reset_infos[1]["z_max"] != 0.25
    assert venv.get_attr("z_max") == [0.25, venv.reset_infos[1]["z_max"]]
    assert venv.get_attr("substeps", indices=[1]) == [50]
    assert venv.env_is_wrapped(gym.Wrapper) == [False, False]
    assert venv.render().shape[-1] == 3
    assert len(venv.env_method("render", indices=[1])) == 1
    venv.set_options({"zmax": 1.0})
    with pytest.raises(ValueError, match="unknown reset option"):
        venv.reset()
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnv(venv=ValveTankVectorEnv(2))
    # the lazily imported name
    from valve_gym.envs import SB3VecEnv as lazy
    assert lazy is SB3VecEnv


def test_make_vec_env_subproc_pickles():
    venv = make_vec_env(ID, n_envs=2, seed=0, vec_env_cls=SubprocVecEnv,
                        vec_env_kwargs={"start_method": "fork"}, env_kwargs={"config": SHORT})
    try:
        obs = venv.reset()
        assert obs.shape == (2, 4)
        for _ in range(5):
            obs, rew, done, info = venv.step(np.zeros((2, 1), np.float32))
        assert np.isfinite(obs).all() and info[0]["t"] == 5.0
        assert venv.get_attr("substeps") == [50, 50]
    finally:
        venv.close()


def test_ppo_learns_a_few_steps_on_the_adapter():
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    torch.set_num_threads(1)
    venv = SB3VecEnv(4, SHORT)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.set_logger(Logger(folder=None, output_formats=[]))    # SB3's default makes a folder in /tmp
    model.learn(total_timesteps=64)
    act, _ = model.predict(venv.reset(), deterministic=True)
    assert act.shape == (4, 1)
