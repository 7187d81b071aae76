"""PPO policies (Stable-Baselines3) behind the common ``predict`` interface.

Stiction is hidden state: from one observation a policy cannot tell a valve
that is stuck from one that is moving. :class:`ObsTransform` therefore turns
the environment's observation into the policy's input with fixed scaling,
optional first differences (``deltas``) and a stack of the last
``frame_stack`` frames. The *same* object is used in training (as the
:class:`TransformVecEnv` wrapper) and at evaluation (inside
:class:`PPOController`, whose SB3 ``state`` carries the frame history), so a
shipped policy sees exactly the inputs it was trained on.

A policy file is SB3's ``.zip`` with one extra entry, ``valve_gym.json``,
holding the observation transform, the environment action mode and the
environment settings the policy was trained with (SB3 ignores the entry when
loading); :func:`load_policy` reads both.
"""
from __future__ import annotations

import json
import os
import zipfile
from dataclasses import asdict, dataclass
from typing import NamedTuple, Optional, Tuple

import numpy as np

from .base import as_obs_batch, episode_start_mask

__all__ = ["ObsTransform", "ObsHistory", "PPOController", "TransformVecEnv", "load_policy",
           "save_policy", "read_policy_meta", "POLICY_META_NAME"]

POLICY_META_NAME = "valve_gym.json"

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
    offset: Tuple[float, ...] = DEFAULT_OFFSET
    scale: Tuple[float, ...] = DEFAULT_SCALE

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

    def start(self, obs) -> Tuple[np.ndarray, ObsHistory]:
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

    def step(self, hist: ObsHistory, obs, episode_start=None) -> Tuple[np.ndarray, ObsHistory]:
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
        d = asdict(self)
        d["offset"], d["scale"] = list(self.offset), list(self.scale)
        return d

    @classmethod
    def from_dict(cls, d: Optional[dict]) -> "ObsTransform":
        return cls(**(d or {}))


# ---------------------------------------------------------------- training wrapper
def _vec_env_wrapper_base():
    from stable_baselines3.common.vec_env import VecEnvWrapper
    return VecEnvWrapper


class TransformVecEnv(_vec_env_wrapper_base()):
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
        self._hist: Optional[ObsHistory] = None

    def reset(self):
        obs = self.venv.reset()
        x, self._hist = self.transform.start(obs)
        return x

    def step_wait(self):
        obs, rew, done, infos = self.venv.step_wait()
        done = np.asarray(done, dtype=bool)
        if done.any():
            for i in np.flatnonzero(done):
                term = infos[i].get("terminal_observation")
                if term is not None:
                    sub = ObsHistory(self._hist.frames[i:i + 1])
                    infos[i]["terminal_observation"] = self.transform.peek(
                        sub, np.asarray(term, dtype=np.float64)[None, :])[0]
        x, self._hist = self.transform.step(self._hist, obs, episode_start=done)
        return x, rew, done, infos


# ---------------------------------------------------------------- policy files
def save_policy(model, path: str, meta: dict) -> str:
    """Save an SB3 model plus ``meta`` atomically to ``path`` (.zip).

    The zip (SB3's entries plus ``valve_gym.json``) is built in memory and
    written through :func:`valve_gym._io.write_atomic` (temporary file, then
    :func:`os.replace`), so a reader never sees a half-written policy.
    """
    import io

    from valve_gym._io import write_atomic

    path = str(path)
    if not path.endswith(".zip"):
        path += ".zip"
    buf = io.BytesIO()
    model.save(buf)
    with zipfile.ZipFile(buf, "a", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr(POLICY_META_NAME, json.dumps(meta, indent=1, sort_keys=True, default=_json_default))
    data = buf.getvalue()
    write_atomic(path, lambda f: f.write(data))
    from .benchmark import _readable

    _readable(path)
    return path


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def read_policy_meta(path: str) -> dict:
    """The ``valve_gym.json`` metadata of a policy zip (``{}`` if it has none)."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"policy file not found: {path}")
    try:
        with zipfile.ZipFile(path) as z:
            if POLICY_META_NAME not in z.namelist():
                return {}
            return json.loads(z.read(POLICY_META_NAME).decode("utf-8"))
    except zipfile.BadZipFile:
        raise ValueError(f"{path} is not a policy .zip (SB3 model file)") from None


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
                 env_overrides: Optional[dict] = None, name: str = "ppo", meta: Optional[dict] = None):
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


def load_policy(path: str, name: Optional[str] = None, device: str = "cpu") -> PPOController:
    """Load a policy zip written by ``valve-gym train`` as a :class:`PPOController`.

    Parameters
    ----------
    path : str, the ``.zip`` file
    name : str, label (default: ``meta['name']`` or the file stem)
    device : str, torch device (default cpu)
    """
    try:
        from stable_baselines3 import PPO
    except ImportError as exc:  # pragma: no cover
        raise ImportError("loading a PPO policy needs stable-baselines3 (pip install "
                          "stable-baselines3)") from exc
    meta = read_policy_meta(path)
    model = PPO.load(path, device=device)
    tf = ObsTransform.from_dict(meta.get("obs_transform"))
    if name is None:
        name = meta.get("name") or os.path.splitext(os.path.basename(path))[0]
    return PPOController(model, transform=tf, env_mode=meta.get("env_mode", "direct"),
                         env_overrides=meta.get("env_overrides", {}), name=name, meta=meta)
