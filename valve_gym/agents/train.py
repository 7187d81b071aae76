"""Train a policy from a YAML config: ``valve-gym train``.

``valve-gym train --config CONFIG [--out DIR] [--resume [CKPT] | --overwrite] [--seed S]
[--generations N | --timesteps N] [--vec-env native|dummy|subproc] [--no-progress]``

Two kinds of config:

* ``configs/learned.yaml`` (``algorithm: es``): the learned stiction compensator, trained by
  evolution strategies on the regulation task (:mod:`valve_gym.agents.es`, :mod:`valve_gym.agents.learned`). Writes
  ``best.{safetensors,json}`` (best on validation; load with :func:`valve_gym.agents.learned.load_learned`),
  ``final.*``, ``curve.csv`` (learning curve), ``checkpoints/latest.*``, ``config.yaml``,
  ``summary.json``.
* ``configs/ppo_*.yaml`` (:class:`TrainConfig`): a PPO policy (stable-baselines3) on
  ``valve_gym/ValveTank-v0``. Writes ``final.*`` and ``best.*`` (``.safetensors`` + ``.json``;
  load with :func:`valve_gym.agents.ppo.load_policy`), ``checkpoints/ckpt_<steps>.*`` and
  ``checkpoints/latest.*`` (model, optimiser, reward normaliser, RNG states, step count),
  ``tb/``, ``config.yaml``, ``eval.csv``, ``summary.json``.

Every file is safetensors weights plus JSON, written atomically; nothing is pickled.

Lifecycle: a non-empty ``--out`` is refused unless ``--resume`` (continue from
``checkpoints/latest``, or from a given checkpoint) or ``--overwrite`` (delete the previous run's
files; files a run does not write are never deleted). Resuming a finished run says so, exits 0
and changes nothing. SIGINT/SIGTERM write a checkpoint of the last completed step and exit 1;
``--resume`` continues. The learned compensator's resumed run equals the uninterrupted one bit for
bit (checkpoints at generation boundaries); a resumed PPO run restores the model, optimiser,
normaliser, RNG states and step count, and its environments start new episodes. Exit codes:
0 done (or already done), 1 the work failed or was interrupted, 2 bad usage.

PPO evaluation: every ``eval.every_steps`` the policy runs on validation valves drawn from the
training range (``best`` is chosen by their mean return); at the end ``final`` and ``best`` are
compared with PI on those and on *held-out* valves outside the training range
(``eval.heldout_z_max``, ``eval.heldout_e_dead``).
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import shlex
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from valve_gym.config import MAX_NUM_ENVS, ConfigError, EnvConfig, check_count, config_to_dict, load_config, read_yaml

from .learned import MAX_LAYER
from .ppo import ObsTransform

__all__ = ["TrainConfig", "PPOHyper", "PolicyKwargs", "ObsConfig", "CheckpointConfig", "EvalConfig",
           "load_train_config", "make_vec_env", "train", "main", "ENV_OVERRIDE_KEYS"]

Range = tuple[float, float]

#: Environment settings a policy needs wherever it is evaluated (stored in its JSON).
ENV_OVERRIDE_KEYS = ("action_mode", "residual_scale", "pi", "measure_stem", "control_period")

#: What to do about an empty training config (it has no defaults to fall back on).
_TRAIN_EMPTY_HINT = "start from a shipped config, e.g. configs/learned.yaml or configs/ppo_residual.yaml"


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

    net_arch: tuple[int, ...] = (64, 64)
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
        check_count("ppo.n_envs", self.n_envs, MAX_NUM_ENVS, "each environment holds its own plant and episode arrays")
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
    """Observation wrappers (see :class:`valve_gym.agents.ppo.ObsTransform`)."""

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
    >>> load_train_config({"ppo": {"n_stepz": 10}})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    valve_gym.config.ConfigError: unknown key 'ppo.n_stepz' (did you mean 'n_steps'?); the keys of 'ppo' are: ...
    """
    src = ""
    if isinstance(path_or_dict, (str, os.PathLike)):
        p = Path(path_or_dict)
        data = read_yaml(p, "training config", empty_hint=_TRAIN_EMPTY_HINT)
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
                and all(isinstance(x, int) and not isinstance(x, bool) and 0 < x <= MAX_LAYER for x in net_arch)):
            raise ConfigError(f"ppo.policy_kwargs.net_arch must be a non-empty list of layer sizes from 1 to "
                              f"{MAX_LAYER}, got {net_arch!r}{src}")
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


