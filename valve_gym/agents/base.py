"""The SB3 ``predict`` interface for RL code, and its adapter over the DCS blocks.

Controllers are DCS function blocks (:mod:`valve_gym.agents.controllers`,
``reset(sp, pv, op)`` / ``step(sp, pv)``); RL code (Stable-Baselines3's
evaluation loops, :mod:`valve_gym.agents.evaluate`) calls ``predict`` instead.
:class:`BlockPolicy` gives any block that call, so the same PI or compensator
runs in both worlds.

Every controller of :mod:`agents` answers Stable-Baselines3's call::

    actions, state = controller.predict(obs, state=None, episode_start=None,
                                        deterministic=True)

on a *batch* of observations ``obs`` of shape ``(n, obs_dim)``, one row per
valve of a vector environment, and returns ``actions`` of shape ``(n, 1)``
(float32, in the environment's action space [-1, 1]) and the controller's
``state`` to pass back on the next call. ``state=None`` starts the
controller from the observation (bumpless); rows where ``episode_start`` is
true are restarted the same way. This is the contract of SB3's
``BasePolicy.predict`` and of its recurrent policies, so the one evaluation
loop of :mod:`valve_gym.agents.evaluate` runs all controllers alike.

Observation layout (columns of ``obs``), as produced by
:class:`valve_gym.envs.ValveTankEnv`:

====  ======================================  =====
col   quantity                                unit
====  ======================================  =====
0     measured level ``y``                    m
1     set point ``sp``                        m
2     control error ``e = sp - y``            m
3     valve input applied last period ``u``   0..1
4     stem position (``measure_stem`` only)   0..1
====  ======================================  =====
"""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from .controllers.block import FunctionBlock, merge_rows

__all__ = ["Controller", "BlockPolicy", "OBS_LEVEL", "OBS_SETPOINT", "OBS_ERROR", "OBS_U", "OBS_STEM",
           "as_obs_batch", "episode_start_mask", "u_to_action", "action_to_u"]

OBS_LEVEL, OBS_SETPOINT, OBS_ERROR, OBS_U, OBS_STEM = 0, 1, 2, 3, 4
_MIN_OBS_DIM = 4


@runtime_checkable
class Controller(Protocol):
    """A batched controller with SB3's ``predict`` signature.

    Attributes
    ----------
    env_mode : {'direct', 'residual'}
        The environment action mode the controller's actions are meant for:
        ``'direct'`` actions are the valve input ``u = (a + 1)/2``;
        ``'residual'`` actions correct the environment's built-in PI.
    name : str
        Short label used in tables and figures.
    """

    env_mode: str
    name: str

    def predict(self, observation: np.ndarray, state: Any | None = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any | None]:
        """Actions ``(n, 1)`` float32 in [-1, 1] and the next state."""
        ...  # pragma: no cover


def as_obs_batch(observation, min_dim: int = _MIN_OBS_DIM) -> tuple[np.ndarray, bool]:
    """Observation as a float ``(n, obs_dim)`` array; also says if it was a single row.

    Parameters
    ----------
    observation : (obs_dim,) or (n, obs_dim) array_like
    min_dim : int, the fewest columns the caller needs

    Returns
    -------
    obs : (n, obs_dim) float64 array
    single : bool, True when ``observation`` was one unbatched row

    Raises
    ------
    ValueError
        If the observation is not 1-D/2-D, has too few columns or is not finite.
    """
    obs = np.asarray(observation, dtype=np.float64)
    single = obs.ndim == 1
    if single:
        obs = obs[None, :]
    if obs.ndim != 2:
        raise ValueError(f"observation must have shape (obs_dim,) or (n, obs_dim), got {obs.shape}")
    if obs.shape[1] < min_dim:
        raise ValueError(
            f"observation has {obs.shape[1]} columns, expected at least {min_dim} "
            "([level, setpoint, error, last valve input, ...] of ValveTankEnv)")
    if not np.isfinite(obs).all():
        raise ValueError("observation contains NaN or inf values")
    return obs, single


def episode_start_mask(episode_start, n: int) -> np.ndarray:
    """``episode_start`` as a boolean ``(n,)`` mask (all False when None)."""
    if episode_start is None:
        return np.zeros(n, dtype=bool)
    m = np.asarray(episode_start).astype(bool).reshape(-1)
    if m.size == 1 and n != 1:
        m = np.full(n, bool(m[0]))
    if m.size != n:
        raise ValueError(f"episode_start has {m.size} entries, expected {n} (one per observation row)")
    return m


