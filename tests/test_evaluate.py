"""evaluate(): one batched rollout per controller, same scenario for every controller."""
import numpy as np
import pytest

from valve_gym.agents import BlockPolicy, load_controller
from valve_gym.agents.evaluate import Rollout, env_config_for, evaluate, make_eval_env, rollout


def pi_policy(**kw):
    """The PI block with SB3's ``predict``."""
    return BlockPolicy(load_controller("pi", **kw))


def knocker_policy(**kw):
    return BlockPolicy(load_controller("knocker", **kw))


VALVES = {"z_max": [0.005, 0.2, 0.8], "e_dead": [0.0, 0.01, 0.03]}
SHORT = {"episode_seconds": 120.0}


def test_evaluate_three_valves():
    df, ro = evaluate(pi_policy(), VALVES, env_config=SHORT, seed=[5, 6, 7], return_rollout=True)
    assert list(df["valve"]) == [0, 1, 2]
    assert np.allclose(df["z_max"], VALVES["z_max"]) and np.allclose(df["e_dead"], VALVES["e_dead"])
    for col in ("iae", "ise", "error_std", "lc_present", "lc_amplitude", "lc_period", "valve_travel",
                "valve_reversals_per_hour", "op_travel", "op_reversals_per_hour", "return"):
        assert col in df.columns
        assert np.all(np.isfinite(df[col]) | (col == "lc_period"))
    assert isinstance(ro, Rollout)
    assert ro.level.shape == (120, 3) and ro.t.shape == (120,) and ro.dt == 1.0
    # the score is the env's own: IAE on the true level, return = sum of rewards
    e = ro.setpoint - ro.level
    assert df["iae"].to_numpy() == pytest.approx(np.abs(e).sum(0))
    assert df["return"].to_numpy() == pytest.approx(ro.reward.sum(0))


def test_same_scenario_for_every_controller_and_deterministic():
    a, ra = evaluate(pi_policy(), VALVES, env_config=SHORT, seed=11, return_rollout=True)
    b, rb = evaluate(knocker_policy(), VALVES, env_config=SHORT, seed=11, return_rollout=True)
    c, rc = evaluate(pi_policy(), VALVES, env_config=SHORT, seed=11, return_rollout=True)
    assert np.array_equal(ra.setpoint, rb.setpoint) and np.array_equal(ra.load, rb.load)
    assert np.array_equal(ra.level, rc.level) and a.equals(c)
    assert not np.array_equal(ra.u, rb.u)        # the knocker pulses


def test_pi_in_direct_mode_equals_env_residual_with_zero_action():
    """Our PI wrapper and the env's built-in PI are the same law (valve_gym.control)."""

    class Zero:
        env_mode = "residual"
        name = "zero"
        env_overrides = {"pi": {"Kc": 1.5, "Ti": 30.0}}

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return np.zeros((len(obs), 1), np.float32), None

    _, r1 = evaluate(pi_policy(Kc=1.5, Ti=30.0), VALVES, env_config=SHORT, seed=3, return_rollout=True)
    _, r2 = evaluate(Zero(), VALVES, env_config=SHORT, seed=3, return_rollout=True)
    assert np.allclose(r1.u, r2.u, atol=1e-6) and np.allclose(r1.level, r2.level, atol=1e-6)


def test_env_config_for_applies_controller_settings():
    class Res:
        env_mode = "residual"
        env_overrides = {"residual_scale": 0.25, "measure_stem": True}

    cfg = env_config_for(Res(), SHORT)
    assert cfg.action_mode == "residual" and cfg.residual_scale == 0.25 and cfg.measure_stem
    assert cfg.episode_seconds == 120.0
    assert env_config_for(pi_policy()).action_mode == "direct"


def test_rollout_batches_predict_over_all_valves():
    calls = []

    class Spy(BlockPolicy):
        def __init__(self):
            super().__init__(load_controller("pi"))

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            calls.append(obs.shape)
            return super().predict(obs, state, episode_start, deterministic)

    env = make_eval_env(Spy(), 3, SHORT)
    rollout(Spy(), env, seeds=0, valves=VALVES)
    assert len(calls) == 120 and set(calls) == {(3, 4)}


def test_bad_input():
    with pytest.raises(ValueError, match="unknown valve parameter"):
        evaluate(pi_policy(), {"zmax": [0.1]})
    with pytest.raises(ValueError, match="one length"):
        evaluate(pi_policy(), {"z_max": [0.1, 0.2], "e_dead": [0.0]})
    with pytest.raises(ValueError, match="give the valves"):
        evaluate(pi_policy())
