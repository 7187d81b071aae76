"""Stable-Baselines3 adapter of the native vector environment.

Stable-Baselines3 consumes its own :class:`~stable_baselines3.common.vec_env.VecEnv`
API, not a Gymnasium vector env. :class:`SB3VecEnv` wraps a
:class:`~valve_gym.envs.ValveTankVectorEnv` (run in ``SAME_STEP`` autoreset
mode) and behaves like ``DummyVecEnv([lambda: gymnasium.make(...)] * N)``:
done envs are reset within the step, ``infos[i]['terminal_observation']``
holds the last observation of the finished episode and
``infos[i]['TimeLimit.truncated']`` tells a time-limit end. Same seeds give
the same observations, rewards, dones and infos as that ``DummyVecEnv``, at the
speed of one kernel call per step.

Importing this module imports stable-baselines3 (and torch).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(
        'valve_gym.envs.sb3 needs stable-baselines3: pip install "valve_gym[rl]" '
        "(the rest of valve_gym works without it)") from exc

from gymnasium.vector import AutoresetMode

from ..config import EnvConfig
from .valve_tank import VALVE_KEYS
from .vector import ValveTankVectorEnv

__all__ = ["SB3VecEnv", "SB3RegulationVecEnv"]


class _OneVectorEnv:
    """What both adapters do the same way: one vector env behind every index (``self.venv``)."""

    venv: Any
    num_envs: int
    _get_indices: Any          # VecEnv's (annotation only: the mixin comes first in the MRO)

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions of the next :meth:`step_wait`."""
        self._actions = actions

    def _reset_done(self, obs, reset_infos: list):
        """After a reset of every loop: keep its infos, forget the pending seeds and options, allow steps."""
        self.reset_infos = reset_infos
        self._reset_seeds()        # type: ignore[attr-defined]  (VecEnv's)
        self._reset_options()      # type: ignore[attr-defined]
        self._started = True
        return obs

    def _check_started(self) -> None:
        if not getattr(self, "_started", False):
            raise RuntimeError("call reset() before step()")

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        """Set an attribute of the vector env (shared by all indices)."""
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
        """Call a method of the vector env once; ``render`` gives each index its frame."""
        idx = list(self._get_indices(indices))
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        if method_name == "render" and result is not None:
            return [result[i] for i in idx]
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list:
        """No Gymnasium wrappers are involved: False for every index."""
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The RGB frame of each sub-environment (``render_mode='rgb_array'``)."""
        if self.venv.render_mode != "rgb_array":
            return [None] * self.num_envs
        frames = self.venv.render()
        return [None] * self.num_envs if frames is None else list(frames)


class SB3VecEnv(_OneVectorEnv, VecEnv):
    """The native vector env as a Stable-Baselines3 ``VecEnv``.

    Parameters
    ----------
    num_envs : int
        Number of sub-environments (ignored if ``venv`` is given).
    config : EnvConfig, mapping, str or path, optional
        As for :class:`~valve_gym.envs.ValveTankEnv`.
    preset : {'default', 'fixed'}
    max_episode_steps : int, optional
        Time limit (default ``config.episode_steps``, the registered limit).
    render_mode : {None, 'rgb_array'}
    venv : ValveTankVectorEnv, optional
        An existing vector env in ``SAME_STEP`` autoreset mode to adapt.

    Notes
    -----
    * ``step`` returns observations ``(N, 4|5)`` float32, rewards ``(N,)``
      float32, dones ``(N,)`` bool and a list of N info dicts with the keys of
      :class:`~valve_gym.envs.ValveTankEnv` (floats), ``TimeLimit.truncated``
      and, when done, ``terminal_observation``. The info of the new episode is
      in ``reset_infos[i]``.
    * ``seed(s)`` seeds sub-environment ``i`` with ``s + i`` at the next
      ``reset()``, as for any SB3 ``VecEnv``; ``set_options({'z_max': 0.2})``
      pins valve parameters at the next reset (a list of dicts: per
      sub-environment).
    * ``get_attr``/``set_attr``/``env_method`` act on the vector env (the
      same value for every index): e.g. ``get_attr('substeps')``;
      ``env_method('render')`` returns the frames of the chosen indices.
      ``get_attr`` also gives the per-episode valve parameters ``z_max``,
      ``e_dead``, ``tau``, ``v_max`` per index.

    Examples
    --------
    >>> from valve_gym.envs.sb3 import SB3VecEnv
    >>> venv = SB3VecEnv(num_envs=4)
    >>> _ = venv.seed(0)
    >>> obs = venv.reset()
    >>> obs.shape
    (4, 4)
    """

    def __init__(self, num_envs: int = 1, config: EnvConfig | Mapping | str | None = None, *,
                 preset: str = "default", max_episode_steps: int | None = None,
                 render_mode: str | None = None, venv: ValveTankVectorEnv | None = None):
        if venv is None:
            venv = ValveTankVectorEnv(num_envs, config, preset=preset, max_episode_steps=max_episode_steps,
                                      autoreset_mode=AutoresetMode.SAME_STEP, render_mode=render_mode)
        elif not isinstance(venv, ValveTankVectorEnv):
            raise TypeError(f"venv must be a ValveTankVectorEnv, got {type(venv).__name__}")
        elif venv.autoreset_mode is not AutoresetMode.SAME_STEP:
            raise ValueError("SB3VecEnv needs the vector env in SAME_STEP autoreset mode: create it with "
                             "ValveTankVectorEnv(..., autoreset_mode='SameStep')")
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions = None
        self._started = False

    # ----------------------------------------------------------------- core
    def reset(self):
        """Reset all sub-environments with the pending seeds and options; returns ``(N, d)`` observations."""
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        options = None
        if any(self._options):
            options = {}
            for i, opt in enumerate(self._options):
                for key, val in (opt or {}).items():
                    if key not in VALVE_KEYS:
                        raise ValueError(f"unknown reset option {key!r} for sub-environment {i}; the "
                                         f"options pin the valve: {', '.join(VALVE_KEYS)}")
                    options.setdefault(key, np.full(self.num_envs, np.nan))[i] = float(val)
        obs, info = self.venv.reset(seed=seeds, options=options)
        return self._reset_done(obs, _split(info, self.num_envs))

    def step_wait(self):
        """Step every loop; returns SB3's ``(obs, rewards, dones, infos)``."""
        self._check_started()
        acts = np.asarray(self._actions, dtype=np.float32).reshape(self.num_envs, -1)
        obs, rew, term, trunc, info = self.venv.step(acts)
        dones = term | trunc
        if dones.any():
            step_info = dict(info["final_info"])
            infos = _split(step_info, self.num_envs)
            resets = _split(info, self.num_envs)
            for i in np.flatnonzero(dones):
                infos[i]["terminal_observation"] = info["final_obs"][i]
                self.reset_infos[i] = resets[i]
        else:
            infos = _split(info, self.num_envs)
        tl = (trunc & ~term).tolist()
        for i, d in enumerate(infos):
            d["TimeLimit.truncated"] = tl[i]
        return obs, rew.astype(np.float32), dones, infos

    def close(self) -> None:
        """Close the wrapped vector env."""
        self.venv.close()

    # ------------------------------------------------------------ attributes
    def get_attr(self, attr_name: str, indices=None) -> list:
        """Attribute of the vector env for each index (valve parameters per index)."""
        idx = list(self._get_indices(indices))
        if attr_name in VALVE_KEYS:
            arr = self.venv._valve[attr_name]
            return [float(arr[i]) for i in idx]
        value = getattr(self.venv, attr_name)
        return [value for _ in idx]



