"""Tests of ValveTankEnv: API contracts, determinism, options, physics through the core, bad input."""
from __future__ import annotations

import subprocess
import sys
import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import valve_gym
from valve_gym import core
from valve_gym.config import EnvConfig, load_config
from valve_gym.control import PIParams, pi_init, pi_step
from valve_gym.envs import ValveTankEnv
from valve_gym.envs.valve_tank import VALVE_KEYS
from valve_gym.params import ValveParams

ID = "valve_gym/ValveTank-v0"
FIXED = "valve_gym/ValveTankFixed-v0"


def rollout(env, seed, n, actions=None, options=None):
    obs, info = env.reset(seed=seed, options=options)
    out = [(obs, 0.0, info)]
    rng = np.random.default_rng(123)
    for k in range(n):
        a = rng.uniform(-1, 1, 1).astype(np.float32) if actions is None else actions[k]
        obs, r, term, trunc, info = env.step(a)
        assert not term
        out.append((obs, r, info))
    return out


# --------------------------------------------------------------------------- checkers
@pytest.mark.parametrize("kwargs", [
    {},
    {"preset": "fixed"},  # as registered for valve_gym/ValveTankFixed-v0
    {"config": {"action_mode": "residual", "measure_stem": True}},
    {"render_mode": "rgb_array"},
])
def test_gymnasium_check_env(kwargs):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ID, **kwargs).unwrapped  # through make: the render check needs the spec
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no checker warning either
        check_env(env)


def test_sb3_check_env():
    from stable_baselines3.common.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(ValveTankEnv(), warn=True)
        check_env(ValveTankEnv({"action_mode": "residual", "measure_stem": True}), warn=True)


def test_spaces_and_attributes():
    env = gym.make(ID)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    assert env.observation_space.shape == (4,) and env.observation_space.dtype == np.float32
    assert env.unwrapped.substeps == 50 and env.unwrapped.episode_steps == 600
    assert env.spec.max_episode_steps == 600
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    assert set(info) == {"setpoint", "level", "stem", "u", "t", "load", *VALVE_KEYS}
    assert ValveTankEnv({"measure_stem": True}).observation_space.shape == (5,)


# --------------------------------------------------------------------------- seeding
def test_same_seed_same_trajectory_different_seed_differs():
    a = rollout(ValveTankEnv(), 7, 150)
    b = rollout(ValveTankEnv(), 7, 150)
    for (oa, ra, ia), (ob, rb, ib) in zip(a, b):
        assert np.array_equal(oa, ob) and ra == rb and ia == ib
    c = rollout(ValveTankEnv(), 8, 150)
    assert a[0][2]["z_max"] != c[0][2]["z_max"]
    assert not np.array_equal(np.array([o for o, _, _ in a]), np.array([o for o, _, _ in c]))


def test_reset_without_seed_continues_the_generator():
    env = ValveTankEnv()
    _, i1 = env.reset(seed=3)
    _, i2 = env.reset()
    env2 = ValveTankEnv()
    env2.reset(seed=3)
    _, j2 = env2.reset()
    assert i1["z_max"] != i2["z_max"] and i2 == j2


def test_fixed_preset_is_the_same_for_every_seed():
    a = rollout(gym.make(FIXED).unwrapped, 1, 60)
    b = rollout(gym.make(FIXED).unwrapped, 2, 60)
    for (oa, ra, ia), (ob, rb, ib) in zip(a, b):
        assert np.array_equal(oa, ob) and ra == rb
    assert a[0][2]["z_max"] == 0.1 and a[0][2]["e_dead"] == 0.01 and a[0][2]["setpoint"] == 1.2


# --------------------------------------------------------------------------- options
def test_pinned_options_appear_in_info_and_are_used():
    pins = {"z_max": 0.3, "e_dead": 0.015, "tau": 0.12, "v_max": 0.4}
    env = ValveTankEnv()
    obs, info = env.reset(seed=5, options=pins)
    for k, v in pins.items():
        assert info[k] == v and getattr(env.model.valve, k) == v
    assert env.unwrapped.model.valve == ValveParams(**pins)
    # everything else of the episode is the draw of the seed
    obs_free, info_free = ValveTankEnv().reset(seed=5)
    assert np.array_equal(obs, obs_free) and info_free["z_max"] != 0.3
    # pinning changes the trajectory, and the next reset draws again
    traj = rollout(env, 5, 100, options={"z_max": 0.3})
    free = rollout(ValveTankEnv(), 5, 100)
    assert any(t[2]["level"] != f[2]["level"] for t, f in zip(traj, free))
    _, info2 = env.reset()
    assert info2["z_max"] != 0.3


