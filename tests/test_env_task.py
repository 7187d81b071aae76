"""Tests of valve_gym.envs.task: the task rules the single and the vector env share, each written once."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym import core
from valve_gym.envs import ValveTankEnv, ValveTankVectorEnv, task
from valve_gym.envs import valve_tank as valve_tank_module
from valve_gym.envs.task import (
    OBS_NAMES,
    TaskPlan,
    batch_actions,
    check_options,
    clip_actions,
    direct_input,
    direct_inputs,
    draw_episodes,
    make_config,
    obs_names,
    observation,
    observation_space,
    observations,
    parse_options,
    raise_nonfinite,
    residual_input,
    residual_inputs,
    scalar_action,
    schedule,
    step_reward,
    step_reward_nb,
    write_observation,
)

SHORT = {"episode_seconds": 60.0, "setpoint": {"interval": [10.0, 20.0]}, "load": {"interval": [5.0, 15.0]}}


def test_valve_tank_reexports_the_task_names():
    for name in ("VALVE_KEYS", "NEVER", "EpisodeDraw", "draw_episodes", "schedule", "make_config"):
        assert getattr(valve_tank_module, name) is getattr(task, name)
    assert set(valve_tank_module.__all__) >= {"ValveTankEnv", "VALVE_KEYS", "draw_episodes", "make_config"}


@pytest.mark.parametrize("stem", [False, True])
def test_observation_layout_is_one_rule(stem):
    cfg = make_config({"measure_stem": stem})
    plan = TaskPlan(cfg)
    names = obs_names(stem)
    assert names[:4] == OBS_NAMES and len(names) == plan.n_obs == observation_space(cfg).shape[0]
    rng = np.random.default_rng(0)
    ym, sp, u, h = rng.uniform(0, 2, (4, 6))
    batch = observations(ym, sp, u, h, stem)
    compiled = np.empty((6, plan.n_obs), dtype=np.float32)
    for i in range(6):
        write_observation(compiled, i, ym[i], sp[i], u[i], h[i])
        one = observation(float(ym[i]), float(sp[i]), float(u[i]), float(h[i]), stem)
        assert one.dtype == np.float32 and one.shape == (plan.n_obs,)
        np.testing.assert_array_equal(batch[i], one)
    np.testing.assert_array_equal(compiled, batch)
    expected = {"level_measured": ym, "setpoint": sp, "error_measured": sp - ym, "u": u, "stem": h}
    for j, name in enumerate(names):
        np.testing.assert_array_equal(batch[:, j], expected[name].astype(np.float32))


def test_scalar_action_validates_and_clips():
    assert scalar_action(np.array([0.25], np.float32)) == 0.25
    assert scalar_action(1.7) == 1.0 and scalar_action([-3.0]) == -1.0
    assert scalar_action(np.array([[0.5]])) == 0.5
    for bad in (np.nan, [np.inf], np.array([-np.inf], np.float32)):
        with pytest.raises(ValueError, match="not finite"):
            scalar_action(bad)
    with pytest.raises(ValueError, match="shape"):
        scalar_action(np.zeros(2))
    with pytest.raises(ValueError, match="number"):
        scalar_action("open")


def test_action_scaling_scalar_equals_batched():
    rng = np.random.default_rng(1)
    a = rng.uniform(-1.5, 1.5, (50, 1)).astype(np.float32)
    u = np.empty(50)
    assert direct_inputs(a, u) == 0
    ac = np.empty(50)
    assert clip_actions(a, ac) == 0
    upi = rng.uniform(-0.1, 1.1, 50)
    ur = np.empty(50)
    residual_inputs(upi, ac, 0.3, ur)
    for i in range(50):
        ai = scalar_action(a[i])
        assert ac[i] == ai and -1.0 <= ai <= 1.0
        assert u[i] == direct_input(ai) == (ai + 1.0) * 0.5
        assert ur[i] == residual_input(upi[i], ai, 0.3) == min(max(upi[i] + 0.3 * ai, 0.0), 1.0)


def test_batched_actions_count_and_name_the_non_finite():
    a = np.array([[0.1], [np.nan], [0.3], [np.inf]], np.float32)
    assert direct_inputs(batch_actions(a, 4), np.empty(4)) == 2
    assert clip_actions(batch_actions(a, 4), np.empty(4)) == 2
    with pytest.raises(ValueError, match=r"sub-environments \[1, 3\]"):
        raise_nonfinite(a)
    assert batch_actions(np.zeros(4), 4).shape == (4, 1)
    with pytest.raises(ValueError, match=r"shape \(4, 1\)"):
        batch_actions(np.zeros((2, 2)), 4)
    with pytest.raises(ValueError, match="numbers"):
        batch_actions(np.array(["a"] * 4, dtype=object), 4)


@pytest.mark.parametrize("wu", [0.0, 0.5])
def test_reward_rule_scalar_array_and_compiled_agree(wu):
    rng = np.random.default_rng(2)
    sp, lv, h, hp, u, up = rng.uniform(0, 2, (6, 20))
    ce, wt = 10.0, 2.0
    arr = step_reward(sp, lv, h, hp, u, up, ce, wt, wu)
    for i in range(20):
        one = step_reward(sp[i], lv[i], h[i], hp[i], u[i], up[i], ce, wt, wu)
        assert one == arr[i] == step_reward_nb(sp[i], lv[i], h[i], hp[i], u[i], up[i], ce, wt, wu)
        assert one == pytest.approx(-(ce * abs(sp[i] - lv[i]) + wt * abs(h[i] - hp[i]) + wu * abs(u[i] - up[i])))


def test_plan_reward_weights_and_action_mode_follow_the_config():
    plan = TaskPlan(make_config({"action_mode": "residual", "residual_scale": 0.2,
                                 "reward": {"error": 2.0, "error_scale": 0.5, "travel": 3.0, "du": 0.1}}))
    assert plan.residual and plan.scale == 0.2
    assert (plan.ce, plan.wt, plan.wu) == (4.0, 3.0, 0.1)
    assert TaskPlan(make_config()).rest_levels() == {"level": 1.0}
    cas = TaskPlan(make_config({"model": {"process_kind": "cascade", "cascade": {}}}))
    m = cas.cfg.model
    assert cas.rest_levels() == {"level": m.cascade.level2_0, "level_upper": m.process.level0}


def test_reward_in_env_is_the_task_rule():
    env = ValveTankEnv({"reward": {"du": 0.3}})
    _, info = env.reset(seed=4)
    rng = np.random.default_rng(0)
    plan = TaskPlan(env.config)
    for _ in range(30):
        _, r, _, _, new = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
        assert r == step_reward(new["setpoint"], new["level"], new["stem"], info["stem"], new["u"], info["u"],
                                plan.ce, plan.wt, plan.wu)
        info = new


def test_parse_and_check_options():
    assert parse_options(None, None, False) is None and parse_options({}, 3, True) is None
    pins = parse_options({"z_max": 0.2, "tau": [0.1, np.nan, 0.15]}, 3, allow_nan=True)
    assert pins is not None and set(pins) == {"z_max", "tau"} and pins["tau"].shape == (3,)
    cases = [(["z_max"], None, "must be a dict"), ({"k_out": 1.0}, None, "unknown reset option"),
             ({"z_max": "big"}, None, "must be a number"), ({"z_max": [0.1, 0.2]}, None, "single number"),
             ({"z_max": [0.1, 0.2]}, 3, r"shape \(3,\)"), ({"z_max": np.nan}, None, "finite"),
             ({"z_max": np.inf}, 3, "finite")]
    for options, n, match in cases:
        with pytest.raises(ValueError, match=match):
            parse_options(options, n, allow_nan=n is not None)
    model = make_config().model
    check_options({"z_max": np.array(0.3)}, model)
    with pytest.raises(ValueError, match="reset option 'tau'.*dt"):
        check_options({"tau": np.array(0.001)}, model)
    with pytest.raises(ValueError, match="reset option 'e_dead'"):
        check_options({"e_dead": np.array([0.01, -1.0])}, model)


def test_batch_draw_equals_single_draws_and_pins_change_nothing_else():
    plan = TaskPlan(make_config())
    batch = draw_episodes([np.random.default_rng(s) for s in range(4)], plan)
    for s in range(4):
        one = draw_episodes([np.random.default_rng(s)], plan)
        for a, b in zip(one, batch):
            np.testing.assert_array_equal(a[0], b[s])
    pinned = draw_episodes([np.random.default_rng(s) for s in range(4)], plan,
                           {"z_max": np.array([0.3, np.nan, 0.3, np.nan])})
    np.testing.assert_array_equal(pinned.z_max, [0.3, batch.z_max[1], 0.3, batch.z_max[3]])
    for key in pinned._fields:
        if key != "z_max":
            np.testing.assert_array_equal(getattr(pinned, key), getattr(batch, key))


def test_schedule_counts_the_events_due():
    rng = np.random.default_rng(5)
    H, n, E = 40, 5, 6
    steps = rng.integers(0, H + 5, (n, E))
    steps[0, -2:] = task.NEVER
    vals = rng.normal(size=(n, E))
    v0 = rng.normal(size=n)
    dense = schedule(v0, steps, vals, H)
    allv = np.concatenate([v0[:, None], vals], axis=1)
    for j in range(n):
        for k in range(H + 1):
            assert dense[j, k] == allv[j, int(np.sum(steps[j] <= k))]


CONFIGS = [
    {},
    {"action_mode": "residual", "reward": {"du": 0.2}},
    {"measure_stem": True, "model": {"process_kind": "cascade", "cascade": {}}},
    {"model": {"dead_time": {"theta": 2.0}, "sensor_lag": {"tau_s": 3.0}}},
    {"model": {"slip_jump": {"law": "kano", "S": 0.03, "J": 0.01}}},
]


@pytest.mark.parametrize("extra", CONFIGS)
def test_single_and_vector_env_agree_across_models(extra):
    cfg = make_config({**SHORT, **extra})
    venv = ValveTankVectorEnv(3, cfg)
    envs = [ValveTankEnv(cfg) for _ in range(3)]
    vobs, _ = venv.reset(seed=[7, 8, 9])
    for i, e in enumerate(envs):
        obs, _ = e.reset(seed=7 + i)
        np.testing.assert_array_equal(vobs[i], obs)
    rng = np.random.default_rng(3)
    for k in range(70):                       # crosses the truncation of the 60-step episodes
        act = rng.uniform(-1.2, 1.2, (3, 1)).astype(np.float32)
        vobs, vr, _, vtr, vinfo = venv.step(act)
        if k == 60:                           # NEXT_STEP autoreset: this step resets every sub-env
            for i, e in enumerate(envs):
                obs, _ = e.reset()
                np.testing.assert_array_equal(vobs[i], obs)
            continue
        for i, e in enumerate(envs):
            obs, r, _, _, info = e.step(act[i])
            np.testing.assert_array_equal(vobs[i], obs)
            assert vr[i] == r and vinfo["level"][i] == info["level"] and vinfo["stem"][i] == info["stem"]


def test_env_starts_from_the_plant_rest_state():
    cfg = make_config({"model": {"process_kind": "cascade", "cascade": {}}})
    env = ValveTankEnv(cfg)
    _, info = env.reset(seed=0)
    st = env._plant.state
    assert st.level[0] == cfg.model.process.level0 and st.level2[0] == cfg.model.cascade.level2_0
    assert info["level"] == cfg.model.cascade.level2_0
    assert info["u"] == core.steady_input(cfg.model, cfg.model.cascade.level2_0, 1)[0] == st.h[0]


def test_envs_run_a_friction_model_with_a_per_scan_law(he_model):
    """The plant applies a per-scan friction law (docs/examples/he_friction.py); both envs run it alike."""
    cfg = make_config({**SHORT, "model": {"slip_jump": {"law": "he", "S": 0.03, "J": 0.01}}})
    env, venv = ValveTankEnv(cfg), ValveTankVectorEnv(2, cfg)
    obs, _ = env.reset(seed=1)
    vobs, _ = venv.reset(seed=[1, 2])
    np.testing.assert_array_equal(obs, vobs[0])
    rng = np.random.default_rng(0)
    stems = []
    for _ in range(40):
        act = rng.uniform(-1, 1, (2, 1)).astype(np.float32)
        obs, r, _, _, info = env.step(act[0])
        vobs, vr, _, _, _ = venv.step(act)
        np.testing.assert_array_equal(obs, vobs[0])
        assert r == vr[0]
        stems.append(info["stem"])
    assert np.ptp(stems) > 0.01


def test_task_from_the_benchmark_config():
    import warnings

    from valve_gym.agents.bench.config import load_bench_config
    from valve_gym.config import ConfigError
    from valve_gym.envs import regulation
    from valve_gym.envs.regulation import RegulationTaskConfig

    bench = load_bench_config({"scan_s": 2.0, "models": ["kano"], "bands": {"sticky": {"n": 10}},
                               "regulation": {"levels": [0.8, 1.2], "noise_std": 0.001}})
    t = RegulationTaskConfig.from_benchmark(bench, episode_s=600.0)
    assert (t.levels, t.noise_std, t.load_std, t.load_tau) == ((0.8, 1.2), (0.001, 0.001), (1e-4, 1e-4), (120.0, 120.0))
    assert t.friction_models == ("kano",) and t.block.scan_s == 2.0 and t.steps == 300
    assert t.S_bands == (0.0, 0.005, 0.05, 0.1) and t.band_weights == (30.0, 10.0, 45.0)
    assert t.S_log_uniform == (False, True, False) and t.reward == "benchmark"
    gap = load_bench_config({"bands": {"severe": {"S": [0.06, 0.1]}}})
    with pytest.raises(ConfigError, match="not contiguous"):
        RegulationTaskConfig.from_benchmark(gap)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        assert regulation.RegulationConfig is RegulationTaskConfig      # the former name, deprecated
    assert any(issubclass(x.category, DeprecationWarning) for x in w)
