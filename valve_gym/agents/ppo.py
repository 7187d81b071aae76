"""PPO policies (Stable-Baselines3) behind the common ``predict`` interface.

Stiction is hidden state: from one observation a policy cannot tell a valve
that is stuck from one that is moving. :class:`ObsTransform` therefore turns
the environment's observation into the policy's input with fixed scaling,
optional first differences (``deltas``) and a stack of the last
``frame_stack`` frames. The *same* object is used in training (as the
:class:`TransformVecEnv` wrapper) and at evaluation (inside
:class:`PPOController`, whose SB3 ``state`` carries the frame history), so a
shipped policy sees exactly the inputs it was trained on.

A policy file is a pair ``NAME.safetensors`` (the weights of SB3's policy,
by ``state_dict`` name) + ``NAME.json`` (architecture, observation transform,
environment action mode and settings, training command, versions);
:func:`load_policy` evaluates the deterministic actor in numpy and never
unpickles anything (SB3 ``.zip`` files are refused, see
:mod:`valve_gym.agents.convert` for converting a trusted one).
"""
from __future__ import annotations

import functools
import os
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numpy as np

from .base import as_obs_batch, episode_start_mask

__all__ = ["ObsTransform", "ObsHistory", "PPOController", "TransformVecEnv", "load_policy",  # noqa: F822 (lazy)
           "save_policy", "read_policy_meta", "NumpyActor", "policy_tensors", "POLICY_FORMAT"]


#: Feature scaling of the raw observation columns [level, sp, error, u, stem]:
#: ``f = (obs - offset) * scale``; the error (a few cm) is blown up to O(1).
DEFAULT_OFFSET = (1.0, 1.0, 0.0, 0.5, 0.5)
DEFAULT_SCALE = (2.0, 2.0, 20.0, 2.0, 2.0)


class ObsHistory(NamedTuple):
    """Frame history of :class:`ObsTransform`: ``frames`` (n, k, d) scaled, oldest first."""

    frames: np.ndarray