def test_env_level_is_the_core_simulation():
    """The plant of the env is valve_gym.core run with the episode's valve and load."""
    env = ValveTankEnv()
    traj = rollout(env, 11, 300, options={"z_max": 0.2})
    info0 = traj[0][2]
    params = replace(env.config.model, valve=ValveParams(**{k: info0[k] for k in VALVE_KEYS}))
    u = np.array([t[2]["u"] for t in traj[1:]])
    d = np.array([t[2]["load"] for t in traj[1:]])
    tr = core.simulate(params, u, d=d, n_sub=env.substeps)
    np.testing.assert_allclose(tr.level[:, 0], [t[2]["level"] for t in traj[1:]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.h[:, 0], [t[2]["stem"] for t in traj[1:]], rtol=0, atol=1e-12)
    assert np.ptp(d) > 0  # load changes happened
    # direct mode: u = (a + 1)/2, clipped
    env.reset(seed=1)
    assert env.step(np.array([0.2], np.float32))[4]["u"] == pytest.approx(0.6)
    assert env.step(np.array([5.0], np.float32))[4]["u"] == 1.0
    assert env.step(np.array([-3.0], np.float32))[4]["u"] == 0.0


def test_residual_zero_action_is_the_pi_loop():
    cfg = load_config({"action_mode": "residual", "noise_std": 0.0})
    env = ValveTankEnv(cfg)
    obs, info = env.reset(seed=4, options={"z_max": 0.15})
    params = replace(cfg.model, valve=ValveParams(**{k: info[k] for k in VALVE_KEYS}))
    state = core.initial_state(params, 1)
    pip = PIParams(Kc=cfg.pi.Kc, Ti=cfg.pi.Ti, Ts=cfg.control_period)
    pis = pi_init(state.h, info["setpoint"] - info["level"])
    zero = np.zeros(1, np.float32)
    moved = 0
    for _ in range(400):
        pis, u = pi_step(pis, info["setpoint"] - info["level"], pip)
        obs, r, _, _, info = env.step(zero)
        state, y = core.step(state, u, params, d=info["load"], n_sub=env.substeps)
        assert info["u"] == info["u_pi"] == pytest.approx(float(u[0]), abs=1e-15)
        assert info["level"] == pytest.approx(float(state.level[0]), abs=1e-12)
        moved += info["stem"] != state.h[0]
    # a residual action moves the input away from the PI output by residual_scale * a
    obs, r, _, _, info = env.step(np.array([0.5], np.float32))
    assert info["u"] == pytest.approx(min(max(info["u_pi"] + 0.05, 0.0), 1.0))


def test_reward_is_tracking_error_plus_travel():
    env = ValveTankEnv({"reward": {"du": 0.5}})
    traj = rollout(env, 2, 50)
    for (_, _, prev), (obs, r, info) in zip(traj[:-1], traj[1:]):
        expect = -(abs(info["setpoint"] - info["level"]) / 0.1 + 2.0 * abs(info["stem"] - prev["stem"])
                   + 0.5 * abs(info["u"] - prev["u"]))
        assert r == pytest.approx(expect, rel=1e-12)
        assert obs[1] == np.float32(info["setpoint"]) and obs[3] == np.float32(info["u"])


def test_measurement_noise_and_stem_observation():
    env = ValveTankEnv({"measure_stem": True})
    traj = rollout(env, 9, 600)
    noise = np.array([o[0] - i["level"] for o, _, i in traj])
    assert 0.0016 < noise.std() < 0.0024 and abs(noise.mean()) < 0.0005
    assert all(o[4] == np.float32(i["stem"]) for o, _, i in traj)
    assert all(env.observation_space.contains(o) for o, _, _ in traj)


def test_schedules_stay_in_their_ranges():
    env = ValveTankEnv()
    cfg = env.config
    for seed in range(5):
        traj = rollout(env, seed, 600, actions=np.zeros((600, 1), np.float32))
        sp = np.array([i["setpoint"] for _, _, i in traj])
        load = np.array([i["load"] for _, _, i in traj])
        assert cfg.setpoint.initial[0] <= sp[0] <= cfg.setpoint.initial[1]
        assert sp.min() >= 0.5 and sp.max() <= 1.5
        changes = np.flatnonzero(np.diff(sp))
        assert 2 <= changes.size <= 5 and np.all(np.diff(changes) >= 119)
        assert np.all((np.abs(np.diff(sp)[changes]) >= 0.1 - 1e-12)
                      | np.isin(sp[changes + 1], (0.5, 1.5)))
        nz = load[load != 0]
        assert nz.size and np.all((np.abs(nz) >= 0.0005) & (np.abs(nz) <= 0.002))


def test_time_limit_truncates_at_600_and_beyond_horizon_holds():
    env = gym.make(ID)
    env.reset(seed=0)
    a = np.zeros(1, np.float32)
    for k in range(600):
        _, _, term, trunc, info = env.step(a)
        assert not term and trunc == (k == 599)
    assert info["t"] == 600.0
    raw = ValveTankEnv({"episode_seconds": 10.0})
    raw.reset(seed=0)
    for _ in range(25):
        obs, r, term, trunc, info = raw.step(a)
        assert np.isfinite(obs).all() and not (term or trunc)
    assert info["t"] == 25.0


def test_render_rgb_array():
    env = ValveTankEnv(render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (200, 160, 3) and frame.dtype == np.uint8
    with pytest.raises(ValueError, match="render_mode"):
        ValveTankEnv(render_mode="human")


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("mode", ["direct", "residual"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises(bad, mode):
    env = ValveTankEnv({"action_mode": mode})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.array([bad], np.float32))


def test_bad_action_shape_and_order():
    env = ValveTankEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(1, np.float32))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(2, np.float32))
    env.step(0.5)  # a plain number is accepted
    env.step([0.5])


def test_bad_reset_options():
    env = ValveTankEnv()
    with pytest.raises(ValueError, match="unknown reset option 'zmax'.*z_max"):
        env.reset(options={"zmax": 0.1})
    with pytest.raises(ValueError, match="tau"):
        env.reset(options={"tau": -0.1})
    with pytest.raises(ValueError, match="dt"):  # faster valve than the Euler step can follow
        env.reset(options={"tau": 0.01})
    with pytest.raises(ValueError, match="z_max"):
        env.reset(options={"z_max": -0.1})
    with pytest.raises(ValueError, match="finite"):
        env.reset(options={"z_max": np.nan})
    env.reset(options={})  # empty options are fine


# --------------------------------------------------------------------------- registration
def test_make_with_config_and_preset(tmp_path):
    env = gym.make(ID, config={"action_mode": "residual"})
    assert env.unwrapped.config.action_mode == "residual"
    path = tmp_path / "c.yaml"
    path.write_text("noise_std: 0.0\nmodel:\n  valve:\n    z_max: 0.3\n")
    env = gym.make(FIXED, config=str(path))
    assert env.unwrapped.config.noise_std == 0.0
    assert env.unwrapped.config.model.valve.z_max == 0.3  # over the fixed preset
    assert not env.unwrapped.config.randomise.enabled
    assert gym.make(ID, config=EnvConfig(noise_std=0.001)).unwrapped.config.noise_std == 0.001


def test_all_exports_exist():
    for name in valve_gym.__all__:
        assert hasattr(valve_gym, name), name


def _run(code):
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return res.stdout


def test_module_colon_id_in_fresh_interpreter_and_light_import():
    out = _run(
        "import sys, gymnasium as gym\n"
        "env = gym.make('valve_gym:valve_gym/ValveTank-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(obs.shape, env.spec.max_episode_steps)\n"
        "heavy = [m for m in ('torch', 'stable_baselines3', 'matplotlib') if m in sys.modules]\n"
        "print('heavy', heavy)\n")
    assert "(4,) 600" in out and "heavy []" in out


def test_no_global_random_state_is_used():
    import random

    np_state, py_state = np.random.get_state(), random.getstate()
    env = ValveTankEnv()
    rollout(env, 0, 20)
    env.reset()
    after = np.random.get_state()
    assert all(np.array_equal(x, y) for x, y in zip(np_state, after)) and random.getstate() == py_state


def test_pickled_env_continues_identically():
    import pickle

    env = ValveTankEnv({"action_mode": "residual"})
    env.reset(seed=3)
    for _ in range(10):
        env.step(np.array([0.3], np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(20):
        a = np.array([-0.2], np.float32)
        o1, r1, *_, i1 = env.step(a)
        o2, r2, *_, i2 = clone.step(a)
        assert np.array_equal(o1, o2) and r1 == r2 and i1 == i2


# ----------------------------------------------------------------- the regulation task
def _reg_cfg(**kw):
    from valve_gym.envs.regulation import RegulationTaskConfig

    return RegulationTaskConfig(**{"episode_s": 60.0, **kw})


def test_regulation_env_registered_and_checkers():
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    from valve_gym.envs import ENV_IDS, ValveTankRegulationEnv

    assert "valve_gym/ValveTankRegulation-v0" in ENV_IDS
    env = gym.make("valve_gym/ValveTankRegulation-v0")
    assert env.spec.max_episode_steps == 1800
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gym_check(env.unwrapped)
        sb3_check(ValveTankRegulationEnv(_reg_cfg()), warn=True)
    venv = gym.make_vec("valve_gym/ValveTankRegulation-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs, info = venv.reset(seed=0)
    assert obs.shape == (3, 14) and venv.action_space.shape == (3, 2)   # 11 + the 3 stickiness features


def test_regulation_single_equals_vector_and_is_deterministic():
    from valve_gym.envs import ValveTankRegulationEnv, ValveTankRegulationVectorEnv

    cfg = _reg_cfg(friction_models=("riihilahti", "choudhury"))
    venv = ValveTankRegulationVectorEnv(3, cfg)
    vo, vi = venv.reset(seed=[7, 8, 9])
    acts = np.random.default_rng(0).uniform(-1, 1, (60, 3, 2)).astype(np.float32)
    traj = [venv.step(a) for a in acts]
    for j, s in enumerate((7, 8, 9)):
        for _ in range(2):                                  # same seed, same trajectory
            env = ValveTankRegulationEnv(cfg)
            o, info = env.reset(seed=s)
            np.testing.assert_array_equal(o, vo[j])
            assert info["S"] == vi["S"][j] and info["friction_model"] == vi["friction_model"][j]
            for k in range(59):
                o, r, term, trunc, inf = env.step(acts[k, j])
                np.testing.assert_array_equal(o, traj[k][0][j])
                assert r == traj[k][1][j] and not trunc
            o, r, term, trunc, inf = env.step(acts[59, j])
            assert trunc and traj[59][3][j]
            np.testing.assert_array_equal(o, traj[59][4]["final_obs"][j])


def test_regulation_starts_at_steady_state_and_pi_action_is_the_pi():
    from valve_gym.envs import ValveTankRegulationVectorEnv
    from valve_gym.envs.regulation import pi_action

    env = ValveTankRegulationVectorEnv(2, _reg_cfg(noise_std=(0.0, 0.0), load_std=(0.0, 0.0)))
    env.reset(seed=1, options={"model": "choudhury", "S": 0.03, "J": 0.01, "level": 1.2})
    for _ in range(30):
        obs, r, te, tr, info = env.step(pi_action(2))
    np.testing.assert_allclose(info["level"], 1.2, atol=1e-6)      # no load, no noise: nothing moves
    np.testing.assert_allclose(obs[:, 0], 0.0, atol=1e-3)


@pytest.mark.parametrize("options,msg", [
    ({"S": 0.6}, "'S'"), ({"J": 0.05, "S": 0.01}, "must not exceed"), ({"model": "karnopp"}, "model"),
    ({"zz": 1}, "unknown reset option"), ({"level": float("nan")}, "'level'"), ({"S": [0.1, 0.2]}, "'S'"),
])
def test_regulation_bad_options(options, msg):
    from valve_gym.envs import ValveTankRegulationEnv

    env = ValveTankRegulationEnv(_reg_cfg())
    with pytest.raises(ValueError, match=msg):
        env.reset(seed=0, options=options)


def test_regulation_bad_actions_and_config():
    from valve_gym.config import ConfigError
    from valve_gym.envs import ValveTankRegulationEnv

    env = ValveTankRegulationEnv(_reg_cfg())
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    for bad, key in (({"friction_models": ["nope"]}, "nope"), ({"S_bands": [0.1, 0.05]}, "S_bands"),
                     ({"block": {"g_min": 0.0}}, "g_min"), ({"levels": [1.0, 0.5]}, "levels")):
        with pytest.raises(ConfigError, match=key):
            ValveTankRegulationEnv(bad)
