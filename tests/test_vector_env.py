"""Tests of ValveTankVectorEnv: equal to N single envs step for step, autoreset, seeding, options."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import valve_gym  # noqa: F401  (registers the ids)
from valve_gym.envs import ValveTankEnv, ValveTankVectorEnv
from valve_gym.envs import vector as vector_module
from valve_gym.envs.valve_tank import VALVE_KEYS

ID = "valve_gym/ValveTank-v0"
SHORT = {"episode_seconds": 20.0, "setpoint": {"interval": [5.0, 9.0]}, "load": {"interval": [3.0, 7.0]}}
STEP_KEYS = ("setpoint", "level", "stem", "u", "t", "load", *VALVE_KEYS)


def singles(cfg, n, seeds):
    envs = [gym.wrappers.TimeLimit(ValveTankEnv(cfg), max_episode_steps=20) for _ in range(n)]
    return envs, [e.reset(seed=s) for e, s in zip(envs, seeds)]


def assert_info_equal(vinfo, i, info, keys):
    for k in keys:
        assert vinfo[k][i] == info[k], (k, vinfo[k][i], info[k])
        assert vinfo["_" + k][i]


@pytest.mark.parametrize("mode", ["direct", "residual"])
def test_equals_single_envs_step_for_step_across_autoreset(mode):
    cfg = {**SHORT, "action_mode": mode, "measure_stem": mode == "residual"}
    n, T = 4, 70  # three episode ends (steps 20, 41, 62: NEXT_STEP resets take one step)
    venv = ValveTankVectorEnv(n, cfg)
    assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    keys = STEP_KEYS + (("u_pi",) if mode == "residual" else ())
    obs, vinfo = venv.reset(seed=10)
    envs, first = singles(cfg, n, [10 + i for i in range(n)])
    for i, (o, info) in enumerate(first):
        assert np.array_equal(obs[i], o)
        assert_info_equal(vinfo, i, info, keys)
    rng = np.random.default_rng(0)
    need_reset = [False] * n
    n_resets = 0
    for t in range(T):
        act = rng.uniform(-1.2, 1.2, (n, 1)).astype(np.float32)
        obs, rew, term, trunc, vinfo = venv.step(act)
        assert rew.dtype == np.float64 and obs.dtype == np.float32 and not term.any()
        for i, env in enumerate(envs):
            if need_reset[i]:
                o, info = env.reset()
                r, tr = 0.0, False
                n_resets += 1
            else:
                o, r, te, tr, info = env.step(act[i])
            need_reset[i] = tr
            assert np.array_equal(obs[i], o), (t, i)
            assert rew[i] == r and trunc[i] == tr, (t, i)
            assert_info_equal(vinfo, i, info, keys)
    assert n_resets == 3 * n


def test_equals_gymnasium_sync_vector_env():
    """Same seeds, same autoreset semantics as Gymnasium's own SyncVectorEnv of the single env."""
    n = 3
    native = gym.make_vec(ID, num_envs=n, vectorization_mode="vector_entry_point", config=SHORT,
                          max_episode_steps=20)
    sync = gym.make_vec(ID, num_envs=n, vectorization_mode="sync", config=SHORT, max_episode_steps=20)
    oa, ia = native.reset(seed=3)
    ob, ib = sync.reset(seed=3)
    assert np.array_equal(oa, ob)
    rng = np.random.default_rng(1)
    for t in range(45):
        act = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        ra, rb = native.step(act), sync.step(act)
        for x, y in zip(ra[:4], rb[:4]):
            assert np.array_equal(x, y), t
        for k in STEP_KEYS:
            assert np.array_equal(ra[4][k], rb[4][k]), (t, k)


def test_same_step_autoreset():
    n = 3
    venv = ValveTankVectorEnv(n, SHORT, autoreset_mode="SameStep")
    assert venv.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    venv.reset(seed=0)
    envs, _ = singles(SHORT, n, range(n))
    act = np.zeros((n, 1), np.float32)
    for t in range(25):
        obs, rew, term, trunc, info = venv.step(act)
        for i, env in enumerate(envs):
            o, r, te, tr, inf = env.step(act[i])
            assert rew[i] == r and trunc[i] == tr
            if tr:
                assert np.array_equal(info["final_obs"][i], o) and info["_final_obs"][i]
                assert_info_equal(info["final_info"], i, inf, STEP_KEYS)
                o, inf = env.reset()
            assert np.array_equal(obs[i], o)
            assert_info_equal(info, i, inf, STEP_KEYS)
        assert ("final_obs" in info) == (t == 19)


def test_seed_list_and_pinned_arrays():
    venv = ValveTankVectorEnv(3)
    obs, info = venv.reset(seed=[5, None, 7], options={"z_max": [0.2, np.nan, 0.3], "e_dead": 0.01})
    assert info["z_max"][0] == 0.2 and info["z_max"][2] == 0.3 and 0.002 <= info["z_max"][1] <= 0.5
    assert np.all(info["e_dead"] == 0.01)
    assert np.all(venv.model.valve.z_max == info["z_max"])
    o5, i5 = ValveTankEnv().reset(seed=5, options={"z_max": 0.2, "e_dead": 0.01})
    assert np.array_equal(obs[0], o5)
    o7, i7 = ValveTankEnv().reset(seed=7)
    assert info["tau"][2] == i7["tau"] and info["z_max"][2] != i7["z_max"]
    # seed=s is s + i; the next reset without a seed continues each generator
    venv.reset(seed=5)
    _, info2 = venv.reset()
    env = ValveTankEnv()
    env.reset(seed=6)
    assert info2["z_max"][1] == env.reset()[1]["z_max"]


