"""``valve-gym train``: config loading, a PPO smoke run, atomic checkpoints and resume."""
import json
import zipfile

import numpy as np
import pytest
import yaml

from agents.ppo import POLICY_META_NAME, ObsTransform, TransformVecEnv, load_policy, read_policy_meta
from agents.train import load_train_config, make_vec_env
from valve_gym.cli import main as cli_main
from valve_gym.config import ConfigError

TINY = {
    "name": "tiny",
    "seed": 3,
    "total_timesteps": 512,
    "env": {"action_mode": "residual", "episode_seconds": 60.0},
    "obs": {"frame_stack": 2, "deltas": True},
    "ppo": {"n_envs": 4, "n_steps": 64, "batch_size": 128, "n_epochs": 2,
            "policy_kwargs": {"net_arch": [16, 16]}},
    "checkpoint": {"every_steps": 256, "keep": 2},
    "eval": {"every_steps": 256, "n_valves": 2, "heldout_n": 2},
}


@pytest.mark.parametrize("data,msg", [
    ({"ppo": {"n_stepz": 10}}, "ppo.n_stepz"),
    ({"ppo": {"learning_rate": "1e-3"}}, "ppo.learning_rate"),
    ({"ppo": {"policy_kwargs": {"net_arch": [64, "x"]}}}, "ppo.policy_kwargs.net_arch"),
    ({"env": {"model": {"valve": {"tua": 0.1}}}}, "env.model.valve.tua"),
    ({"obs": {"frame_stack": 0}}, "obs.frame_stack"),
    ({"ppo": {"n_envs": 3, "n_steps": 10, "batch_size": 7}}, "batch_size"),
    ({"vec_env": "gpu"}, "vec_env"),
])
def test_bad_config_names_key_path(data, msg):
    with pytest.raises(ConfigError, match=msg.replace(".", r"\.")):
        load_train_config(data)


def test_shipped_configs_load():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "configs"
    files = sorted(root.glob("ppo_*.yaml"))
    assert files
    for f in files:
        cfg = load_train_config(f)
        assert cfg.total_timesteps > 0


def test_transform_wrapper_handles_autoreset():
    cfg = load_train_config({**TINY, "env": {"episode_seconds": 3.0}})
    tf = ObsTransform(frame_stack=3, deltas=True)
    venv = TransformVecEnv(make_vec_env(cfg.env, 2, 0, "native"), tf)
    obs = venv.reset()
    assert obs.shape == (2, tf.out_dim(4)) and obs.dtype == np.float32
    for k in range(3):
        venv.step_async(np.zeros((2, 1), np.float32))
        obs, rew, done, infos = venv.step_wait()
    assert done.all()
    term = infos[0]["terminal_observation"]
    assert term.shape == (tf.out_dim(4),)
    # the new episode's stack starts fresh (deltas zero), the terminal one does not
    assert np.allclose(obs[:, -4:], 0.0)
    venv.close()


@pytest.mark.slow
def test_ppo_smoke_training_checkpoint_and_resume(tmp_path, capsys):
    cfg_path = tmp_path / "tiny.yaml"
    cfg_path.write_text(yaml.safe_dump(TINY))
    out = tmp_path / "run"
    rc = cli_main(["train", "--config", str(cfg_path), "--out", str(out), "--no-progress"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "training wall time" in printed and "IAE reduction vs PI" in printed
    for name in ("final.zip", "best.zip", "config.yaml", "eval.csv", "summary.json"):
        assert (out / name).exists(), name
    ckpts = sorted((out / "checkpoints").glob("ckpt_*.zip"))
    assert 1 <= len(ckpts) <= 2 and (out / "checkpoints" / "latest.zip").exists()
    assert not list(out.rglob(".tmp_*"))                        # atomic: no leftovers
    assert list((out / "tb").rglob("events.out.tfevents*"))     # TensorBoard logs
    meta = read_policy_meta(str(out / "final.zip"))
    assert meta["env_mode"] == "residual" and meta["obs_transform"]["frame_stack"] == 2
    assert meta["command"].startswith("valve-gym train --config") and meta["seed"] == 3
    with zipfile.ZipFile(out / "final.zip") as z:
        assert POLICY_META_NAME in z.namelist() and "policy.pth" in z.namelist()
    pol = load_policy(str(out / "final.zip"))
    a, s = pol.predict(np.array([[1.0, 1.1, 0.1, 0.5]] * 5, np.float32))
    assert a.shape == (5, 1) and np.all(np.abs(a) <= 1)
    s1 = json.loads((out / "summary.json").read_text())
    assert s1["total_timesteps"] >= 512
    # resume from the latest checkpoint up to 1024 steps
    rc = cli_main(["train", "--config", str(cfg_path), "--out", str(out), "--resume",
                   str(out / "checkpoints" / "latest.zip"), "--timesteps", "1024", "--no-progress",
                   "--no-final-eval"])
    assert rc == 0
    s2 = json.loads((out / "summary.json").read_text())
    assert s2["total_timesteps"] >= 1024 and s2["steps_this_run"] < 1024
    assert read_policy_meta(str(out / "final.zip"))["num_timesteps"] == s2["total_timesteps"]


def test_resume_rejects_other_transform(tmp_path):
    from stable_baselines3 import PPO

    from agents.train import build_training_env, policy_meta
    from agents.ppo import save_policy

    cfg = load_train_config(TINY)
    env = build_training_env(cfg, 0)
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, device="cpu")
    meta = policy_meta(cfg, model, "x", 0)
    meta["obs_transform"]["frame_stack"] = 5
    ck = save_policy(model, str(tmp_path / "c.zip"), meta)
    env.close()
    cfg_path = tmp_path / "tiny.yaml"
    cfg_path.write_text(yaml.safe_dump(TINY))
    assert cli_main(["train", "--config", str(cfg_path), "--out", str(tmp_path / "o"), "--resume", ck,
                     "--no-progress"]) == 2


def test_shipped_policy_matches_its_config():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    zips = sorted((root / "agents" / "policies").glob("*.zip"))
    for z in zips:
        meta = read_policy_meta(str(z))
        assert meta["command"].startswith("valve-gym train --config configs/")
        cfg_file = meta["command"].split("--config ")[1].split()[0]
        cfg = load_train_config(root / cfg_file)
        if "--seed" in meta["command"]:
            from dataclasses import replace

            cfg = replace(cfg, seed=int(meta["command"].split("--seed ")[1].split()[0]))
        assert load_train_config(meta["train_config"]) == cfg
        assert load_train_config(z.with_suffix(".yaml")) == cfg