def build_training_env(cfg: TrainConfig, seed: int, kind: str | None = None):
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


def make_model(cfg: TrainConfig, env, seed: int, tb_dir: str | None = None):
    """A fresh SB3 PPO model for ``cfg`` on ``env``.

    ``tb_dir``: where its TensorBoard logs go; without one the model logs nowhere (SB3's own default
    would make an empty ``SB3-<time>`` folder in the system's temporary folder on every ``learn``).
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    h = cfg.ppo
    lr = _LinearSchedule(h.learning_rate) if h.lr_schedule == "linear" else h.learning_rate
    clip = _LinearSchedule(h.clip_range) if h.lr_schedule == "linear" else h.clip_range
    model = PPO("MlpPolicy", env, learning_rate=lr, n_steps=h.n_steps, batch_size=h.batch_size,
               n_epochs=h.n_epochs, gamma=h.gamma, gae_lambda=h.gae_lambda, clip_range=clip,
               ent_coef=h.ent_coef, vf_coef=h.vf_coef, max_grad_norm=h.max_grad_norm,
               target_kl=h.target_kl or None, normalize_advantage=h.normalize_advantage,
               policy_kwargs=_policy_kwargs(h.policy_kwargs), tensorboard_log=tb_dir, seed=seed,
               device="cpu", verbose=0)
    if tb_dir is None:
        model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def policy_meta(cfg: TrainConfig, model, command: str, seed: int, wall_s: float | None = None) -> dict:
    """Metadata stored in the JSON of every policy file of a run."""
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
    import pandas as pd

    from .evaluate import evaluate

    df = evaluate(ctrl, valves=valves, n=len(seeds), env_config=cfg.env, seed=seeds)
    assert isinstance(df, pd.DataFrame)
    return df


def _compare(df, ref):
    """Paired scores of ``df`` against ``ref`` (same valves)."""
    r_iae = df["iae"].to_numpy() / np.maximum(ref["iae"].to_numpy(), 1e-12)
    r_tr = df["valve_travel"].to_numpy() / np.maximum(ref["valve_travel"].to_numpy(), 1e-12)
    return {"mean_return": float(df["return"].mean()), "median_iae": float(df["iae"].median()),
            "iae_reduction_vs_pi": float(1.0 - np.median(r_iae)),
            "travel_ratio_vs_pi": float(np.median(r_tr))}


CKPT_FORMAT = "valve_gym.ppo_checkpoint/1"


def _vecnormalize(venv):
    from stable_baselines3.common.vec_env import VecNormalize

    v = venv
    while v is not None:
        if isinstance(v, VecNormalize):
            return v
        v = getattr(v, "venv", None)
    return None


def save_ppo_checkpoint(model, venv, path, meta: dict, finished: bool = False) -> str:
    """Write everything a resume needs as ``path.safetensors`` + ``path.json`` (no pickle).

    Weights of the policy, Adam's moment estimates and step counts, the reward normaliser's
    running statistics (``VecNormalize``), the RNG states of torch, numpy's global generator
    (SB3's minibatch order) and Python's ``random``, the step and update counts.
    """
    import random

    import torch

    from .ppo import policy_tensors
    from .safe_files import save_model_file

    t = {f"policy/{k}": v for k, v in policy_tensors(model).items()}
    opt = model.policy.optimizer.state_dict()
    for pid, st in opt["state"].items():
        for k, v in st.items():
            t[f"optim/{pid}/{k}"] = v.detach().cpu().numpy() if torch.is_tensor(v) else np.asarray(v)
    t["rng/torch"] = torch.get_rng_state().numpy()
    nps: tuple = tuple(np.random.get_state(legacy=True))
    t["rng/numpy_keys"] = np.asarray(nps[1], dtype=np.uint32)
    pys = random.getstate()
    t["rng/python"] = np.asarray(pys[1], dtype=np.uint64)
    norm = _vecnormalize(venv)
    if norm is not None:
        t["norm/ret_mean"] = np.asarray(norm.ret_rms.mean, float)
        t["norm/ret_var"] = np.asarray(norm.ret_rms.var, float)
        t["norm/returns"] = np.asarray(norm.returns, float)
    groups = [{k: (v if isinstance(v, (int, float, bool, str, list)) or v is None else
                   (list(v) if isinstance(v, tuple) else None)) for k, v in g.items()} for g in opt["param_groups"]]
    j = {**meta, "format": CKPT_FORMAT, "num_timesteps": int(model.num_timesteps), "n_updates": int(model._n_updates),
         "optim_param_groups": groups, "rng_numpy": [nps[0], int(nps[2]), int(nps[3]), float(nps[4])],
         "rng_python": [pys[0], pys[2]], "norm_count": float(norm.ret_rms.count) if norm is not None else None,
         "finished": bool(finished)}
    return save_model_file(path, t, j)[1]


def load_ppo_checkpoint(model, venv, path) -> dict:
    """Restore a checkpoint of :func:`save_ppo_checkpoint` into ``model``/``venv``; returns its JSON."""
    import random

    import torch

    from .safe_files import load_model_file

    mf = load_model_file(path)
    j, t = mf.meta, mf.tensors
    if j.get("format") != CKPT_FORMAT:
        raise ValueError(f"{path} is not a PPO training checkpoint (format {j.get('format')!r})")
    sd = {k[len("policy/"):]: torch.from_numpy(v.copy()) for k, v in t.items() if k.startswith("policy/")}
    model.policy.load_state_dict(sd)
    state: dict = {}
    for k, v in t.items():
        if k.startswith("optim/"):
            _, pid, name = k.split("/", 2)
            state.setdefault(int(pid), {})[name] = torch.from_numpy(v.copy())
    model.policy.optimizer.load_state_dict({"state": state, "param_groups": j["optim_param_groups"]})
    torch.set_rng_state(torch.from_numpy(t["rng/torch"].copy()))
    a, pos, hg, cg = j["rng_numpy"]
    np.random.set_state((a, t["rng/numpy_keys"], pos, hg, cg))
    random.setstate((j["rng_python"][0], tuple(int(x) for x in t["rng/python"]), j["rng_python"][1]))
    norm = _vecnormalize(venv)
    if norm is not None and "norm/ret_mean" in t:
        norm.ret_rms.mean, norm.ret_rms.var = t["norm/ret_mean"], t["norm/ret_var"]
        norm.ret_rms.count = j["norm_count"]
    model.num_timesteps = int(j["num_timesteps"])
    model._n_updates = int(j["n_updates"])
    return j


def _callbacks(cfg: TrainConfig, out: Path, command: str, seed: int, venv):
    """The checkpoint (and stop-on-signal) callback and the validation callback of a PPO run."""
    return _checkpoint_callback(cfg, out, command, seed, venv), _validate_callback(cfg, out, command, seed)


def _checkpoint_callback(cfg: TrainConfig, out: Path, command: str, seed: int, venv):
    from stable_baselines3.common.callbacks import BaseCallback

    from .lifecycle import STOP

    ckpt_dir = out / "checkpoints"

    class Checkpoint(BaseCallback):
        """Atomic periodic checkpoints (safetensors + JSON), keeping the last ``keep``; stops on SIGINT/SIGTERM."""

        def __init__(self):
            super().__init__()
            self.last = 0
            self.saved: list = []

        def _on_training_start(self):
            self.last = self.model.num_timesteps

        def _on_step(self) -> bool:
            if STOP["flag"]:
                return False
            if self.model.num_timesteps - self.last >= cfg.checkpoint.every_steps:
                self.save()
            return True

        def save(self, finished: bool = False):
            self.last = self.model.num_timesteps
            meta = policy_meta(cfg, self.model, command, seed)
            stem = ckpt_dir / f"ckpt_{self.model.num_timesteps:09d}"
            save_ppo_checkpoint(self.model, venv, stem, meta, finished)
            save_ppo_checkpoint(self.model, venv, ckpt_dir / "latest", meta, finished)
            if stem not in self.saved:
                self.saved.append(stem)
            while len(self.saved) > cfg.checkpoint.keep:
                old = self.saved.pop(0)
                for ext in (".json", ".safetensors"):
                    if old.with_suffix(ext).exists():
                        old.with_suffix(ext).unlink()

    return Checkpoint()


def _validate_callback(cfg: TrainConfig, out: Path, command: str, seed: int):
    from stable_baselines3.common.callbacks import BaseCallback

    from .ppo import save_policy

    class Validate(BaseCallback):
        """Validation on drawn valves; keeps ``best`` by mean return."""

        def __init__(self):
            super().__init__()
            self.last = 0
            self.best = -np.inf
            self.history: list = []
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
            ret = float(df["return"].to_numpy().mean())
            self.history.append({"timesteps": int(self.model.num_timesteps), "mean_return": ret,
                                 "median_iae": float(np.median(df["iae"].to_numpy())),
                                 "median_valve_travel": float(np.median(df["valve_travel"].to_numpy()))})
            self.logger.record("eval/mean_return", ret)
            if ret > self.best:
                self.best = ret
                save_policy(self.model, str(out / "best"), policy_meta(cfg, self.model, command, seed))

    return Validate()


def _write_text(path: Path, text: str) -> None:
    from valve_gym._io import write_atomic

    write_atomic(path, lambda f: f.write(text.encode("utf-8")))


def train(cfg: TrainConfig, out: Path, resume: str | None = None, seed: int | None = None,
          timesteps: int | None = None, progress: bool = True, command: str = "",
          vec_env: str | None = None, final_eval: bool = True) -> dict:
    """Train (or resume) a PPO policy; returns the run summary (also in ``summary.json``).

    Parameters
    ----------
    cfg : TrainConfig
    out : Path, output folder
    resume : str, optional, checkpoint (``checkpoints/latest.json``) to continue from; the model,
        optimiser, reward normaliser, RNG states and step count are restored, the environments
        start new episodes (seeded from the seed and the step count)
    seed : int, optional, overrides ``cfg.seed``
    timesteps : int, optional, overrides ``cfg.total_timesteps`` (total, counting the steps
        already in a resumed checkpoint)
    progress : bool, show SB3's progress bar
    command : str, the command line, stored in the policy files
    vec_env : str, optional, overrides ``cfg.vec_env``
    final_eval : bool, compare final/best policy with PI at the end

    Returns
    -------
    dict with ``status`` ``'finished'``, ``'already finished'`` or ``'interrupted'``.
    """
    import torch
    import yaml
    from stable_baselines3.common.callbacks import CallbackList

    from .lifecycle import STOP, stop_on_signals
    from .ppo import save_policy

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
    if resume:
        from .safe_files import load_model_file

        j = load_model_file(resume).meta
        if j.get("finished") and int(j.get("num_timesteps", 0)) >= cfg.total_timesteps:
            return {"status": "already finished", "total_timesteps": int(j["num_timesteps"])}
    out.mkdir(parents=True, exist_ok=True)
    if not resume:
        _write_text(out / "config.yaml", yaml.safe_dump(train_config_to_dict(cfg), sort_keys=False))
    t0 = time.perf_counter()
    done = 0
    model, env = None, None
    with stop_on_signals():
        env = build_training_env(cfg, cfg.seed)
        model = make_model(cfg, env, cfg.seed, str(out / "tb"))
        if resume:
            j = load_ppo_checkpoint(model, env, resume)
            if j.get("obs_transform") != obs_transform(cfg).to_dict() or j.get("env_mode") != cfg.env.action_mode:
                raise UsageError(f"checkpoint {resume} was trained with another observation transform or action "
                                 f"mode; resume with the config of that run")
            done = int(model.num_timesteps)
            env.seed(cfg.seed + done)
            print(f"resuming from {resume} at {done} steps")
        ckpt, val = _callbacks(cfg, out, command, cfg.seed, env)
        t_learn = time.perf_counter()
        remaining = cfg.total_timesteps - done
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=CallbackList([ckpt, val]), tb_log_name=cfg.name,
                        reset_num_timesteps=not resume, progress_bar=progress)
        learn_s = time.perf_counter() - t_learn
        if STOP["flag"]:
            ckpt.save()
            env.close()
            return {"status": "interrupted", "total_timesteps": int(model.num_timesteps), "signal": STOP["signal"]}
    steps = int(model.num_timesteps) - done
    if cfg.eval.every_steps:
        val.run()                      # the final policy competes for best too
    wall_train = time.perf_counter() - t0
    meta = policy_meta(cfg, model, command, cfg.seed, wall_s=wall_train)
    final_path = save_policy(model, str(out / "final"), meta)
    if not (out / "best.json").exists():
        save_policy(model, str(out / "best"), meta)
    ckpt.save(finished=True)
    env.close()
    summary = {"status": "finished", "name": cfg.name, "command": command, "seed": cfg.seed,
               "total_timesteps": int(model.num_timesteps), "steps_this_run": steps,
               "learn_seconds": learn_s, "env_steps_per_second": steps / learn_s if learn_s > 0 else None,
               "train_wall_seconds": wall_train, "validation_history": val.history,
               "final": str(final_path), "best": str(out / "best.json")}
    if final_eval:
        summary.update(_final_eval(cfg, out, model))
    summary["wall_seconds"] = time.perf_counter() - t0
    _write_text(out / "summary.json", json.dumps(summary, indent=1, default=str))
    return summary


def _final_eval(cfg: TrainConfig, out: Path, model) -> dict:
    """Final and best policy against PI on validation and held-out valves (``eval.csv``)."""
    import pandas as pd

    from .base import BlockPolicy
    from .controllers import load_controller
    from .ppo import load_policy

    sets: dict = {"validation": validation_valves(cfg)}
    if cfg.eval.heldout_n > 0:
        sets["heldout"] = heldout_valves(cfg)
    ctrls = {"pi": BlockPolicy(load_controller("pi", scan_s=cfg.env.control_period)),
             "final": _controller(cfg, model, "final"),
             "best": load_policy(str(out / "best.json"), name="best")}
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
    _write_text(out / "eval.csv", pd.concat(frames, ignore_index=True).to_csv(index=False))
    return {"eval": res}


# --------------------------------------------------------------------------- CLI
class UsageError(ValueError):
    """Bad usage of ``valve-gym train`` (exit code 2)."""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="valve-gym train",
        description="Train a policy from a YAML config: the learned stiction compensator "
                    "(configs/learned.yaml, evolution strategies on the regulation task) or a PPO policy "
                    "(configs/ppo_*.yaml). Exit codes: 0 done (or already done), 1 the training failed or "
                    "was interrupted (a checkpoint was written), 2 bad usage.")
    p.add_argument("--config", required=True, help="training YAML, e.g. configs/learned.yaml")
    p.add_argument("--out", default=None, help="output folder (default: runs/<name>); must be empty or "
                                                "absent unless --resume or --overwrite")
    p.add_argument("--resume", nargs="?", const="auto", default=None, metavar="CKPT",
                   help="continue the run in --out from its latest checkpoint (or from CKPT, a "
                        ".safetensors/.json checkpoint); a finished run is left unchanged")
    p.add_argument("--overwrite", action="store_true",
                   help="delete the previous run's files in --out and start afresh")
    p.add_argument("--timesteps", type=int, default=None, help="override total_timesteps (PPO)")
    p.add_argument("--generations", type=int, default=None, help="override es.generations (learned compensator)")
    p.add_argument("--seed", type=int, default=None, help="override the seed")
    p.add_argument("--vec-env", choices=("native", "dummy", "subproc"), default=None,
                   help="override the vectorisation of PPO (default from the config: native)")
    p.add_argument("--no-progress", action="store_true", help="no progress output")
    p.add_argument("--no-final-eval", action="store_true", help="skip the comparison with PI at the end (PPO)")
    return p


#: Files and folders a training run writes into --out (what --overwrite removes).
RUN_FILES = ("config.yaml", "summary.json", "eval.csv", "curve.csv", "final.safetensors", "final.json",
             "best.safetensors", "best.json", "checkpoints", "tb")


def _started(out: Path, entries: list[str]) -> bool:
    """Whether ``out`` holds more than a run that failed before its first checkpoint (its config alone)."""
    ck = out / "checkpoints"
    return any(e not in ("config.yaml", "checkpoints") for e in entries) or (ck.is_dir() and any(ck.iterdir()))


def prepare_out(out: Path, resume: str | None, overwrite: bool) -> Path | None:
    """Check ``--out`` against ``--resume``/``--overwrite``; returns the checkpoint to resume from (or None).

    Raises
    ------
    UsageError
        A non-empty ``out`` without ``--resume`` or ``--overwrite``, both flags, a missing checkpoint,
        or ``--overwrite`` on a folder with files a run does not write (nothing is deleted then). A
        folder that holds only the config of a run that failed before its first checkpoint (nothing to
        resume) is started again without ``--overwrite``.
    """
    import shutil

    if resume and overwrite:
        raise UsageError("--resume and --overwrite exclude each other: continue the run or start afresh")
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file; give a folder")
    entries = sorted(x.name for x in out.iterdir()) if out.is_dir() else []
    if resume:
        ck = out / "checkpoints" / "latest.json" if resume == "auto" else Path(resume)
        if not ck.is_file():
            raise UsageError(f"no checkpoint to resume: {ck} does not exist (train without --resume first)")
        return ck
    if entries and not _started(out, entries):
        overwrite = True      # a run that failed before its first checkpoint left only its config: start it again
    if entries and not overwrite:
        raise UsageError(f"--out {out} is not empty ({', '.join(entries[:5])}{' ...' if len(entries) > 5 else ''}); "
                         f"pass --resume to continue that run, --overwrite to replace it, or another --out")
    if entries:
        foreign = [e for e in entries if e not in RUN_FILES and not e.startswith(".")]
        if foreign:
            raise UsageError(f"--overwrite would delete files that a training run does not write in {out}: "
                             f"{', '.join(foreign[:5])}; move them or choose another --out (nothing was deleted)")
        for e in entries:
            q = out / e
            shutil.rmtree(q) if q.is_dir() else q.unlink()
    return None


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


#: Largest ``--seed`` (the seeders of NumPy's legacy RNG and of SB3 take 32-bit seeds).
_MAX_SEED = 2**32 - 1


def check_options(args) -> None:
    """Refuse bad numeric options before anything is read, created or trained (:class:`UsageError`)."""
    if args.seed is not None and not 0 <= args.seed <= _MAX_SEED:
        raise UsageError(f"--seed must be an integer from 0 to {_MAX_SEED}, got {args.seed}")
    for flag, val in (("--generations", args.generations), ("--timesteps", args.timesteps)):
        if val is not None and val < 1:
            raise UsageError(f"{flag} must be an integer >= 1, got {val}")
    if args.out is not None and not str(args.out).strip():
        raise UsageError("--out must not be empty; give a folder (or leave it out for runs/<name>)")


def _raw_algorithm(path: str) -> str:
    data = read_yaml(Path(path), "training config", empty_hint=_TRAIN_EMPTY_HINT)
    if isinstance(data, Mapping) and data.get("algorithm") is not None:
        return str(data.get("algorithm"))
    return "ppo"


def _is_baseline(path: str) -> bool:
    """A config of :mod:`valve_gym.agents.baselines` (it names ``env_id``)."""
    data = read_yaml(Path(path), "training config", empty_hint=_TRAIN_EMPTY_HINT)
    return isinstance(data, Mapping) and "env_id" in data


def _main_baseline(args, command: str) -> int:
    """SB3 PPO / A2C / SAC / TD3 on the regulation env (:mod:`valve_gym.agents.baselines`)."""
    from .baselines import load_baseline_config, train_baseline

    cfg = load_baseline_config(args.config)
    for flag, val in (("--resume", args.resume), ("--generations", args.generations), ("--vec-env", args.vec_env)):
        if val is not None:
            raise UsageError(f"{flag} is not used by {cfg['algorithm']} baselines ({args.config})")
    seed = 0 if args.seed is None else int(args.seed)
    out = Path(args.out) if args.out else Path("runs") / f"{cfg['name']}_{seed}"
    prepare_out(out, None, args.overwrite)
    s = train_baseline(cfg, out, seed, args.timesteps, not args.no_progress, command)
    f = s["final"]
    print(f"{cfg['name']} seed {seed}: {s['env_steps']} env steps in {s['train_wall_s']:.0f} s; median R "
          f"{f['R']:.2f}, travel / frictionless PI {f['travel_vs_frictionless']:.2f}, LC share {f['lc_share']:.2f}; "
          f"policy {out / 'policy.json'}")
    return 0


def _main_learned(args, command: str) -> int:
    from valve_gym._io import write_atomic

    from .es import load_learned_train_config, summary_json, train_learned

    cfg = load_learned_train_config(args.config)
    for flag, val in (("--timesteps", args.timesteps), ("--vec-env", args.vec_env),
                      ("--no-final-eval", args.no_final_eval or None)):
        if val is not None:
            raise UsageError(f"{flag} is for PPO configs; {args.config} trains the learned compensator "
                             f"(use --generations to change its length)")
    out = Path(args.out) if args.out else Path("runs") / cfg.name
    ck = prepare_out(out, args.resume, args.overwrite)
    if ck is None:
        out.mkdir(parents=True, exist_ok=True)
        import yaml

        from valve_gym.config import config_to_dict

        text = yaml.safe_dump(config_to_dict(cfg), sort_keys=False)
        write_atomic(out / "config.yaml", lambda f: f.write(text.encode()))
    s = train_learned(cfg, out, resume=ck, seed=args.seed, generations=args.generations, command=command,
                      progress=not args.no_progress)
    if s["status"] == "already finished":
        print(f"valve-gym train: the run in {out} is already finished ({s['gen']} generations); nothing changed")
        return 0
    write_atomic(out / "summary.json", lambda f: f.write(summary_json(s).encode()))
    if s["status"] == "interrupted":
        print(f"valve-gym train: interrupted by signal {s['signal']} at generation {s['gen']}; checkpoint written "
              f"to {out / 'checkpoints' / 'latest.json'}; continue with --resume", file=sys.stderr)
        return 1
    print(f"\n{cfg.name}: {s['gen']} generations, {s['env_steps']} env steps, training wall time "
          f"{s['train_wall_s']:.1f} s ({s['train_wall_s'] / 60:.2f} min)\nlearned block: {out / 'best.json'} "
          f"(best on validation), {out / 'final.json'} (last); learning curve: {out / 'curve.csv'}")
    return 0


def main(argv=None) -> int:
    """``valve-gym train``; returns the exit code (0 done, 1 failed or interrupted, 2 bad usage)."""
    args = _parser().parse_args(argv)
    argv_list = list(sys.argv[1:] if argv is None else argv)
    command = "valve-gym train " + " ".join(shlex.quote(a) for a in argv_list)
    try:
        check_options(args)
        algo = _raw_algorithm(args.config).lower()
        if algo == "es":
            return _main_learned(args, command)
        if algo in ("sac", "td3", "a2c") or (algo == "ppo" and _is_baseline(args.config)):
            return _main_baseline(args, command)
        return _main_ppo(args, command)
    except (ConfigError, UsageError) as exc:
        print(f"valve-gym train: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        from valve_gym.cli import missing_extra

        said = missing_extra(exc, "train")
        if said is None:
            raise
        print(said, file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:
        print(f"valve-gym train: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - one line instead of a traceback; the variable shows it
        if os.environ.get("VALVE_GYM_DEBUG"):
            raise
        print(f"valve-gym train: internal error {type(exc).__name__}: {exc} (set VALVE_GYM_DEBUG=1 for the "
              f"traceback and report it)", file=sys.stderr)
        return 1


def _main_ppo(args, command: str) -> int:
    cfg = load_train_config(args.config)
    if args.generations is not None:
        raise UsageError(f"--generations is for the learned compensator (algorithm: es); {args.config} is a PPO "
                         f"config: use --timesteps")
    out = Path(args.out) if args.out else Path("runs") / cfg.name
    ck = prepare_out(out, args.resume, args.overwrite)
    s = train(cfg, out, resume=None if ck is None else str(ck), seed=args.seed, timesteps=args.timesteps,
              progress=not args.no_progress, command=command, vec_env=args.vec_env,
              final_eval=not args.no_final_eval)
    if s.get("status") == "already finished":
        print(f"valve-gym train: the run in {out} is already finished ({s['total_timesteps']} steps); "
              f"nothing changed")
        return 0
    if s.get("status") == "interrupted":
        print(f"valve-gym train: interrupted at {s['total_timesteps']} steps; checkpoint written to "
              f"{out / 'checkpoints' / 'latest.json'}; continue with --resume", file=sys.stderr)
        return 1
    _print_summary(s)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
