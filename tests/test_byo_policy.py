"""Bring your own policy: SB3 models, safe exports, converted zips and DCS blocks in the benchmark."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO, SAC, TD3  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import VecNormalize  # noqa: E402

import valve_gym  # noqa: E402,F401
from valve_gym.agents import load_controller  # noqa: E402
from valve_gym.agents.bench.policies import (  # noqa: E402
    PolicyBlock,
    PolicyShapeError,
    as_block,
    evaluate,
    export_policy,
    load_policy_block,
)
from valve_gym.agents.safe_files import UnsafeFileError, describe_file  # noqa: E402

pytestmark = pytest.mark.slow   # end-to-end runs of several seconds each: outside the fast subset

ROOT = Path(__file__).resolve().parents[1]
RID = "valve_gym/ValveTankRegulation-v0"
SHORT = {"config": {"episode_s": 60.0}}


def _venv(norm=True):
    v = make_vec_env(RID, n_envs=2, seed=0, env_kwargs=SHORT)
    return VecNormalize(v) if norm else v


def _model(cls, venv, steps=64):
    kw = {"n_steps": 32, "batch_size": 32} if cls is PPO else {"learning_starts": 16, "batch_size": 16}
    return cls("MlpPolicy", venv, seed=0, device="cpu", **kw).learn(steps)


@pytest.fixture(scope="module")
def trained():
    venv = _venv()
    return {cls.__name__: (_model(cls, venv), venv) for cls in (PPO, SAC, TD3)}


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["PPO", "SAC", "TD3"])
def test_model_in_memory_and_safe_export_act_as_sb3_predicts(trained, tmp_path, algo):
    model, venv = trained[algo]
    obs = venv.get_original_obs()
    want, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    blk = as_block(model)                         # the VecNormalize is found on the model's env
    assert isinstance(blk, PolicyBlock) and blk.normaliser is not None
    np.testing.assert_allclose(blk.act(obs), want, atol=1e-5)
    j = export_policy(model, tmp_path / algo.lower())
    assert describe_file(tmp_path / f"{algo.lower()}.safetensors") == "safetensors"
    loaded = load_policy_block(j)
    np.testing.assert_allclose(loaded.act(obs), want, atol=1e-5)
    assert loaded.meta["algorithm"] == algo.lower()


def test_block_runs_as_a_dcs_block_on_scalars_and_arrays(trained):
    blk = as_block(trained["SAC"][0])
    blk.reset(1.0, 1.0, 0.5)
    u = blk.step(1.0, 1.003)
    assert isinstance(u, float) and 0.0 <= u <= 1.0
    blk.reset(np.array([1.0, 0.8]), np.array([1.0, 0.8]), np.array([0.5, 0.4]))
    assert blk.step(np.array([1.0, 0.8]), np.array([1.001, 0.79])).shape == (2,)


@pytest.mark.slow
def test_sb3_zip_is_refused_in_one_line_and_converts_only_when_trusted(trained, tmp_path):
    model, venv = trained["SAC"]
    zpath = tmp_path / "sac.zip"
    model.save(zpath)
    with pytest.raises(UnsafeFileError, match="never unpickles.*convert-policy --trust-pickle"):
        as_block(str(zpath))
    vpath = tmp_path / "vecnormalize.pkl"
    venv.save(str(vpath))
    r = subprocess.run([sys.executable, "-m", "valve_gym.cli", "convert-policy", "--trust-pickle", str(zpath),
                        str(tmp_path / "conv"), "--vecnormalize", str(vpath)], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    obs = venv.get_original_obs()
    want, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(as_block(str(tmp_path / "conv.json")).act(obs), want, atol=1e-5)


def test_shape_mismatch_is_a_clear_error_before_any_loop(tmp_path):
    old = make_vec_env("valve_gym/ValveTank-v0", n_envs=1, seed=0)
    m = PPO("MlpPolicy", old, n_steps=16, batch_size=16, seed=0, device="cpu")
    with pytest.raises(PolicyShapeError, match="maps 4 observations to 1 actions.*ValveTank-v0"):
        as_block(m)
    v11 = make_vec_env(RID, n_envs=1, seed=0, env_kwargs={"config": {"episode_s": 60.0,
                                                                       "block": {"stick_features": False}}})
    m11 = PPO("MlpPolicy", v11, n_steps=16, batch_size=16, seed=0, device="cpu")
    with pytest.raises(PolicyShapeError, match="maps 11 observations"):
        as_block(m11, task={})                   # the default task's block gives 14
    with pytest.raises(PolicyShapeError, match="ValveTank-v0"):
        as_block(str(ROOT / "valve_gym" / "agents" / "policies" / "ppo.json"))


def test_cli_refuses_a_zip_and_a_wrong_shape_in_one_line_before_running(trained, tmp_path):
    zpath = tmp_path / "ppo.zip"
    trained["PPO"][0].save(zpath)
    for pol in (str(zpath), str(ROOT / "valve_gym" / "agents" / "policies" / "ppo.json")):
        r = subprocess.run([sys.executable, "-m", "valve_gym.cli", "benchmark", "--quick", "--out",
                            str(tmp_path / "out"), "--policy", pol], cwd=ROOT, capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 2
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("valve-gym benchmark: ") and "Traceback" not in r.stderr
        assert not (tmp_path / "out" / "results.md").exists()


@pytest.mark.slow
def test_evaluate_puts_policies_beside_the_classical_rows(trained, tmp_path):
    j = export_policy(trained["PPO"][0], tmp_path / "ppo")
    res = evaluate({"mine": [j, trained["TD3"][0]], "knock": load_controller("knocker", S=0.02)}, quick=True)
    labels = [s.label for s in res.specs]
    assert labels[:2] == ["PI frictionless", "PI (SIMC)"] and labels[-2:] == ["mine", "knock"]
    rows = {(r.controller, r.metric) for r in res.summary if r.part == "regulation" and r.band == "sticky+severe"}
    for metric in ("R", "iae_per_h", "travel_per_h", "lc_share", "travel_vs_frictionless"):
        assert ("mine", metric) in rows and ("PI (SIMC)", metric) in rows
    est = next(r.estimate for r in res.summary if r.controller == "mine" and r.metric == "R"
               and r.part == "regulation" and r.band == "sticky+severe")
    assert est.lo <= est.value <= est.hi and est.n > 0
    assert any(n.startswith("mine: per-loop medians over 2 seeds") for n in res.notes)


def _tiny_cfg(tmp_path, algo):
    cfg = {"algorithm": algo, "env_id": RID, "name": algo.upper(),
           "eval": {"every_steps": 10_000, "n_loops": 3, "seed": 5, "duration_s": 60},
           RID: {"n_timesteps": 96, "policy": "MlpPolicy", "n_envs": 2, "normalize": True,
                 "env_kwargs": {"config": {"episode_s": 60.0}}, "policy_kwargs": "dict(net_arch=[16, 16])"}}
    cfg[RID].update({"n_steps": 16, "batch_size": 16} if algo == "ppo" else {"learning_starts": 32,
                                                                            "batch_size": 16})
    p = tmp_path / f"{algo}.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_train_config_algorithm_is_understood_and_reproducible(tmp_path, algo):
    from safetensors.numpy import load_file

    from valve_gym.agents.train import main

    p = _tiny_cfg(tmp_path, algo)
    for d in ("a", "b"):
        assert main(["--config", str(p), "--seed", "3", "--out", str(tmp_path / d), "--no-progress"]) == 0
    wa = load_file(str(tmp_path / "a" / "policy.safetensors"))
    wb = load_file(str(tmp_path / "b" / "policy.safetensors"))
    assert wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)
    assert (tmp_path / "a" / "curve.csv").read_text().count("\n") >= 2


def test_unknown_key_in_a_baseline_config_is_named(tmp_path, capsys):
    from valve_gym.agents.train import main

    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump({"algorithm": "sac", "env_id": RID, RID: {"n_timesteps": 10, "n_stepz": 3}}))
    assert main(["--config", str(p)]) == 2
    assert "n_stepz" in capsys.readouterr().err


def test_shipped_baseline_policies_load_and_fit_the_registered_env():
    files = sorted((ROOT / "valve_gym" / "agents" / "policies" / "rl").glob("*.json"))
    assert len(files) == 15
    env = gym.make(RID)
    obs, _ = env.reset(seed=0)
    for f in files:
        blk = load_policy_block(f)
        a = blk.act(obs[None, :])
        assert a.shape == (1, 2) and np.all(np.abs(a) <= 1.0)


def test_a_folder_of_exports_is_the_seeds_of_one_row_and_names_pair_with_policies(trained, tmp_path):
    from valve_gym.agents.bench.policies import as_blocks

    folder = tmp_path / "my_sac"
    folder.mkdir()
    for i, algo in enumerate(("SAC", "TD3")):
        export_policy(trained[algo][0], folder / f"seed{i}")
    rows = as_blocks([str(folder), str(folder / "seed0.json")], names=[None, "single"])
    assert list(rows) == ["my_sac", "single"] and len(rows["my_sac"]) == 2 and len(rows["single"]) == 1
    with pytest.raises(FileNotFoundError, match="no policy files"):
        as_blocks([str(tmp_path / "nothing_here")] if (tmp_path / "nothing_here").mkdir() is None else [])
