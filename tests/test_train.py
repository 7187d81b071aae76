"""``valve-gym train``: config loading, PPO and learned-compensator runs, safe checkpoints, lifecycle."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from valve_gym.agents.ppo import ObsTransform, TransformVecEnv, load_policy, read_policy_meta
from valve_gym.agents.train import load_train_config, make_vec_env
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


def _snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(folder.rglob("*"))
            if p.is_file()}


@pytest.mark.slow
def test_ppo_smoke_training_checkpoint_and_resume(tmp_path, capsys):
    cfg_path = tmp_path / "tiny.yaml"
    cfg_path.write_text(yaml.safe_dump(TINY))
    out = tmp_path / "run"
    rc = cli_main(["train", "--config", str(cfg_path), "--out", str(out), "--no-progress"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "training wall time" in printed and "IAE reduction vs PI" in printed
    for name in ("final.json", "final.safetensors", "best.json", "best.safetensors", "config.yaml", "eval.csv",
                 "summary.json"):
        assert (out / name).exists(), name
    assert not list(out.rglob("*.zip")) and not list(out.rglob("*.pkl"))
    ckpts = sorted((out / "checkpoints").glob("ckpt_*.json"))
    assert 1 <= len(ckpts) <= 2 and (out / "checkpoints" / "latest.safetensors").exists()
    assert not list(out.rglob(".*.tmp"))                        # atomic: no leftovers
    assert list((out / "tb").rglob("events.out.tfevents*"))     # TensorBoard logs
    meta = read_policy_meta(str(out / "final.json"))
    assert meta["env_mode"] == "residual" and meta["obs_transform"]["frame_stack"] == 2
    assert meta["command"].startswith("valve-gym train --config") and meta["seed"] == 3
    pol = load_policy(str(out / "final.json"))
    a, s = pol.predict(np.array([[1.0, 1.1, 0.1, 0.5]] * 5, np.float32))
    assert a.shape == (5, 1) and np.all(np.abs(a) <= 1)
    s1 = json.loads((out / "summary.json").read_text())
    assert s1["total_timesteps"] >= 512
    # non-empty --out without --resume/--overwrite: refused, nothing touched
    before = _snapshot(out)
    assert cli_main(["train", "--config", str(cfg_path), "--out", str(out), "--no-progress"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert _snapshot(out) == before
    # resuming the finished run: exit 0, says so, changes nothing
    assert cli_main(["train", "--config", str(cfg_path), "--out", str(out), "--resume", "--no-progress"]) == 0
    assert "already finished" in capsys.readouterr().out
    assert _snapshot(out) == before
    # resume from the latest checkpoint up to 1024 steps
    rc = cli_main(["train", "--config", str(cfg_path), "--out", str(out), "--resume", "--timesteps", "1024",
                   "--no-progress", "--no-final-eval"])
    assert rc == 0
    s2 = json.loads((out / "summary.json").read_text())
    assert s2["total_timesteps"] >= 1024 and s2["steps_this_run"] < 1024
    assert read_policy_meta(str(out / "final.json"))["num_timesteps"] == s2["total_timesteps"]


def test_model_without_tensorboard_folder_makes_no_log_folder(tmp_path, monkeypatch):
    import tempfile

    from valve_gym.agents.train import build_training_env, make_model

    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    cfg = load_train_config(TINY)
    env = build_training_env(cfg, 0)
    model = make_model(cfg, env, 0)
    model.learn(64)
    env.close()
    assert model.num_timesteps >= 64
    assert [p.name for p in scratch.iterdir() if p.name.startswith("SB3-")] == []


def test_ppo_checkpoint_restores_optimiser_and_rng(tmp_path):
    import torch

    from valve_gym.agents.train import (
        build_training_env,
        load_ppo_checkpoint,
        make_model,
        policy_meta,
        save_ppo_checkpoint,
    )

    cfg = load_train_config(TINY)
    env = build_training_env(cfg, 0)
    model = make_model(cfg, env, 0)
    model.learn(256)
    save_ppo_checkpoint(model, env, tmp_path / "ck", policy_meta(cfg, model, "x", 0))
    r1 = (torch.rand(3), np.random.rand(3))
    model2 = make_model(cfg, env, 1)
    load_ppo_checkpoint(model2, env, tmp_path / "ck.json")
    r2 = (torch.rand(3), np.random.rand(3))
    assert torch.equal(r1[0], r2[0]) and np.array_equal(r1[1], r2[1])
    assert model2.num_timesteps == model.num_timesteps
    for (k, v), v2 in zip(model.policy.state_dict().items(), model2.policy.state_dict().values()):
        assert torch.equal(v, v2), k
    o1, o2 = model.policy.optimizer.state_dict(), model2.policy.optimizer.state_dict()
    for pid in o1["state"]:
        for k in o1["state"][pid]:
            assert torch.equal(o1["state"][pid][k], o2["state"][pid][k])
    env.close()


def test_resume_rejects_other_transform(tmp_path):
    from valve_gym.agents.train import build_training_env, make_model, policy_meta, save_ppo_checkpoint

    cfg = load_train_config(TINY)
    env = build_training_env(cfg, 0)
    model = make_model(cfg, env, 0)
    meta = policy_meta(cfg, model, "x", 0)
    meta["obs_transform"]["frame_stack"] = 5
    ck = save_ppo_checkpoint(model, env, tmp_path / "c", meta)
    env.close()
    cfg_path = tmp_path / "tiny.yaml"
    cfg_path.write_text(yaml.safe_dump(TINY))
    assert cli_main(["train", "--config", str(cfg_path), "--out", str(tmp_path / "o"), "--resume", ck,
                     "--no-progress"]) == 2


def test_shipped_policy_matches_its_config():
    root = Path(__file__).resolve().parents[1]
    meta = read_policy_meta(str(root / "valve_gym" / "agents" / "policies" / "ppo.json"))
    assert meta["command"].startswith("valve-gym train --config configs/")
    cfg_file = meta["command"].split("--config ")[1].split()[0]
    cfg = load_train_config(root / cfg_file)
    if "--seed" in meta["command"]:
        from dataclasses import replace

        cfg = replace(cfg, seed=int(meta["command"].split("--seed ")[1].split()[0]))
    assert load_train_config(meta["train_config"]) == cfg
    assert load_train_config(root / "valve_gym" / "agents" / "policies" / "ppo.yaml") == cfg


# ----------------------------------------------------------------- the learned compensator (ES)
ES_TINY = {"algorithm": "es", "name": "tiny_es", "seed": 5, "checkpoint_every": 1,
           "task": {"episode_s": 60.0},
           "es": {"generations": 4, "pairs": 2, "scenarios": 3, "hidden": [8], "episode_s": 40.0},
           "eval": {"every": 2, "n_loops": 3}}


def _es_cfg(tmp_path, **over) -> Path:
    d = json.loads(json.dumps(ES_TINY))
    for k, v in over.items():
        d[k].update(v) if isinstance(v, dict) else d.__setitem__(k, v)
    p = tmp_path / "es.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_es_resumed_run_equals_uninterrupted(tmp_path, capsys):
    from valve_gym.agents.safe_files import load_model_file

    cfg = _es_cfg(tmp_path)
    a, b = tmp_path / "a", tmp_path / "b"
    assert cli_main(["train", "--config", str(cfg), "--out", str(a), "--no-progress"]) == 0
    assert cli_main(["train", "--config", str(cfg), "--out", str(b), "--generations", "2", "--no-progress"]) == 0
    assert cli_main(["train", "--config", str(cfg), "--out", str(b), "--resume", "--no-progress"]) == 0
    ta = load_model_file(a / "checkpoints" / "latest.json")
    tb = load_model_file(b / "checkpoints" / "latest.json")
    for k in ("theta", "adam_m", "adam_v", "best_theta", "obs_mean", "obs_std"):
        assert np.array_equal(ta.tensors[k], tb.tensors[k]), k
    assert ta.meta["rng_state"] == tb.meta["rng_state"] and ta.meta["gen"] == tb.meta["gen"] == 4
    assert [r["train_fitness_center"] for r in ta.meta["curve"]] == [r["train_fitness_center"]
                                                                     for r in tb.meta["curve"]]
    # the trained block loads without torch and runs as a DCS block
    from valve_gym.agents.learned import load_learned

    blk = load_learned(a)
    blk.reset(1.0, 1.0, 0.5)
    assert 0.0 <= blk.step(1.0, 1.01) <= 1.0
    # resuming the finished run: exit 0, says so, nothing changes
    before = _snapshot(a)
    capsys.readouterr()
    assert cli_main(["train", "--config", str(cfg), "--out", str(a), "--resume", "--no-progress"]) == 0
    assert "already finished" in capsys.readouterr().out
    assert _snapshot(a) == before


def test_out_folder_rules(tmp_path, capsys):
    cfg = _es_cfg(tmp_path, es={"generations": 1})
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert cli_main(["train", "--config", str(cfg), "--out", str(out), "--no-progress"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert cli_main(["train", "--config", str(cfg), "--out", str(out), "--overwrite", "--no-progress"]) == 2
    assert "notes.txt" in capsys.readouterr().err and (out / "notes.txt").read_text() == "mine"
    (out / "notes.txt").unlink()
    (out / "best.json").write_text("{}")                         # a stale file of an earlier run
    assert cli_main(["train", "--config", str(cfg), "--out", str(out), "--overwrite", "--no-progress"]) == 0
    assert json.loads((out / "best.json").read_text())["format"] == "valve_gym.learned_block/1"
    assert cli_main(["train", "--config", str(cfg), "--out", str(out), "--resume", "--overwrite"]) == 2
    assert cli_main(["train", "--config", str(cfg), "--out", str(tmp_path / "new"), "--resume"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    # a run that failed before its first checkpoint leaves only its config: nothing to resume, so the same
    # command starts it again (it used to be refused as "not empty" with --resume impossible)
    failed = tmp_path / "failed"
    (failed / "checkpoints").mkdir(parents=True)
    (failed / "config.yaml").write_text("name: failed\n")
    assert cli_main(["train", "--config", str(cfg), "--out", str(failed), "--no-progress"]) == 0
    assert (failed / "best.json").is_file() and "name: failed" not in (failed / "config.yaml").read_text()
    (failed / "notes.txt").write_text("mine")                    # anything more is still a run's folder
    assert cli_main(["train", "--config", str(cfg), "--out", str(failed), "--no-progress"]) == 2
    assert "not empty" in capsys.readouterr().err


def test_sigterm_writes_checkpoint_and_exits_cleanly(tmp_path):
    root = Path(__file__).resolve().parents[1]
    cfg = _es_cfg(tmp_path, es={"generations": 10_000})
    out = tmp_path / "sig"
    p = subprocess.Popen([sys.executable, "-m", "valve_gym.agents.train", "--config", str(cfg), "--out", str(out)],
                         cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ck = out / "checkpoints" / "latest.json"
    for _ in range(600):                                          # wait for the first generation
        if ck.exists() or p.poll() is not None:
            break
        time.sleep(0.1)
    assert ck.exists()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 1 and "Traceback" not in err
    assert "interrupted" in err and "--resume" in err
    gen = json.loads(ck.read_text())["gen"]
    assert gen >= 1 and not json.loads(ck.read_text())["finished"]
    # it continues from there
    assert cli_main(["train", "--config", str(cfg), "--out", str(out), "--resume", "--generations", str(gen + 1),
                     "--no-progress"]) == 0
    assert json.loads(ck.read_text())["gen"] == gen + 1


def test_learned_config_errors(tmp_path):
    from valve_gym.agents.es import load_learned_train_config

    for data, key in (({"es": {"pairz": 3}}, "es.pairz"), ({"task": {"friction_models": ["nope"]}}, "nope"),
                      ({"task": {"block": {"g_min": 0.0}}}, "g_min"), ({"es": {"sigma": "1e-2"}}, "es.sigma")):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            load_learned_train_config({"algorithm": "es", **data})
    bad = tmp_path / "bad.yaml"
    bad.write_text("algorithm: es\nes: {pairz: 3}\n")
    r = subprocess.run([sys.executable, "-m", "valve_gym.agents.train", "--config", str(bad)], capture_output=True,
                       text=True,
                       cwd=Path(__file__).resolve().parents[1], env={**os.environ})
    assert r.returncode == 2 and "es.pairz" in r.stderr and "Traceback" not in r.stderr


def test_es_fitness_terms_and_reversal_count():
    from valve_gym.agents.bench.scores import valve_motion
    from valve_gym.agents.es import ESHyper, RolloutScores, centered_ranks, fitness

    x = np.array([[0.0, 0.0], [0.05, 0.005], [0.02, -0.004], [0.06, 0.003], [0.01, 0.0]])
    assert valve_motion(x, 0.01)[1].tolist() == [3, 0]          # moves under the dead band do not count
    S = np.array([0.001, 0.03])                                # one healthy, one sticky loop
    ref_iae, ref_rev, ref_lc = np.array([1.0, 2.0]), np.array([10.0, 10.0]), np.array([0.0, 1.0])

    def sc(iae, rev, lc, travel=(0.0, 0.0)):
        return RolloutScores(np.array([iae]), np.array([travel]), np.array([rev]), np.array([lc]),
                             np.zeros(11), np.ones(11), S)

    h = ESHyper(travel_penalty=0.0, reversal_weight=0.0, lc_weight=0.0)
    base = fitness(sc([1.0, 2.0], [10, 10], [0, 1]), ref_iae, ref_rev, h, 1.0, ref_lc=ref_lc)[0]
    assert base == pytest.approx(0.0)
    # better than PI on the healthy valve earns nothing; on the sticky one it does
    assert fitness(sc([0.5, 2.0], [10, 10], [0, 1]), ref_iae, ref_rev, h, 1.0)[0] == pytest.approx(0.0)
    assert fitness(sc([1.0, 1.0], [10, 10], [0, 1]), ref_iae, ref_rev, h, 1.0)[0] == pytest.approx(np.log(2) / 2)
    h2 = ESHyper(travel_penalty=0.0, reversal_weight=0.0, lc_weight=1.0)
    assert fitness(sc([1.0, 2.0], [10, 10], [1, 0]), ref_iae, ref_rev, h2, 1.0, ref_lc=ref_lc)[0] \
        == pytest.approx(0.5)                                  # the healthy loop's detection does not count
    h3 = ESHyper(travel_penalty=0.0, reversal_weight=1.0)
    assert fitness(sc([1.0, 2.0], [10, 21], [0, 1]), ref_iae, ref_rev, h3, 1.0)[0] == pytest.approx(-np.log(2) / 2)
    assert centered_ranks(np.array([3.0, 1.0, 2.0])).tolist() == [0.5, -0.5, 0.0]


def test_flags_of_the_other_trainer_are_refused(tmp_path, capsys):
    cfg = _es_cfg(tmp_path)
    for extra in (["--timesteps", "10"], ["--vec-env", "dummy"], ["--no-final-eval"]):
        assert cli_main(["train", "--config", str(cfg), "--out", str(tmp_path / "x")] + extra) == 2
        assert "PPO" in capsys.readouterr().err
    ppo = tmp_path / "tiny.yaml"
    ppo.write_text(yaml.safe_dump(TINY))
    assert cli_main(["train", "--config", str(ppo), "--out", str(tmp_path / "y"), "--generations", "3"]) == 2
    assert "--timesteps" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_es_scores_the_measured_level_with_the_benchmarks_iae():
    """The trainer's IAE is the benchmark's loop score (bench.scores.loop_iae) of SP - PV measured."""
    from valve_gym.agents.bench.scores import loop_iae
    from valve_gym.agents.es import rollout_scores
    from valve_gym.envs.regulation import RegulationTaskConfig, pi_action
    from valve_gym.envs.regulation_env import ValveTankRegulationVectorEnv

    task = RegulationTaskConfig(episode_s=120.0, noise_std=(0.003, 0.003), reward="tracking")
    seeds = [3, 4]
    sc = rollout_scores([None], task, seeds)
    env = ValveTankRegulationVectorEnv(2, task)
    env.reset(seed=seeds)
    e, lv = np.empty((task.steps, 2)), np.empty((task.steps, 2))
    for k in range(task.steps):
        _, _, _, _, inf = env.step(pi_action(2))
        fin = inf.get("final_info", inf)
        e[k], lv[k] = fin["setpoint"] - fin["pv"], fin["level"]
    np.testing.assert_array_equal(sc.iae[0], loop_iae(e, task.block.scan_s))
    assert not np.allclose(sc.iae[0], np.abs(fin["setpoint"] - lv).sum(0) * task.block.scan_s)   # not the true level


def test_es_rollouts_on_the_runner_equal_the_regulation_env():
    """The ES trainer rolls its networks out with the closed-loop runner; the loops, the block law and so the
    scores are those of the regulation vector env driven step by step with the same networks."""
    from dataclasses import replace

    from valve_gym.agents.bench.scores import loop_iae, valve_motion
    from valve_gym.agents.es import rollout_scores
    from valve_gym.agents.learned import load_learned, mlp_forward, normalise
    from valve_gym.envs.regulation import N_ACT, RegulationTaskConfig, pi_action
    from valve_gym.envs.regulation_env import ValveTankRegulationVectorEnv

    blk = load_learned()
    task = replace(RegulationTaskConfig(), episode_s=300.0)
    seeds = [5, 11]
    sc = rollout_scores([None, blk.weights], task, seeds, (blk.obs_mean, blk.obs_std))
    env = ValveTankRegulationVectorEnv(4, task)
    obs, _ = env.reset(seed=seeds + seeds)
    err, stem = np.empty((task.steps, 4)), np.empty((task.steps, 4))
    for k in range(task.steps):
        act = np.tile(pi_action(1), (4, 1))
        act[2:] = mlp_forward(blk.weights, normalise(obs[2:].astype(np.float64), blk.obs_mean, blk.obs_std))
        obs, _, _, _, inf = env.step(act.reshape(4, N_ACT))
        fin = inf["final_info"] if "final_info" in inf else inf
        err[k], stem[k] = fin["setpoint"] - fin["pv"], fin["stem"]
    iae = loop_iae(err, task.block.scan_s).reshape(2, 2)
    travel, rev = valve_motion(stem, 0.0005)
    np.testing.assert_array_equal(sc.iae, iae)
    np.testing.assert_array_equal(sc.travel, travel.reshape(2, 2))
    np.testing.assert_array_equal(sc.reversals, rev.reshape(2, 2))
    assert not np.array_equal(sc.iae[0], sc.iae[1])            # the network is not the PI