@dataclass(frozen=True)
class ObsTransform:
    """Fixed observation pre-processing shared by training and evaluation.

    Parameters
    ----------
    frame_stack : int
        Number of most recent frames concatenated (>= 1; 1 = no stacking).
    deltas : bool
        Append the first difference of the scaled features (newest frame minus
        the one before), a direct view of how the level and valve input move.
    offset, scale : sequence of float
        ``feature = (obs - offset) * scale`` per raw column (length >= obs_dim).

    Notes
    -----
    Output per step: ``[f_{t-k+1}, ..., f_t]`` followed by ``f_t - f_{t-1}``
    when ``deltas``; at an episode start the history is filled with the first
    frame (so the deltas are zero).

    Examples
    --------
    >>> import numpy as np
    >>> tf = ObsTransform(frame_stack=2, deltas=True)
    >>> obs = np.array([[1.0, 1.1, 0.1, 0.5]])
    >>> x, h = tf.start(obs)
    >>> x.shape, tf.out_dim(4)
    ((1, 12), 12)
    >>> x2, h = tf.step(h, obs + np.array([[0.0, 0.0, 0.0, 0.1]]))
    >>> round(float(x2[0, -1]), 6)    # delta of the scaled valve input: 0.1 * 2
    0.2
    """

    frame_stack: int = 1
    deltas: bool = False
    offset: tuple[float, ...] = DEFAULT_OFFSET
    scale: tuple[float, ...] = DEFAULT_SCALE

    def __post_init__(self):
        if isinstance(self.frame_stack, bool) or not isinstance(self.frame_stack, (int, np.integer)) \
                or self.frame_stack < 1:
            raise ValueError(f"frame_stack must be an integer >= 1, got {self.frame_stack!r}")
        if not isinstance(self.deltas, (bool, np.bool_)):
            raise ValueError(f"deltas must be true or false, got {self.deltas!r}")
        object.__setattr__(self, "offset", tuple(float(v) for v in self.offset))
        object.__setattr__(self, "scale", tuple(float(v) for v in self.scale))
        if len(self.offset) != len(self.scale):
            raise ValueError("offset and scale must have the same length")

    def out_dim(self, obs_dim: int) -> int:
        """Length of the transformed observation for ``obs_dim`` raw columns."""
        return obs_dim * (self.frame_stack + (1 if self.deltas else 0))

    def features(self, obs: np.ndarray) -> np.ndarray:
        """Scaled features ``(n, d)`` of raw observations ``(n, d)``."""
        d = obs.shape[1]
        if d > len(self.scale):
            raise ValueError(f"observation has {d} columns but the transform scales only "
                             f"{len(self.scale)}; give offset/scale for every column")
        return (obs - np.asarray(self.offset[:d])) * np.asarray(self.scale[:d])

    def _nframes(self) -> int:
        return max(self.frame_stack, 2 if self.deltas else 1)

    def start(self, obs) -> tuple[np.ndarray, ObsHistory]:
        """Start a history from the first observations ``(n, d)``."""
        obs = np.asarray(obs, dtype=np.float64)
        f = self.features(obs)
        frames = np.repeat(f[:, None, :], self._nframes(), axis=1)
        return self._out(frames), ObsHistory(frames)

    def _out(self, frames: np.ndarray) -> np.ndarray:
        k = self.frame_stack
        stacked = frames[:, -k:].reshape(frames.shape[0], -1)
        if self.deltas:
            stacked = np.concatenate([stacked, frames[:, -1] - frames[:, -2]], 1)
        return stacked.astype(np.float32)

    def step(self, hist: ObsHistory, obs, episode_start=None) -> tuple[np.ndarray, ObsHistory]:
        """Push observations ``(n, d)``; rows with ``episode_start`` restart their history."""
        obs = np.asarray(obs, dtype=np.float64)
        f = self.features(obs)
        frames = np.concatenate([hist.frames[:, 1:], f[:, None, :]], axis=1)
        if episode_start is not None:
            m = episode_start_mask(episode_start, obs.shape[0])
            if m.any():
                frames[m] = f[m][:, None, :]
        return self._out(frames), ObsHistory(frames)

    def peek(self, hist: ObsHistory, obs) -> np.ndarray:
        """Transformed observation if ``obs`` were pushed, without keeping it."""
        return self.step(hist, obs)[0]

    def to_dict(self) -> dict:
        """JSON-able settings (inverse of :meth:`from_dict`)."""
        d = asdict(self)
        d["offset"], d["scale"] = list(self.offset), list(self.scale)
        return d

    @classmethod
    def from_dict(cls, d: dict | None) -> ObsTransform:
        """The transform of :meth:`to_dict` settings (the default transform for ``None``)."""
        return cls(**(d or {}))


# ---------------------------------------------------------------- training wrapper
@functools.cache
def _transform_vec_env() -> type:
    """The class :class:`TransformVecEnv`, defined on first use.

    It subclasses SB3's ``VecEnvWrapper``; defined lazily, this module (the policy files and the numpy
    controller) imports without stable-baselines3.
    """
    try:
        from stable_baselines3.common.vec_env import VecEnvWrapper
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ModuleNotFoundError('TransformVecEnv needs stable-baselines3: pip install "valve_gym[rl]"',
                                  name="stable_baselines3") from exc

    class TransformVecEnv(VecEnvWrapper):
        """SB3 ``VecEnvWrapper`` applying an :class:`ObsTransform` (training side).

        Handles SB3's auto-reset: for a finished sub-env the returned observation
        starts a new history, and ``infos[i]["terminal_observation"]`` is
        transformed with the old history so that PPO bootstraps the value of a
        truncated episode from the right input.
        """

        def __init__(self, venv, transform: ObsTransform):
            from gymnasium import spaces
            self.transform = transform
            d = int(venv.observation_space.shape[0])
            od = transform.out_dim(d)
            space = spaces.Box(low=-np.inf, high=np.inf, shape=(od,), dtype=np.float32)
            super().__init__(venv, observation_space=space)
            self._hist: ObsHistory | None = None

        def reset(self):
            """Reset the wrapped env; returns the transformed first observations."""
            obs = self.venv.reset()
            x, self._hist = self.transform.start(obs)
            return x

        def step_wait(self):
            """Step the wrapped env; transforms the observations (and terminal ones)."""
            obs, rew, done, infos = self.venv.step_wait()
            done = np.asarray(done, dtype=bool)
            assert self._hist is not None, "reset() before step()"
            if done.any():
                for i in np.flatnonzero(done):
                    term = infos[i].get("terminal_observation")
                    if term is not None:
                        sub = ObsHistory(self._hist.frames[i:i + 1])
                        infos[i]["terminal_observation"] = self.transform.peek(
                            sub, np.asarray(term, dtype=np.float64)[None, :])[0]
            x, self._hist = self.transform.step(self._hist, obs, episode_start=done)
            return x, rew, done, infos

    return TransformVecEnv