def u_to_action(u) -> np.ndarray:
    """Valve input ``u`` (n,) in 0..1 to direct-mode actions ``(n, 1)`` float32 ``2u - 1``."""
    return (2.0 * np.asarray(u, dtype=np.float64) - 1.0).astype(np.float32).reshape(-1, 1)


def action_to_u(action) -> np.ndarray:
    """Direct-mode actions (n, 1) or (n,) to valve input ``(n,)`` ``clip((a + 1)/2, 0, 1)``."""
    a = np.asarray(action, dtype=np.float64).reshape(-1)
    return np.clip(0.5 * (a + 1.0), 0.0, 1.0)


def _batch_size(state) -> int:
    while isinstance(state, tuple):
        state = state[0]
    return int(np.shape(state)[0])


class BlockPolicy:
    """SB3-style ``predict`` over a DCS block (:class:`valve_gym.agents.controllers.FunctionBlock`).

    Parameters
    ----------
    block : FunctionBlock, e.g. ``load_controller("knocker")``
    name : str, label in tables (default the block's name)
    env_mode : {'direct'}, the block outputs the valve input itself

    Notes
    -----
    Per row of the observation: ``sp = obs[:, 1]``, ``pv = sp - obs[:, 2]``
    (the error column, so ``sp - pv`` is exactly the observed error), and the
    valve input applied last period ``obs[:, 3]``. ``state=None`` (or
    ``episode_start`` for some rows) starts those rows bumplessly from that
    input (:meth:`FunctionBlock.initial_state`); the state passed back and forth
    is the block's named tuple of ``(n,)`` arrays. Actions are ``2 u - 1``.

    Examples
    --------
    >>> from valve_gym.agents.controllers import load_controller
    >>> pol = BlockPolicy(load_controller("pi", Kc=1.0, Ti=10.0))
    >>> a, s = pol.predict(np.array([[0.9, 1.0, 0.1, 0.5], [1.0, 1.0, 0.0, 0.3]]))
    >>> np.round((a[:, 0] + 1) / 2, 3)   # 0.5 + 1/10*0.1, and unchanged
    array([0.51, 0.3 ], dtype=float32)
    """

    def __init__(self, block: FunctionBlock, name: str | None = None, env_mode: str = "direct"):
        if not isinstance(block, FunctionBlock):
            raise TypeError(f"BlockPolicy wraps a controller block (load_controller(...)), got "
                            f"{type(block).__name__}")
        self.block = block
        self.name = block.name if name is None else name
        self.env_mode = env_mode

    def initial_state(self, obs):
        """Bumpless start of every row from the observed last valve input."""
        obs, _ = as_obs_batch(obs)
        sp, pv, u = self._signals(obs)
        return self.block.initial_state(sp, pv, u)

    def _signals(self, obs: np.ndarray):
        lo, hi = self.block.settings["op_lo"], self.block.settings["op_hi"]
        sp = obs[:, OBS_SETPOINT]
        return sp, sp - obs[:, OBS_ERROR], np.clip(obs[:, OBS_U], lo, hi)

    def control(self, obs, state=None, episode_start=None):
        """One scan in valve units: ``(obs, state) -> (u (n,), state)``."""
        obs, _ = as_obs_batch(obs)
        n = obs.shape[0]
        sp, pv, u = self._signals(obs)
        if state is None:
            state = self.block.initial_state(sp, pv, u)
        else:
            if _batch_size(state) != n:
                raise ValueError(f"{self.name}: state has batch size {_batch_size(state)}, observation "
                                 f"has {n} rows; pass state=None to restart")
            start = episode_start_mask(episode_start, n)
            if start.any():
                state = merge_rows(start, self.block.initial_state(sp, pv, u), state)
        state, u_out = self.block.advance(state, sp, pv)
        return u_out, state

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style batched prediction; see :class:`Controller`.

        Returns
        -------
        actions : (n, 1) float32 in [-1, 1] (``(1,)`` for a single observation row)
        state : the block's state
        """
        obs, single = as_obs_batch(observation)
        u, state = self.control(obs, state, episode_start)
        a = u_to_action(u)
        return (a[0] if single else a), state
