"""``valve_gym/ValveFamilyRegulation-v0``: the regulation task over the training family of ``learned``.

The env must draw exactly that family (one loop per episode, from ``reset(seed=...)`` alone), score the plain
PI at ``R = 0`` against its own references, rank the frictionless PI above the PI above a dithering relay on
sticky loops, and run its policies as DCS blocks on any loop given that loop's ``Kc``, ``Ti`` and scan.
"""
from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import valve_gym  # noqa: F401  (registers the ids)
from valve_gym.agents.adaptive_train import draw_loop
from valve_gym.envs.family_env import FAMILY_ID, FamilyConfig, ValveFamilyRegulationEnv

SHIPPED = Path(valve_gym.__file__).resolve().parent / "agents" / "policies" / "rl_family"
STEPS = FamilyConfig().steps


def _episode(env, seed: int, policy, free: bool = False) -> tuple[float, dict]:
    obs, _ = env.reset(seed=seed, options={"frictionless": free})
    G, info = 0.0, {}
    for _ in range(STEPS):
        obs, r, term, trunc, info = env.step(policy(env, obs))
        assert not term and np.isfinite(r)
        G += r
    assert trunc
    return G, info


def _pi(env, obs):
    return np.array([1.0, 0.0], np.float32)


def _relay(env, obs):
    """A 6 %-of-stroke relay on the error's sign on top of the PI: dithers the valve free, at a price in travel."""
    return np.array([1.0, 0.75 * np.sign(obs[0])], np.float32)


def test_checkers_pass():
    from gymnasium.utils.env_checker import check_env

    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(ValveFamilyRegulationEnv(), skip_render_check=True)
        sb3.check_env(gym.make(FAMILY_ID), warn=True)


def test_reset_seed_is_reproducible_and_draws_the_training_family():
    a, b = ValveFamilyRegulationEnv(), ValveFamilyRegulationEnv()
    oa, ia = a.reset(seed=11)
    ob, ib = b.reset(seed=11)
    np.testing.assert_array_equal(oa, ob)
    assert ia == ib
    rng = np.random.default_rng(1)
    for _ in range(50):
        act = rng.uniform(-1, 1, 2).astype(np.float32)
        sa, sb = a.step(act), b.step(act)
        np.testing.assert_array_equal(sa[0], sb[0])
        assert sa[1] == sb[1]
    # the episode is the loop draw_loop gives for the same generator (the family of learned)
    row, load, noise = draw_loop(np.random.default_rng(11), steps=STEPS + 1)
    assert (ia["kind"], ia["band"], ia["friction_model"]) == (row["kind"], row["band"], row["model"])
    assert (ia["S"], ia["Kc"], ia["Ti"], ia["scan_s"]) == (row["S"], row["Kc"], row["Ti"], row["scan"])
    assert row["model"] != "karnopp"
    kinds = {a.reset(seed=s)[1]["kind"] for s in range(12)}
    assert kinds == {"tank", "integrating", "first_order"}
    assert a.reset(seed=12)[1] != a.reset(seed=13)[1]


def test_observation_error_scale_is_the_loops_proportional_action():
    env = ValveFamilyRegulationEnv()
    env.reset(seed=3)
    ep = env._ep
    assert ep is not None
    assert ep.settings == FamilyConfig().block_for(ep.row["Kc"], ep.row["Ti"], ep.row["scan"])
    assert ep.settings.e_ref * ep.settings.Kc == pytest.approx(FamilyConfig().e_stroke)


def test_the_plain_pi_scores_zero_and_the_reward_ranks_as_the_benchmark():
    env = ValveFamilyRegulationEnv()
    seeds = [s for s in range(30) if env.reset(seed=s)[1]["band"] != "healthy"][:6]
    G = {k: [] for k in ("frictionless PI", "PI", "relay")}
    for s in seeds:
        g_pi, info = _episode(env, s, _pi)
        assert info["R"] == pytest.approx(0.0, abs=1e-9)
        G["PI"].append(g_pi)
        g0, info0 = _episode(env, s, _pi, free=True)
        refs = env._ep.refs                  # the frictionless PI is the reference: R = (IAE_PI - IAE_0) / D
        assert info0["R"] == pytest.approx(float((refs.iae_pi - refs.iae_0)[0] / refs.denom[0]), abs=1e-9)
        assert 0.0 < info0["R"] <= 1.0 + 1e-12
        G["frictionless PI"].append(g0)
        G["relay"].append(_episode(env, s, _relay)[0])
    m = {k: float(np.mean(v)) for k, v in G.items()}
    assert m["frictionless PI"] > m["PI"] > m["relay"], m
    assert all(a > b for a, b in zip(G["frictionless PI"], G["PI"]))