def __getattr__(name: str):
    if name == "TransformVecEnv":
        return _transform_vec_env()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ---------------------------------------------------------------- policy files
#: Format tag of a PPO policy file's JSON.
POLICY_FORMAT = "valve_gym.ppo_policy/1"


def policy_tensors(model) -> dict:
    """The policy's weights as float32 numpy arrays, by SB3's ``state_dict`` names."""
    return {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.policy.state_dict().items()}


def save_policy(model, path: str, meta: dict) -> str:
    """Save an SB3 model's policy as ``path.safetensors`` + ``path.json`` (atomic; no pickle).

    The JSON holds ``meta`` (observation transform, environment settings, training command, ...)
    and the architecture (``net_arch``, activation, observation and action sizes); returns the JSON path.
    """
    from .safe_files import save_model_file

    stem = str(path)
    for ext in (".zip", ".json", ".safetensors"):
        if stem.endswith(ext):
            stem = stem[: -len(ext)]
    pk = meta.get("train_config", {}).get("ppo", {}).get("policy_kwargs", {})
    arch = {"net_arch": list(pk.get("net_arch", [64, 64])), "activation_fn": pk.get("activation_fn", "tanh"),
            "obs_dim": int(model.observation_space.shape[0]), "act_dim": int(model.action_space.shape[0])}
    full = {**meta, "format": POLICY_FORMAT, "architecture": arch}
    _, jpath = save_model_file(stem, policy_tensors(model), full)
    return jpath


def read_policy_meta(path: str) -> dict:
    """The JSON metadata of a policy file (``.json`` / ``.safetensors`` / stem); refuses pickle-based files."""
    from .safe_files import load_model_file, model_file_paths, refuse_unsafe

    if os.path.isfile(path) and not str(path).endswith((".json", ".safetensors")):
        refuse_unsafe(path)
    _, jpath = model_file_paths(path)
    if not jpath.is_file():
        raise FileNotFoundError(f"policy file not found: {jpath}")
    return load_model_file(path).meta


class NumpyActor:
    """Deterministic actor of an SB3 ``MlpPolicy`` evaluated in numpy (no torch, no pickle).

    ``a = W_a h_L + b_a`` with ``h_i = act(W_i h_i-1 + b_i)``, the mean of SB3's Gaussian policy
    (its deterministic action), from the ``mlp_extractor.policy_net.*`` and ``action_net`` weights.
    """

    def __init__(self, tensors: dict, activation: str = "tanh"):
        idx = sorted({int(k.split(".")[2]) for k in tensors if k.startswith("mlp_extractor.policy_net.")})
        self.layers = [(tensors[f"mlp_extractor.policy_net.{i}.weight"].astype(np.float64),
                        tensors[f"mlp_extractor.policy_net.{i}.bias"].astype(np.float64)) for i in idx]
        self.out = (tensors["action_net.weight"].astype(np.float64), tensors["action_net.bias"].astype(np.float64))
        if activation not in ("tanh", "relu"):
            raise ValueError(f"activation must be 'tanh' or 'relu', got {activation!r}")
        self.act = np.tanh if activation == "tanh" else (lambda x: np.maximum(x, 0.0))

    def predict(self, x, deterministic: bool = True):
        """SB3-like ``predict``: ``(actions (n, act_dim), None)``, deterministic (the mean action)."""
        h = np.asarray(x, dtype=np.float64)
        for W, b in self.layers:
            h = self.act(h @ W.T + b)
        W, b = self.out
        return h @ W.T + b, None


