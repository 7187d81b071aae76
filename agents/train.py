"""Train a PPO policy from a YAML config: ``valve-gym train``.

``valve-gym train --config configs/ppo_shipped.yaml [--out DIR] [--resume CKPT]
[--timesteps N] [--seed S] [--vec-env native|dummy|subproc] [--no-progress]``

The config (see :class:`TrainConfig`; ``configs/ppo_shipped.yaml`` made the
shipped direct policy, ``configs/ppo_residual.yaml`` is a residual one)
holds rl-zoo style PPO hyperparameters (``ppo``: ``n_envs``, ``n_steps``,
``batch_size``, ``gamma``, ``gae_lambda``, ``learning_rate``, ``ent_coef``,
``policy_kwargs.net_arch``, ...), ``total_timesteps``, environment overrides
(``env``: any key of :class:`valve_gym.config.EnvConfig`), the observation
wrappers (``obs``: frame stacking, deltas; :class:`agents.ppo.ObsTransform`),
checkpointing and evaluation settings. Unknown keys and mistyped values are
errors that name the key path.

The training environment is the native vector env
(:class:`valve_gym.envs.ValveTankVectorEnv`, all ``n_envs`` loops in one
kernel call) through the SB3 adapter, wrapped by SB3's ``VecMonitor`` (episode
statistics) and :class:`agents.ppo.TransformVecEnv`.

Written to ``--out`` (default ``runs/<name>``):

``final.zip``
    The policy at the end of training (SB3 zip with the observation
    transform and environment settings embedded; load with
    :func:`agents.ppo.load_policy`).
``best.zip``
    The policy with the best mean return on the validation valves.
``checkpoints/ckpt_<steps>.zip``, ``checkpoints/latest.zip``
    Periodic checkpoints (written to a temporary file, then renamed with
    :func:`os.replace`), for ``--resume``.
``tb/``
    TensorBoard logs (``tensorboard --logdir DIR/tb``).
``config.yaml``, ``eval.csv``, ``summary.json``
    The exact config, the held-out evaluation per valve, wall time and scores.

Evaluation: every ``eval.every_steps`` the policy runs on validation valves
drawn from the training range (``best.zip`` is chosen by their mean return);
at the end ``final.zip`` and ``best.zip`` are compared with PI on those and on
*held-out* valves outside the training range (``eval.heldout_z_max``,
``eval.heldout_e_dead``).
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import shlex
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Optional, Tuple

import numpy as np

from valve_gym.config import read_yaml, ConfigError, EnvConfig, config_to_dict, load_config

from .ppo import ObsTransform, read_policy_meta, save_policy

__all__ = ["TrainConfig", "PPOHyper", "PolicyKwargs", "ObsConfig", "CheckpointConfig", "EvalConfig",
           "load_train_config", "make_vec_env", "train", "main", "ENV_OVERRIDE_KEYS"]

Range = Tuple[float, float]

#: Environment settings a policy needs wherever it is evaluated (stored in its zip).
ENV_OVERRIDE_KEYS = ("action_mode", "residual_scale", "pi", "measure_stem", "control_period")


# --------------------------------------------------------------------------- config
@dataclass(frozen=True)
class PolicyKwargs:
    """``policy_kwargs`` of SB3's ``MlpPolicy``.

    Parameters
    ----------
    net_arch : list of int
        Hidden layer sizes, shared by the actor and the critic (separate networks).
    activation_fn : {'tanh', 'relu'}
    log_std_init : float
        Initial log standard deviation of the Gaussian action noise.
    ortho_init : bool
    """

    net_arch: Tuple[int, ...] = (64, 64)
    activation_fn: str = "tanh"
    log_std_init: float = -0.5
    ortho_init: bool = True

    def __post_init__(self):
        if self.activation_fn not in ("tanh", "relu"):
            raise ConfigError(f"activation_fn must be 'tanh' or 'relu', got {self.activation_fn!r}")


@dataclass(frozen=True)
class PPOHyper:
    """PPO hyperparameters (names as in stable-baselines3 / rl-zoo).

    ``learning_rate`` and ``clip_range`` decay linearly to 0 over training
    when ``lr_schedule`` is ``'linear'``. ``normalize_reward`` divides the
    training rewards by a running estimate of the standard deviation of the
    discounted return (SB3's ``VecNormalize(norm_obs=False)``; training only,
    the policy's inputs are not affected).
    """

    n_envs: int = 16
    n_steps: int = 256
    batch_size: int = 256
    n_epochs: int = 10
    gamma: float = 0.98
    gae_lambda: float = 0.95
    learning_rate: float = 3.0e-4
    lr_schedule: str = "constant"
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float = 0.0
    normalize_advantage: bool = True
    normalize_reward: bool = False
    policy_kwargs: PolicyKwargs = field(default_factory=PolicyKwargs)

    def __post_init__(self):
        for name in ("n_envs", "n_steps", "batch_size", "n_epochs"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        if not 0 < self.gamma <= 1:
            raise ConfigError(f"gamma must be in (0, 1], got {self.gamma!r}")
        if not 0 <= self.gae_lambda <= 1:
            raise ConfigError(f"gae_lambda must be in [0, 1], got {self.gae_lambda!r}")
        if not self.learning_rate > 0:
            raise ConfigError(f"learning_rate must be > 0, got {self.learning_rate!r}")
        if self.lr_schedule not in ("constant", "linear"):
            raise ConfigError(f"lr_schedule must be 'constant' or 'linear', got {self.lr_schedule!r}")
        for name in ("clip_range", "ent_coef", "vf_coef", "max_grad_norm", "target_kl"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if (self.n_envs * self.n_steps) % self.batch_size:
            raise ConfigError(
                f"batch_size = {self.batch_size} should divide n_envs * n_steps = "
                f"{self.n_envs * self.n_steps} (the rollout size) so that no samples are dropped")


@dataclass(frozen=True)
class ObsConfig:
    """Observation wrappers (see :class:`agents.ppo.ObsTransform`)."""

    frame_stack: int = 1
    deltas: bool = False

    def __post_init__(self):
        if self.frame_stack < 1:
            raise ConfigError(f"frame_stack must be >= 1, got {self.frame_stack!r}")


@dataclass(frozen=True)
class CheckpointConfig:
    """Periodic checkpoints: every ``every_steps`` env steps, keeping the last ``keep``."""

    every_steps: int = 100_000
    keep: int = 3

    def __post_init__(self):
        if self.every_steps < 1 or self.keep < 1:
            raise ConfigError("every_steps and keep must be >= 1")


@dataclass(frozen=True)
class EvalConfig:
    """Evaluation settings.

    Parameters
    ----------
    every_steps : int
        Validation period in env steps (0 = only at the end).
    n_valves : int
        Validation valves (drawn by the env's randomisation, i.e. the training range).
    seed : int
        Seed of the validation and held-out episodes (kept away from the
        training seeds and the benchmark's).
    heldout_n : int
        Held-out valves at the end.
    heldout_z_max, heldout_e_dead : (2,) ranges
        Friction of the held-out valves (outside the training range).
    """

    every_steps: int = 100_000
    n_valves: int = 32
    seed: int = 900_000
    heldout_n: int = 32
    heldout_z_max: Range = (0.5, 1.5)
    heldout_e_dead: Range = (0.02, 0.04)

    def __post_init__(self):
        if self.every_steps < 0 or self.n_valves < 1 or self.heldout_n < 0:
            raise ConfigError("every_steps >= 0, n_valves >= 1 and heldout_n >= 0 are required")
        if not (0 < self.heldout_z_max[0] <= self.heldout_z_max[1]):
            raise ConfigError(f"heldout_z_max must be [low, high] with 0 < low <= high, got "
                              f"{list(self.heldout_z_max)!r}")
        if not (0 <= self.heldout_e_dead[0] <= self.heldout_e_dead[1] <= 0.5):
            raise ConfigError(f"heldout_e_dead must be [low, high] within [0, 0.5], got "
                              f"{list(self.heldout_e_dead)!r}")


@dataclass(frozen=True)
class TrainConfig:
    """A training run (YAML: ``configs/ppo_*.yaml``).

    Parameters
    ----------
    name : str
        Policy name (label in the benchmark; default output folder ``runs/<name>``).
    seed : int
        Seed of PPO's networks and of the training environments.
    total_timesteps : int
        Environment steps of training.
    vec_env : {'native', 'dummy', 'subproc'}
        Vectorisation: the native vector env through the SB3 adapter (default),
        or SB3's DummyVecEnv / SubprocVecEnv over single envs.
    env : EnvConfig
        The training task (keys of :class:`valve_gym.config.EnvConfig`; the
        valve is drawn by ``env.randomise`` each episode).
    obs : ObsConfig
    ppo : PPOHyper
    checkpoint : CheckpointConfig
    eval : EvalConfig
    """

    name: str = "ppo"
    seed: int = 0
    total_timesteps: int = 1_000_000
    vec_env: str = "native"
    env: EnvConfig = field(default_factory=EnvConfig)
    obs: ObsConfig = field(default_factory=ObsConfig)
    ppo: PPOHyper = field(default_factory=PPOHyper)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)

    def __post_init__(self):
        if self.total_timesteps < 1:
            raise ConfigError(f"total_timesteps must be >= 1, got {self.total_timesteps!r}")
        if self.vec_env not in ("native", "dummy", "subproc"):
            raise ConfigError(f"vec_env must be 'native', 'dummy' or 'subproc', got {self.vec_env!r}")
        if not self.name or any(c in self.name for c in "/\\ "):
            raise ConfigError(f"name must be a non-empty word without slashes or spaces, got {self.name!r}")


def load_train_config(path_or_dict) -> TrainConfig:
    """Load a :class:`TrainConfig` from a YAML file or mapping.

    Raises
    ------
    valve_gym.config.ConfigError
        Naming the key path of an unknown key, a string where a number
        belongs, or a value out of range (e.g. ``ppo.n_stepz``).

    Examples
    --------
    >>> cfg = load_train_config({"ppo": {"policy_kwargs": {"net_arch": [32, 32, 32]}},
    ...                          "env": {"action_mode": "residual"}})
    >>> cfg.ppo.policy_kwargs.net_arch, cfg.env.action_mode
    ((32, 32, 32), 'residual')
    >>> load_train_config({"ppo": {"n_stepz": 10}})
    Traceback (most recent call last):
    ...
    valve_gym.config.ConfigError: unknown key 'ppo.n_stepz' (did you mean 'n_steps'?); the keys of 'ppo' are: n_envs, n_steps, batch_size, n_epochs, gamma, gae_lambda, learning_rate, lr_schedule, clip_range, ent_coef, vf_coef, max_grad_norm, target_kl, normalize_advantage, normalize_reward, policy_kwargs
    """
    src = ""
    if isinstance(path_or_dict, (str, os.PathLike)):
        p = Path(path_or_dict)
        data = read_yaml(p, "training config")
        src = f" in {p}"
    else:
        data = path_or_dict or {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"a training config must be a mapping{src}, got {type(data).__name__}")
    data = copy.deepcopy(dict(data))
    # net_arch is a variable-length list: validated here, the rest by the loader
    net_arch = None
    ppo = data.get("ppo")
    if isinstance(ppo, Mapping) and isinstance(ppo.get("policy_kwargs"), Mapping) \
            and "net_arch" in ppo["policy_kwargs"]:
        ppo = dict(ppo)
        pk = dict(ppo["policy_kwargs"])
        net_arch = pk.pop("net_arch")
        ppo["policy_kwargs"] = pk
        data["ppo"] = ppo
        if not (isinstance(net_arch, (list, tuple)) and len(net_arch) > 0
                and all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in net_arch)):
            raise ConfigError(f"ppo.policy_kwargs.net_arch must be a non-empty list of positive "
                              f"integers (layer sizes), got {net_arch!r}{src}")
    try:
        cfg = load_config(data, cls=TrainConfig, base=TrainConfig())
    except ConfigError as exc:
        raise ConfigError(f"{exc}{src}") from None
    if net_arch is not None:
        cfg = replace(cfg, ppo=replace(cfg.ppo, policy_kwargs=replace(cfg.ppo.policy_kwargs,
                                                                      net_arch=tuple(net_arch))))
    return cfg


def train_config_to_dict(cfg: TrainConfig) -> dict:
    d = config_to_dict(cfg)
    d["ppo"]["policy_kwargs"]["net_arch"] = list(cfg.ppo.policy_kwargs.net_arch)
    return d


def env_overrides(cfg: TrainConfig) -> dict:
    """The environment settings stored with the policy (see :data:`ENV_OVERRIDE_KEYS`)."""
    d = config_to_dict(cfg.env)
    return {k: d[k] for k in ENV_OVERRIDE_KEYS}


def obs_transform(cfg: TrainConfig) -> ObsTransform:
    return ObsTransform(frame_stack=cfg.obs.frame_stack, deltas=cfg.obs.deltas)


# --------------------------------------------------------------------------- envs
def make_vec_env(env_cfg: EnvConfig, n_envs: int, seed: int, kind: str = "native"):
    """An SB3 ``VecEnv`` of ``n_envs`` training loops.

    Parameters
    ----------
    env_cfg : EnvConfig
    n_envs : int
    seed : int, sub-env ``i`` is seeded with ``seed + i``
    kind : {'native', 'dummy', 'subproc'}
        ``native``: :class:`valve_gym.envs.ValveTankVectorEnv` through the SB3
        adapter :class:`valve_gym.envs.sb3.SB3VecEnv`; ``dummy`` /
        ``subproc``: SB3's DummyVecEnv / SubprocVecEnv over single
        ``ValveTankEnv`` made with ``gymnasium.make`` (with its time limit).
    """
    if kind == "native":
        from valve_gym.envs.sb3 import SB3VecEnv

        venv = SB3VecEnv(num_envs=n_envs, config=env_cfg)
        venv.seed(seed)
        return venv
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    import valve_gym.envs  # noqa: F401  (registration)
    from valve_gym.envs import register_envs

    register_envs()
    fns = [_EnvFactory(env_cfg) for _ in range(n_envs)]
    if kind == "dummy":
        venv = DummyVecEnv(fns)
    elif kind == "subproc":
        venv = SubprocVecEnv(fns, start_method="fork")
    else:
        raise ValueError(f"vec_env must be 'native', 'dummy' or 'subproc', got {kind!r}")
    venv.seed(seed)
    return venv


class _EnvFactory:
    """Picklable ``gymnasium.make`` of one training env (for SubprocVecEnv)."""

    def __init__(self, env_cfg: EnvConfig):
        self.env_cfg = env_cfg

    def __call__(self):
        import gymnasium as gym

        from valve_gym.envs import register_envs

        register_envs()
        return gym.make("valve_gym/ValveTank-v0", config=self.env_cfg,
                        max_episode_steps=self.env_cfg.episode_steps)


def build_training_env(cfg: TrainConfig, seed: int, kind: Optional[str] = None):
    """Vec env + VecMonitor + observation transform, as used by :func:`train`."""
    from stable_baselines3.common.vec_env import VecMonitor

    from .ppo import TransformVecEnv

    venv = make_vec_env(cfg.env, cfg.ppo.n_envs, seed, kind or cfg.vec_env)
    venv = TransformVecEnv(VecMonitor(venv), obs_transform(cfg))
    if cfg.ppo.normalize_reward:
        from stable_baselines3.common.vec_env import VecNormalize

        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=cfg.ppo.gamma)
    return venv


# --------------------------------------------------------------------------- training
class _LinearSchedule:
    """``progress_remaining -> value * progress_remaining`` (picklable, for SB3)."""

    def __init__(self, value: float):
        self.value = float(value)

    def __call__(self, progress_remaining: float) -> float:
        return self.value * progress_remaining

    def __repr__(self) -> str:
        return f"linear({self.value:g})"


def _policy_kwargs(pk: PolicyKwargs) -> dict:
    import torch

    act = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[pk.activation_fn]
    net = list(pk.net_arch)
    return {"net_arch": {"pi": net, "vf": list(net)}, "activation_fn": act,
            "log_std_init": float(pk.log_std_init), "ortho_init": bool(pk.ortho_init)}


def make_model(cfg: TrainConfig, env, seed: int, tb_dir: Optional[str] = None):
    """A fresh SB3 PPO model for ``cfg`` on ``env``."""
    from stable_baselines3 import PPO

    h = cfg.ppo
    lr = _LinearSchedule(h.learning_rate) if h.lr_schedule == "linear" else h.learning_rate
    clip = _LinearSchedule(h.clip_range) if h.lr_schedule == "linear" else h.clip_range
    return PPO("MlpPolicy", env, learning_rate=lr, n_steps=h.n_steps, batch_size=h.batch_size,
               n_epochs=h.n_epochs, gamma=h.gamma, gae_lambda=h.gae_lambda, clip_range=clip,
               ent_coef=h.ent_coef, vf_coef=h.vf_coef, max_grad_norm=h.max_grad_norm,
               target_kl=h.target_kl or None, normalize_advantage=h.normalize_advantage,
               policy_kwargs=_policy_kwargs(h.policy_kwargs), tensorboard_log=tb_dir, seed=seed,
               device="cpu", verbose=0)


def policy_meta(cfg: TrainConfig, model, command: str, seed: int, wall_s: float = None) -> dict:
    """Metadata embedded in every policy zip of a run."""
    import stable_baselines3

    return {"name": cfg.name, "env_mode": cfg.env.action_mode, "env_overrides": env_overrides(cfg),
            "obs_transform": obs_transform(cfg).to_dict(), "train_config": train_config_to_dict(cfg),
            "command": command, "seed": seed, "num_timesteps": int(model.num_timesteps),
            "wall_time_s": wall_s, "sb3_version": stable_baselines3.__version__}


def _controller(cfg: TrainConfig, model, name=None):
    from .ppo import PPOController

    return PPOController(model, transform=obs_transform(cfg), env_mode=cfg.env.action_mode,
                         env_overrides=env_overrides(cfg), name=name or cfg.name)


def validation_valves(cfg: TrainConfig):
    """``(valves, seeds)`` of the validation set: drawn by the env, seeds ``eval.seed + i``."""
    n = cfg.eval.n_valves
    return None, [cfg.eval.seed + i for i in range(n)]


def heldout_valves(cfg: TrainConfig):
    """``(valves, seeds)`` of the held-out set: friction outside the training range."""
    e = cfg.eval
    n = e.heldout_n
    rng = np.random.default_rng(e.seed + 7)
    lo, hi = e.heldout_z_max
    z = lo * np.exp(rng.random(n) * np.log(hi / lo)) if hi > lo else np.full(n, lo)
    ed = e.heldout_e_dead[0] + rng.random(n) * (e.heldout_e_dead[1] - e.heldout_e_dead[0])
    seeds = [e.seed + 10_000 + i for i in range(n)]
    return {"z_max": z, "e_dead": ed}, seeds


def _score(ctrl, cfg: TrainConfig, valves, seeds):
    from .evaluate import evaluate

    return evaluate(ctrl, valves=valves, n=len(seeds), env_config=cfg.env, seed=seeds)


def _compare(df, ref):
    """Paired scores of ``df`` against ``ref`` (same valves)."""
    r_iae = df["iae"].to_numpy() / np.maximum(ref["iae"].to_numpy(), 1e-12)
    r_tr = df["valve_travel"].to_numpy() / np.maximum(ref["valve_travel"].to_numpy(), 1e-12)
    return {"mean_return": float(df["return"].mean()), "median_iae": float(df["iae"].median()),
            "iae_reduction_vs_pi": float(1.0 - np.median(r_iae)),
            "travel_ratio_vs_pi": float(np.median(r_tr))}


def _callbacks(cfg: TrainConfig, out: Path, command: str, seed: int):
    from stable_baselines3.common.callbacks import BaseCallback

    ckpt_dir = out / "checkpoints"

    class Checkpoint(BaseCallback):
        """Atomic periodic checkpoints (tmp file + os.replace), keeping the last ``keep``."""

        def __init__(self):
            super().__init__()
            self.last = 0
            self.saved = []

        def _on_training_start(self):
            self.last = self.model.num_timesteps

        def _on_step(self) -> bool:
            if self.model.num_timesteps - self.last >= cfg.checkpoint.every_steps:
                self.save()
            return True

        def save(self):
            self.last = self.model.num_timesteps
            meta = policy_meta(cfg, self.model, command, seed)
            p = save_policy(self.model, str(ckpt_dir / f"ckpt_{self.model.num_timesteps:09d}.zip"), meta)
            save_policy(self.model, str(ckpt_dir / "latest.zip"), meta)
            if p not in self.saved:
                self.saved.append(p)
            while len(self.saved) > cfg.checkpoint.keep:
                old = self.saved.pop(0)
                if os.path.exists(old):
                    os.unlink(old)

    class Validate(BaseCallback):
        """Validation on drawn valves; keeps ``best.zip`` by mean return."""

        def __init__(self):
            super().__init__()
            self.last = 0
            self.best = -np.inf
            self.history = []
            self.valves, self.seeds = validation_valves(cfg)

        def _on_training_start(self):
            self.last = self.model.num_timesteps

        def _on_step(self) -> bool:
            if cfg.eval.every_steps and self.model.num_timesteps - self.last >= cfg.eval.every_steps:
                self.run()
            return True

        def run(self):
            self.last = self.model.num_timesteps
            df = _score(_controller(cfg, self.model), cfg, self.valves, self.seeds)
            ret = float(df["return"].mean())
            self.history.append({"timesteps": int(self.model.num_timesteps), "mean_return": ret,
                                 "median_iae": float(df["iae"].median()),
                                 "median_valve_travel": float(df["valve_travel"].median())})
            self.logger.record("eval/mean_return", ret)
            self.logger.record("eval/median_iae", float(df["iae"].median()))
            self.logger.record("eval/median_valve_travel", float(df["valve_travel"].median()))
            if ret > self.best:
                self.best = ret
                save_policy(self.model, str(out / "best.zip"),
                            policy_meta(cfg, self.model, command, seed))

    return Checkpoint(), Validate()


def train(cfg: TrainConfig, out: Path, resume: Optional[str] = None, seed: Optional[int] = None,
          timesteps: Optional[int] = None, progress: bool = True, command: str = "",
          vec_env: Optional[str] = None, final_eval: bool = True) -> dict:
    """Train (or resume) a PPO policy; returns the run summary (also in ``summary.json``).

    Parameters
    ----------
    cfg : TrainConfig
    out : Path, output folder
    resume : str, optional, checkpoint zip to continue from (its observation
        transform and action mode must match ``cfg``)
    seed : int, optional, overrides ``cfg.seed``
    timesteps : int, optional, overrides ``cfg.total_timesteps`` (total, counting
        the steps already in a resumed checkpoint)
    progress : bool, show SB3's progress bar
    command : str, the command line, stored in the policy files
    vec_env : str, optional, overrides ``cfg.vec_env``
    final_eval : bool, compare final/best policy with PI at the end
    """
    import torch
    import yaml
    from stable_baselines3.common.callbacks import CallbackList

    torch.set_num_threads(1)
    if seed is not None:
        cfg = replace(cfg, seed=int(seed))
    if timesteps is not None:
        if timesteps < 1:
            raise ValueError(f"--timesteps must be >= 1, got {timesteps}")
        cfg = replace(cfg, total_timesteps=int(timesteps))
    if vec_env is not None:
        cfg = replace(cfg, vec_env=vec_env)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from .benchmark import _atomic_write_text

    _atomic_write_text(out / "config.yaml", yaml.safe_dump(train_config_to_dict(cfg), sort_keys=False))
    t0 = time.perf_counter()
    env = build_training_env(cfg, cfg.seed)
    tb_dir = str(out / "tb")
    if resume:
        from stable_baselines3 import PPO

        meta = read_policy_meta(resume)
        want = obs_transform(cfg).to_dict()
        if meta and (meta.get("obs_transform") != want or meta.get("env_mode") != cfg.env.action_mode):
            raise ValueError(
                f"checkpoint {resume} was trained with obs_transform={meta.get('obs_transform')} and "
                f"env_mode={meta.get('env_mode')!r}, but the config asks for {want} and "
                f"{cfg.env.action_mode!r}; resume with the config of that run")
        model = PPO.load(resume, env=env, device="cpu", tensorboard_log=tb_dir)
        done = int(model.num_timesteps)
        print(f"resuming from {resume} at {done} steps")
    else:
        model = make_model(cfg, env, cfg.seed, tb_dir)
        done = 0
    remaining = cfg.total_timesteps - done
    ckpt, val = _callbacks(cfg, out, command, cfg.seed)
    t_learn = time.perf_counter()
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=CallbackList([ckpt, val]), tb_log_name=cfg.name,
                    reset_num_timesteps=not resume, progress_bar=progress)
    learn_s = time.perf_counter() - t_learn
    steps = int(model.num_timesteps) - done
    if cfg.eval.every_steps:
        val.run()                      # the final policy competes for best.zip too
    wall_train = time.perf_counter() - t0
    meta = policy_meta(cfg, model, command, cfg.seed, wall_s=wall_train)
    final_path = save_policy(model, str(out / "final.zip"), meta)
    ckpt.save()
    if not (out / "best.zip").exists():
        save_policy(model, str(out / "best.zip"), meta)
    env.close()
    summary = {"name": cfg.name, "command": command, "seed": cfg.seed,
               "total_timesteps": int(model.num_timesteps), "steps_this_run": steps,
               "learn_seconds": learn_s, "env_steps_per_second": steps / learn_s if learn_s > 0 else None,
               "train_wall_seconds": wall_train, "validation_history": val.history,
               "final": str(final_path), "best": str(out / "best.zip")}
    if final_eval:
        summary.update(_final_eval(cfg, out, model))
    summary["wall_seconds"] = time.perf_counter() - t0
    _atomic_write_text(out / "summary.json", json.dumps(summary, indent=1, default=str))
    return summary


def _final_eval(cfg: TrainConfig, out: Path, model) -> dict:
    """Final and best policy against PI on validation and held-out valves (``eval.csv``)."""
    import pandas as pd

    from .pi import PIController
    from .ppo import load_policy

    from .benchmark import _atomic_write_text

    sets = {"validation": validation_valves(cfg)}
    if cfg.eval.heldout_n > 0:
        sets["heldout"] = heldout_valves(cfg)
    ctrls = {"pi": PIController(Ts=cfg.env.control_period), "final": _controller(cfg, model, "final"),
             "best": load_policy(str(out / "best.zip"), name="best")}
    frames, res = [], {}
    for sname, (valves, seeds) in sets.items():
        dfs = {}
        for cname, c in ctrls.items():
            df = _score(c, cfg, valves, seeds)
            df.insert(0, "controller", cname)
            df.insert(0, "set", sname)
            dfs[cname] = df
            frames.append(df)
        for cname in ("final", "best"):
            res[f"{sname}_{cname}"] = _compare(dfs[cname], dfs["pi"])
        res[f"{sname}_pi"] = {"mean_return": float(dfs["pi"]["return"].mean()),
                              "median_iae": float(dfs["pi"]["iae"].median())}
    _atomic_write_text(out / "eval.csv", pd.concat(frames, ignore_index=True).to_csv(index=False))
    return {"eval": res}


# --------------------------------------------------------------------------- CLI
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="valve-gym train",
                                description="Train a PPO policy (stable-baselines3) from a YAML config.")
    p.add_argument("--config", required=True, help="training YAML, e.g. configs/ppo_shipped.yaml")
    p.add_argument("--out", default=None, help="output folder (default: runs/<name>)")
    p.add_argument("--resume", default=None, metavar="CKPT", help="checkpoint .zip to continue from")
    p.add_argument("--timesteps", type=int, default=None, help="override total_timesteps")
    p.add_argument("--seed", type=int, default=None, help="override the seed")
    p.add_argument("--vec-env", choices=("native", "dummy", "subproc"), default=None,
                   help="override the vectorisation (default from the config: native)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-final-eval", action="store_true", help="skip the comparison with PI at the end")
    return p


def _print_summary(s: dict) -> None:
    print(f"\n{s['name']}: {s['total_timesteps']} steps; learning {s['learn_seconds']:.1f} s "
          f"({(s['env_steps_per_second'] or 0):.0f} env-steps/s); training wall time "
          f"{s['train_wall_seconds']:.1f} s ({s['train_wall_seconds'] / 60:.2f} min); total "
          f"{s['wall_seconds']:.1f} s")
    ev = s.get("eval", {})
    if ev:
        print("\n| set | policy | mean return | median IAE [m s] | IAE reduction vs PI | valve travel vs PI |")
        print("|---|---|---|---|---|---|")
        for key, v in ev.items():
            sname, cname = key.rsplit("_", 1)
            red = v.get("iae_reduction_vs_pi")
            tr = v.get("travel_ratio_vs_pi")
            print(f"| {sname} | {cname} | {v['mean_return']:.1f} | {v['median_iae']:.2f} | "
                  f"{'' if red is None else f'{100 * red:+.1f} %'} | {'' if tr is None else f'{tr:.2f}x'} |")
    print(f"\npolicy: {s['final']} (best on validation: {s['best']})")


def main(argv=None) -> int:
    """``valve-gym train``."""
    args = _parser().parse_args(argv)
    try:
        cfg = load_train_config(args.config)
    except ConfigError as exc:
        print(f"valve-gym train: bad config: {exc}", file=sys.stderr)
        return 2
    if args.resume and not os.path.isfile(args.resume):
        print(f"valve-gym train: checkpoint not found: {args.resume}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path("runs") / cfg.name
    argv_list = list(sys.argv[1:] if argv is None else argv)
    command = "valve-gym train " + " ".join(shlex.quote(a) for a in argv_list)
    try:
        s = train(cfg, out, resume=args.resume, seed=args.seed, timesteps=args.timesteps,
                  progress=not args.no_progress, command=command, vec_env=args.vec_env,
                  final_eval=not args.no_final_eval)
    except ValueError as exc:
        print(f"valve-gym train: {exc}", file=sys.stderr)
        return 2
    _print_summary(s)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