def test_bad_input_is_one_clear_error():
    env = ValveFamilyRegulationEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="frictionless"):
        env.reset(seed=0, options={"S": 0.03})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([np.nan, 0.0]))
    from valve_gym.config import ConfigError

    with pytest.raises(ConfigError, match="steps"):
        FamilyConfig(steps=3)


def _shipped() -> list[Path]:
    files = sorted(SHIPPED.glob("*.json"))
    return [f for f in files if json.loads(f.read_text()).get("format") == "valve_gym.sb3_block/1"]


def test_shipped_family_policies_load_safely_and_run_as_the_envs_block():
    from valve_gym.agents.bench.policies import PolicyBlock, load_policy_block

    files = _shipped()
    assert {f.stem for f in files} >= {"ppo_seed0", "ppo_seed1", "sac_seed0", "sac_seed1"}
    env = ValveFamilyRegulationEnv()
    for f in files:
        blk = load_policy_block(f)
        assert isinstance(blk, PolicyBlock) and blk.meta.get("e_stroke") == FamilyConfig().e_stroke
        obs, info = env.reset(seed=5)
        loop = blk.for_loop(info["Kc"], info["Ti"], info["scan_s"])
        assert loop.block_settings == FamilyConfig().block_for(info["Kc"], info["Ti"], info["scan_s"])
        ep = env._ep
        assert ep is not None
        loop.reset(ep.sp, ep.sp + ep.noise[0], ep.op0)
        pv = ep.sp + ep.noise[0]
        for _ in range(300):            # the DCS block on the env's plant: the env's outputs, step for step
            a = loop.act(obs[None, :])
            assert np.all(np.isfinite(a)) and np.all(np.abs(a) <= 1.0)
            u = loop.step(ep.sp, pv)
            obs, r, _, _, step_info = env.step(a[0].astype(np.float32))
            assert np.isfinite(r) and step_info["op"] == pytest.approx(float(np.ravel(u)[0]), abs=1e-6)
            pv = np.array([step_info["pv"]])


def test_policy_rows_reach_the_generalisation_part():
    from valve_gym.agents.bench.config import BenchConfig
    from valve_gym.agents.bench.generalisation import GenFamily, generalisation_markdown, run_generalisation
    from valve_gym.agents.bench.policies import load_policy_block

    files = _shipped()
    cfg = BenchConfig()
    cfg = replace(cfg, controllers=replace(cfg.controllers, compensators=("knocker",), detune=(), learned=False))
    fam = GenFamily(n_healthy=1, n_sticky=1, n_severe=1, duration_s=300.0)
    res = run_generalisation(cfg, fam, policies={"ppo family": load_policy_block(files[0])})
    assert "ppo family" in res.scores and "ppo family" in res.comparisons
    s = res.scores["ppo family"]
    assert np.all(np.isfinite(s.iae_per_h)) and np.all(np.isfinite(s.travel_per_h))
    assert "| ppo family |" in generalisation_markdown(res, cfg)


@pytest.mark.slow
def test_family_config_trains_reproducibly_and_exports_a_loop_scaled_policy(tmp_path):
    """``valve-gym train`` with the shipped family config (a few hundred steps): same seed, same weights."""
    pytest.importorskip("stable_baselines3")
    import yaml
    from safetensors.numpy import load_file

    from valve_gym.agents.bench.policies import load_policy_block
    from valve_gym.agents.train import main

    root = Path(__file__).resolve().parents[1]
    cfg = yaml.safe_load((root / "configs" / "rl" / "ppo_family.yaml").read_text())
    cfg["eval"] = {"every_steps": 256, "n_loops": 3, "seed": 900001, "duration_s": 300}
    cfg[FAMILY_ID].update(n_timesteps=256, n_envs=2, n_steps=64, batch_size=64, n_epochs=1)
    p = tmp_path / "ppo_family_tiny.yaml"
    p.write_text(yaml.safe_dump(cfg))
    for d in ("a", "b"):
        assert main(["--config", str(p), "--seed", "3", "--out", str(tmp_path / d), "--no-progress"]) == 0
    wa = load_file(str(tmp_path / "a" / "policy.safetensors"))
    wb = load_file(str(tmp_path / "b" / "policy.safetensors"))
    assert wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)
    blk = load_policy_block(tmp_path / "a" / "policy.json")
    assert blk.meta["e_stroke"] == FamilyConfig().e_stroke
    assert blk.for_loop(4.0, 30.0, 2.0).block_settings.e_ref == pytest.approx(FamilyConfig().e_stroke / 4.0)