def _split(info: dict, n: int) -> list:
    """Vector info (dict of arrays with ``_key`` masks) to a list of n dicts of Python values."""
    keys = [k for k in info if not k.startswith("_") and k not in ("final_obs", "final_info")
            and f"_{k}" in info]
    cols = [info[k].tolist() for k in keys]
    masks = [info[f"_{k}"] for k in keys]
    out = [dict() for _ in range(n)]
    for k, col, m in zip(keys, cols, masks):
        if m.all():
            for d, v in zip(out, col):
                d[k] = v
        else:
            for i in np.flatnonzero(m):
                out[i][k] = col[i]
    return out


class SB3RegulationVecEnv(_OneVectorEnv, VecEnv):
    """The native regulation vector env (:class:`~valve_gym.envs.ValveTankRegulationVectorEnv`) as an SB3 ``VecEnv``.

    Parameters
    ----------
    num_envs : int
    config : RegulationTaskConfig, mapping or YAML path, optional

    Notes
    -----
    All sub-environments end together (one horizon); at the step that ends them ``infos[i]`` has
    ``terminal_observation``, ``TimeLimit.truncated`` (True) and the episode's benchmark scores ``R``,
    ``travel_vs_frictionless`` and ``lc_present``; on other steps the infos are empty (the per-loop
    signals are in :attr:`last_info`, a dict of ``(N,)`` arrays). ``seed(s)`` seeds sub-env ``i`` with
    ``s + i`` at the next reset, as :class:`~stable_baselines3.common.vec_env.DummyVecEnv` of
    ``gymnasium.make`` envs does: the observations and rewards are the same.

    Examples
    --------
    >>> from valve_gym.envs.sb3 import SB3RegulationVecEnv
    >>> venv = SB3RegulationVecEnv(num_envs=4, config={"episode_s": 60.0})
    >>> _ = venv.seed(0)
    >>> venv.reset().shape
    (4, 14)
    """

    def __init__(self, num_envs: int = 1, config=None, render_mode: str | None = None):
        from .regulation_env import ValveTankRegulationVectorEnv

        self.venv = ValveTankRegulationVectorEnv(num_envs, config, render_mode=render_mode)
        super().__init__(self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._actions = None
        self._started = False
        self.last_info: dict = {}

    def reset(self):
        """Reset all sub-environments with the pending seeds; returns ``(N, n_obs)`` observations."""
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        opts = [o for o in self._options if o]
        obs, info = self.venv.reset(seed=seeds, options=opts[0] if opts else None)
        return self._reset_done(obs, [{} for _ in range(self.num_envs)])

    def step_wait(self):
        """Step every loop; returns SB3's ``(obs, rewards, dones, infos)``."""
        self._check_started()
        obs, rew, term, trunc, info = self.venv.step(np.asarray(self._actions, dtype=np.float32))
        dones = term | trunc
        self.last_info = info
        if dones.any():
            fi, fo = info["final_info"], info["final_obs"]
            extra = [k for k in ("R", "travel_vs_frictionless", "lc_present") if k in fi]
            infos = [{"terminal_observation": fo[i], "TimeLimit.truncated": True,
                      **{k: float(fi[k][i]) for k in extra}} for i in range(self.num_envs)]
        else:
            infos = [{} for _ in range(self.num_envs)]
        return obs, rew.astype(np.float32), dones, infos

    def close(self) -> None:
        """Close the wrapped vector env."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list:
        """Attribute of the vector env (the same for every index)."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