class PPOState(NamedTuple):
    """State of :class:`PPOController`: the observation history."""

    hist: ObsHistory


class PPOController:
    """A trained SB3 policy with its observation transform (batched ``predict``).

    Parameters
    ----------
    model : stable_baselines3 BaseAlgorithm (or anything with SB3's ``predict``)
    transform : ObsTransform
    env_mode : {'direct', 'residual'}
        Action mode the policy was trained in.
    env_overrides : dict, optional
        Environment settings the policy needs at evaluation (action mode,
        residual scale, measured stem, ...), applied on top of the evaluation
        environment's configuration.
    name : str
    """

    def __init__(self, model, transform: ObsTransform = ObsTransform(), env_mode: str = "direct",
                 env_overrides: dict | None = None, name: str = "ppo", meta: dict | None = None):
        if env_mode not in ("direct", "residual"):
            raise ValueError(f"env_mode must be 'direct' or 'residual', got {env_mode!r}")
        self.model = model
        self.transform = transform
        self.env_mode = env_mode
        self.env_overrides = dict(env_overrides or {})
        self.name = name
        self.meta = dict(meta or {})

    def __repr__(self) -> str:
        return (f"PPOController(name={self.name!r}, env_mode={self.env_mode!r}, "
                f"frame_stack={self.transform.frame_stack}, deltas={self.transform.deltas})")

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style batched prediction; ``state`` carries the frame history."""
        obs, single = as_obs_batch(observation)
        if state is None:
            x, hist = self.transform.start(obs)
        else:
            hist = ObsHistory(*PPOState(*state).hist)
            x, hist = self.transform.step(hist, obs, episode_start)
        act, _ = self.model.predict(x, deterministic=deterministic)
        act = np.clip(np.asarray(act, dtype=np.float32).reshape(obs.shape[0], -1), -1.0, 1.0)
        return (act[0] if single else act), PPOState(hist)


def load_policy(path: str, name: str | None = None, device: str = "cpu") -> PPOController:
    """Load a policy written by ``valve-gym train`` (``.json`` + ``.safetensors``) as a :class:`PPOController`.

    Parameters
    ----------
    path : str, the policy's ``.json`` or ``.safetensors`` file (or their common stem)
    name : str, label (default: ``meta['name']`` or the file stem)
    device : str, ignored (the actor runs in numpy); kept for compatibility

    Raises
    ------
    valve_gym.agents.safe_files.UnsafeFileError
        For an SB3 ``.zip`` or any pickle: never unpickled (the message says how to convert a trusted one).
    """
    from .safe_files import load_model_file, refuse_unsafe

    if os.path.isfile(path) and not str(path).endswith((".json", ".safetensors")):
        refuse_unsafe(path)
    mf = load_model_file(path)
    meta = mf.meta
    if meta.get("format") != POLICY_FORMAT:
        raise ValueError(f"{path} is not a PPO policy file (format {meta.get('format')!r}, expected "
                         f"{POLICY_FORMAT!r}); a learned compensator loads with valve_gym.agents.learned.load_learned")
    arch = meta.get("architecture", {})
    model = NumpyActor(mf.tensors, arch.get("activation_fn", "tanh"))
    tf = ObsTransform.from_dict(meta.get("obs_transform"))
    if name is None:
        name = meta.get("name") or os.path.splitext(os.path.basename(str(path)))[0]
    return PPOController(model, transform=tf, env_mode=meta.get("env_mode", "direct"),
                         env_overrides=meta.get("env_overrides", {}), name=name, meta=meta)