def test_partial_reset_with_mask():
    venv = ValveTankVectorEnv(3, SHORT, autoreset_mode=AutoresetMode.DISABLED)
    venv.reset(seed=0)
    for _ in range(5):
        obs, *_ , info = venv.step(np.zeros((3, 1), np.float32))
    obs2, info2 = venv.reset(options={"reset_mask": np.array([False, True, False])})
    assert list(info2["t"]) == [5.0, 0.0, 5.0]
    assert np.array_equal(obs2[[0, 2]], obs[[0, 2]])
    assert info2["level"][1] == 1.0
    # DISABLED: no autoreset at the limit
    for _ in range(20):
        *_, trunc, info = venv.step(np.zeros((3, 1), np.float32))
    assert list(info["t"]) == [25.0, 20.0, 25.0]


def test_one_kernel_call_per_step(monkeypatch):
    calls = []
    real = vector_module.core.run_packed

    def counting(*args, **kw):
        calls.append(args[3].shape)
        return real(*args, **kw)

    monkeypatch.setattr(vector_module.core, "run_packed", counting)
    venv = ValveTankVectorEnv(16, SHORT)
    venv.reset(seed=0)
    for _ in range(30):
        venv.step(np.zeros((16, 1), np.float32))
    assert calls == [(1, 16)] * 30


def test_kernel_threads_change_nothing_but_speed():
    out = []
    for threads in (1, 2):
        venv = ValveTankVectorEnv(7, SHORT, threads=threads)
        obs, _ = venv.reset(seed=3)
        rng = np.random.default_rng(0)
        rows = [obs]
        for _ in range(80):                       # crosses the autoresets of SHORT episodes
            obs, rew, term, trunc, info = venv.step(rng.uniform(-1, 1, (7, 1)).astype(np.float32))
            rows += [obs, rew[:, None], info["stem"][:, None], info["level"][:, None]]
        out.append(np.concatenate([np.asarray(r, float).reshape(7, -1) for r in rows], axis=1))
    np.testing.assert_array_equal(out[0], out[1])


def test_make_vec_vector_entry_point_and_time_limit():
    envs = gym.make_vec(ID, num_envs=5, vectorization_mode="vector_entry_point")
    assert isinstance(envs.unwrapped, ValveTankVectorEnv) and envs.num_envs == 5
    assert envs.unwrapped.substeps == 50 and envs.unwrapped.max_episode_steps == 600
    assert envs.observation_space.shape == (5, 4) and envs.action_space.shape == (5, 1)
    envs.reset(seed=0)
    a = np.zeros((5, 1), np.float32)
    for k in range(601):
        obs, rew, term, trunc, info = envs.step(a)
        assert trunc.all() == (k == 599)
    assert np.all(info["t"] == 0.0) and np.all(rew == 0.0)  # the autoreset step
    fixed = gym.make_vec("valve_gym/ValveTankFixed-v0", num_envs=2, vectorization_mode="vector_entry_point")
    _, info = fixed.reset(seed=0)
    assert np.all(info["z_max"] == 0.1)


def test_render_and_bad_input():
    venv = ValveTankVectorEnv(2, render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(np.zeros((2, 1), np.float32))
    venv.reset(seed=0)
    frames = venv.render()
    assert len(frames) == 2 and frames[0].shape == (200, 160, 3)
    with pytest.raises(ValueError, match=r"sub-environments \[1\]"):
        venv.step(np.array([[0.0], [np.nan]], np.float32))
    with pytest.raises(ValueError, match="not finite"):
        venv.step(np.array([[np.inf], [0.0]], np.float32))
    residual = ValveTankVectorEnv(2, {"action_mode": "residual"})
    residual.reset(seed=0)
    with pytest.raises(ValueError, match=r"sub-environments \[0\]"):
        residual.step(np.array([[-np.inf], [0.0]], np.float32))
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 1), np.float32))
    with pytest.raises(ValueError, match="unknown reset option"):
        venv.reset(options={"zmax": 0.1})
    with pytest.raises(ValueError, match="shape"):
        venv.reset(options={"z_max": [0.1, 0.2, 0.3]})
    with pytest.raises(ValueError, match="z_max"):
        venv.reset(options={"z_max": [0.1, -0.2]})
    with pytest.raises(ValueError, match="3 seeds"):
        ValveTankVectorEnv(3).reset(seed=[1, 2])
    with pytest.raises(ValueError, match="num_envs"):
        ValveTankVectorEnv(0)
    with pytest.raises(ValueError, match="autoreset_mode"):
        ValveTankVectorEnv(2, autoreset_mode="sometimes")
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="threads must be a positive integer"):
            ValveTankVectorEnv(2, threads=bad)
    venv.step(np.zeros(2, np.float32))  # (N,) is accepted as (N, 1)


def test_pickled_vector_env_continues_identically():
    import pickle

    venv = ValveTankVectorEnv(3, {**SHORT, "action_mode": "residual"})
    venv.reset(seed=1)
    a = np.full((3, 1), 0.2, np.float32)
    for _ in range(8):
        venv.step(a)
    clone = pickle.loads(pickle.dumps(venv))
    for _ in range(30):
        r1, r2 = venv.step(-a), clone.step(-a)
        for x, y in zip(r1[:4], r2[:4]):
            assert np.array_equal(x, y)
