"""Natively vectorised level-control environment: N valve-tank loops in one kernel call.

Every :meth:`ValveTankVectorEnv.step` advances a :class:`valve_gym.plant.Plant`
of ``N`` loops by one scan (one call of the physics core,
:func:`valve_gym.core.run_packed`), followed by one compiled bookkeeping pass
(:func:`_finish_step`: noise, set-point and load schedules, reward,
observation); there is no per-environment Python loop in a step. The task
rules (episode draw, options, observation layout, action scaling, reward) are
those of :mod:`valve_gym.envs.task`, shared with
:class:`~valve_gym.envs.ValveTankEnv`. Only the per-episode draws at a reset
loop over the resetting sub-environments, each drawing from its own generator
(:func:`~valve_gym.envs.task.draw_episodes`), so that sub-environment ``i``
seeded with ``s_i`` is step-for-step equal to a single env reset with
``seed=s_i``.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import replace

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import core  # noqa: F401  (the physics core the plant calls; kept as this module's attribute)
from .._numba import HAVE_NUMBA, njit
from ..config import MAX_NUM_ENVS, EnvConfig, check_count
from ..control import pi_init, pi_step
from ..params import ValveParams
from ..plant import Plant
from . import task
from .task import (
    NEVER,
    VALVE_KEYS,
    TaskPlan,
    batch_actions,
    check_options,
    clip_actions,
    direct_inputs,
    draw_episodes,
    make_config,
    observations,
    parse_options,
    raise_nonfinite,
    residual_inputs,
    step_reward_nb,
    write_observation,
)
from .valve_tank import render_frame

__all__ = ["ValveTankVectorEnv"]

_MODES = {m.value: m for m in AutoresetMode}
_MODES.update({m.name: m for m in AutoresetMode})
_MODES.update({m.name.lower(): m for m in AutoresetMode})


@njit(cache=True)
def _finish_step(Y, Hs, LV, NOISE, k, H, sp_next, sp_ptr, sp_ev, sp_val, ld_next, ld_ptr, ld_ev,
                 ld_val, h_prev, u, u_prev, ce, wt, wu, obs, reward, ym, sp, load):  # pragma: no cover
    """Bookkeeping after the plant step, one pass over the batch (no physics here).

    Advances the step counters ``k`` and the set-point/load event pointers,
    adds the measurement noise, and writes the observations, the rewards and
    the new set point, measured level and load (for the next step). The
    reward and the observation are the compiled rules of :mod:`valve_gym.envs.task`
    (:func:`~valve_gym.envs.task.step_reward`, :func:`~valve_gym.envs.task.write_observation`),
    so every number is computed as ``ValveTankEnv.step`` computes it.
    """
    n = k.shape[0]
    for i in range(n):
        ki = k[i] + 1
        k[i] = ki
        kk = ki if ki < H else H
        while sp_next[i] <= kk:
            p = sp_ptr[i] + 1
            sp_ptr[i] = p
            sp_next[i] = sp_ev[i, p]
        while ld_next[i] <= kk:
            p = ld_ptr[i] + 1
            ld_ptr[i] = p
            ld_next[i] = ld_ev[i, p]
        s = sp_val[i, sp_ptr[i]]
        load[i] = ld_val[i, ld_ptr[i]]
        kn = ki if ki <= H else ki % (H + 1)
        y = Y[0, i] + NOISE[kn, i]
        h = Hs[0, i]
        reward[i] = step_reward_nb(s, LV[0, i], h, h_prev[i], u[i], u_prev[i], ce, wt, wu)
        ym[i] = y
        sp[i] = s
        write_observation(obs, i, y, s, u[i], h)


def _flush_stale_cache() -> None:
    """Drop numba's on-disk cache of `_finish_step` when :mod:`valve_gym.envs.task` is newer than it.

    numba keys the cache on this file only; the reward and observation rules it
    inlines live in ``task.py``, so an edit there would otherwise run a stale pass.
    """
    try:
        idx = _finish_step._cache._cache_file._index_path  # type: ignore[attr-defined]
        if os.path.exists(idx) and task.__file__ and os.path.getmtime(task.__file__) > os.path.getmtime(idx):
            _finish_step._cache.flush()  # type: ignore[attr-defined]
    except Exception:  # pragma: no cover - numba internals moved: keep the cache as numba decides
        pass


if HAVE_NUMBA:
    _flush_stale_cache()


def _transpose_into(dst, src, idx=None, block=256):
    """``dst[:, idx] = src.T`` in cache-sized blocks (much faster for large arrays)."""
    n = src.shape[0]
    for j0 in range(0, n, block):
        cols = slice(j0, j0 + block) if idx is None else idx[j0:j0 + block]
        dst[:, cols] = src[j0:j0 + block].T


class ValveTankVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~valve_gym.envs.ValveTankEnv`, simulated as one batch.

    Observations, actions, rewards, the reward rule, the episode draws and
    the info keys are those of the single environment (see its docstring),
    batched along the first axis: observations ``(N, 4)`` (``(N, 5)`` with
    ``measure_stem``) float32, actions ``(N, 1)`` float32 in [-1, 1], rewards
    ``(N,)`` float64, ``info`` a dict of ``(N,)`` arrays, each key ``k`` with
    Gymnasium's mask ``_k`` (all True: every key is always present).

    ## Description

    The task of :class:`~valve_gym.envs.ValveTankEnv` (``valve_gym/ValveTank-v0``, ``ValveTankFixed-v0``
    with ``preset='fixed'``) for ``N`` loops in one kernel call per step.

    ## Action Space

    ``Box(-1, 1, (N, 1), float32)``: the single env's action per sub-env.

    ## Observation Space

    ``Box((N, 4|5), float32)``: the single env's observation per sub-env.

    ## Rewards

    The single env's per-step reward (its docstring has the formula), per sub-env.

    ## Starting State

    As the single env; sub-env ``i`` reset with seed ``s + i`` equals the single env reset with ``s + i``.

    ## Episode End

    Truncation after ``max_episode_steps`` (600 registered); autoreset as ``autoreset_mode`` says.

    ## Arguments

    See Parameters.

    ## Version History

    * v0: initial version.

    Parameters
    ----------
    num_envs : int
        Number of sub-environments ``N``.
    config : EnvConfig, mapping, str or path, optional
        As for :class:`~valve_gym.envs.ValveTankEnv`.
    preset : {'default', 'fixed'}
    max_episode_steps : int, optional
        Truncation after this many steps (default ``config.episode_steps``;
        ``gymnasium.make_vec`` passes the registered limit).
    autoreset_mode : gymnasium.vector.AutoresetMode or str
        ``NEXT_STEP`` (default, as Gymnasium's own vector envs): the step
        after a truncation resets that sub-environment, ignores its action and
        returns its first observation with reward 0. ``SAME_STEP``: the
        sub-environment is reset within the truncating step; its final
        observation is ``info['final_obs'][i]`` and the step's info
        ``info['final_info']`` (with masks ``_final_obs``, ``_final_info``),
        while the returned observation and the top-level info are those of
        the new episode. ``DISABLED``: no autoreset; reset chosen
        sub-environments with ``reset(options={'reset_mask': mask})``.
    render_mode : {None, 'rgb_array'}
        ``render()`` returns a tuple of N frames.

    Notes
    -----
    **Seeding.** Each sub-environment owns a :class:`numpy.random.Generator`
    made like ``gymnasium.Env.reset(seed=...)`` makes its ``np_random``.
    ``reset(seed=s)`` seeds sub-environment ``i`` with ``s + i`` (as
    :class:`gymnasium.vector.SyncVectorEnv`); ``reset(seed=[s_0, ..., s_N-1])``
    seeds each (``None`` keeps a generator running); autoresets continue each
    generator. Sub-environment ``i`` then follows the trajectory of
    ``ValveTankEnv`` reset with ``seed=s_i`` and reset again without a seed at
    each episode end, step for step and bit for bit.

    **Options.** ``reset(options=...)`` pins valve parameters of the episodes
    starting now: ``{'z_max': 0.2}`` for all, or an ``(N,)`` array per
    sub-environment where NaN entries are drawn. ``'reset_mask'`` (``(N,)``
    bool) resets only the marked sub-environments.

    **Threads.** ``threads=2`` (or more) runs the plant of the sub-environments
    in that many column blocks at once (the compiled kernel releases the GIL);
    the results are bit for bit those of ``threads=1``. It pays for large ``N``
    (``benchmarks/bench_env_speed.py``).

    Attributes
    ----------
    config : EnvConfig
    substeps : int
        Euler steps per action.
    max_episode_steps : int
    model : ModelParams
        The physics of the current episodes, valve fields ``(N,)`` arrays.

    Examples
    --------
    >>> import numpy as np
    >>> from valve_gym.envs import ValveTankVectorEnv
    >>> envs = ValveTankVectorEnv(num_envs=3)
    >>> obs, info = envs.reset(seed=0, options={"z_max": [0.1, np.nan, 0.3]})
    >>> obs.shape, info["z_max"][[0, 2]].tolist()
    ((3, 4), [0.1, 0.3])
    >>> obs, rew, term, trunc, info = envs.step(np.zeros((3, 1), np.float32))
    >>> rew.shape, envs.substeps
    ((3,), 50)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10,
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, config: EnvConfig | Mapping | str | None = None, *,
                 preset: str = "default", max_episode_steps: int | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 render_mode: str | None = None, threads: int = 1):
        N, cfg, autoreset_mode, max_episode_steps = self._check_args(
            num_envs, config, preset, max_episode_steps, autoreset_mode, render_mode, threads)
        self.threads = int(threads)
        self.num_envs = N
        self.config = cfg
        self.max_episode_steps = int(max_episode_steps)
        self.autoreset_mode = autoreset_mode
        self.metadata = {**type(self).metadata, "autoreset_mode": autoreset_mode}
        self.render_mode = render_mode
        self._plan = TaskPlan(cfg)
        self.substeps = cfg.substeps
        self.episode_steps = cfg.episode_steps
        self.model = cfg.model
        self.residual = self._plan.residual
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, N)
        self.single_observation_space = task.observation_space(cfg)
        self.observation_space = batch_space(self.single_observation_space, N)
        self._nobs = self._plan.n_obs
        self._init_state(cfg, N)

    def _check_args(self, num_envs, config, preset, max_episode_steps, autoreset_mode, render_mode,
                    threads) -> tuple[int, EnvConfig, AutoresetMode, int]:
        """Check the arguments of ``__init__``: number of envs, config, autoreset mode, episode length."""
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        N = check_count("num_envs", num_envs, MAX_NUM_ENVS, "each environment holds its own plant and episode arrays")
        cfg = make_config(config, preset)
        if isinstance(autoreset_mode, str):
            if autoreset_mode not in _MODES:
                raise ValueError(f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, "
                                 f"got {autoreset_mode!r}")
            autoreset_mode = _MODES[autoreset_mode]
        if not isinstance(autoreset_mode, AutoresetMode):
            raise ValueError(f"autoreset_mode must be a gymnasium.vector.AutoresetMode, got {autoreset_mode!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if max_episode_steps is None:
            max_episode_steps = cfg.episode_steps
        if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, (int, np.integer)) \
                or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be a positive integer, got {max_episode_steps!r}")
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise ValueError(f"threads must be a positive integer (kernel threads per step; 1 = none), "
                             f"got {threads!r}")
        return N, cfg, autoreset_mode, int(max_episode_steps)

    def _init_state(self, cfg: EnvConfig, N: int) -> None:
        """Initial state, rewards' weights, schedules and per-env buffers of ``N`` sub-environments."""
        # the config and check_options() validate every valve an episode can have: no check per reset
        self._plant = Plant(cfg.model, N, scan_s=cfg.control_period, threads=self.threads, check=False)
        # the plant at rest (independent of the drawn friction parameters), restored at each reset
        rest = self._plant.reset(**self._plan.rest_levels())
        self._rest_state = self._plant.state
        self._h0 = float(rest.op[0])
        self._stem0 = float(rest.stem[0])
        self._level0 = float(rest.pv[0])
        self._y0 = float(rest.y[0])
        self._started = False
        H1 = self._plan.H + 1
        self._NOISE = np.zeros((H1, N))  # time-major: one row per step
        # piecewise-constant schedules: event steps (last column NEVER), values
        # (first column the initial value), number of events passed, next event step
        E = self._plan.E_sp
        self._sp_ev = np.full((N, E + 1), NEVER, dtype=np.int64)
        self._sp_val = np.zeros((N, E + 1))
        self._sp_ptr = np.zeros(N, dtype=np.int64)
        self._sp_next = np.full(N, NEVER, dtype=np.int64)
        E = self._plan.E_ld
        self._ld_ev = np.full((N, E + 1), NEVER, dtype=np.int64)
        self._ld_val = np.zeros((N, E + 1))
        self._ld_ptr = np.zeros(N, dtype=np.int64)
        self._ld_next = np.full(N, NEVER, dtype=np.int64)
        self._rngs: list = [None] * N
        self._valve = {k: np.zeros(N) for k in VALVE_KEYS}
        self._k = np.zeros(N, dtype=np.int64)
        self._sp = np.zeros(N)
        self._ym = np.zeros(N)
        self._lv = np.zeros(N)
        self._h = np.zeros(N)
        self._u = np.zeros(N)
        self._upi = np.zeros(N)
        self._load = np.zeros(N)
        self._pi = pi_init(np.full(N, self._h0), 0.0)
        self._autoreset = np.zeros(N, dtype=bool)
        self._level_max = 1.25 * cfg.setpoint.limits[1]
        keys = ("setpoint", "level", "stem", "u", "t", "load") + (("u_pi",) if self.residual else ()) + VALVE_KEYS
        self._mask_keys = tuple("_" + key for key in keys)   # Gymnasium's masks of the info keys

    # ----------------------------------------------------------------- seeding
    @property
    def np_randoms(self) -> list:
        """The generators of the sub-environments (``None`` before the first reset)."""
        return list(self._rngs)

    def _seed(self, seed, idx):
        N = self.num_envs
        if seed is None:
            seeds = [None] * N
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(N)]
        else:
            seeds = list(seed)  # type: ignore[arg-type]
            if len(seeds) != N:
                raise ValueError(f"seed must be None, an int or a sequence of {N} seeds (one per "
                                 f"sub-environment), got {len(seeds)} seeds")
        for i in idx:
            s = seeds[i]
            if s is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(None if s is None else int(s))

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict | None = None):
        """Reset all (or, with ``options['reset_mask']``, some) sub-environments.

        Returns
        -------
        obs : (N, 4|5) float32
        info : dict of (N,) arrays (see the class docstring)
        """
        N = self.num_envs
        options = dict(options) if options else {}
        mask = options.pop("reset_mask", None)
        if mask is None:
            idx = np.arange(N)
        else:
            mask = np.asarray(mask)
            if mask.shape != (N,) or mask.dtype != np.bool_:
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({N},), got "
                                 f"{mask.dtype} {mask.shape}")
            if not self._started and not mask.all():
                raise ValueError("the first reset must reset every sub-environment (no reset_mask)")
            idx = np.flatnonzero(mask)
        pins = parse_options(options, N, allow_nan=True)
        if pins:
            check_options({k: (v if v.ndim == 0 else v[idx]) for k, v in pins.items()}, self.config.model)
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool)
                      else None)
        self._seed(seed, idx)
        if idx.size:
            self._reset_envs(idx, pins)
        return self._obs_now(), self._info_now()

    def _reset_envs(self, idx: np.ndarray, pins=None):
        """Start new episodes in sub-environments ``idx``: draws, state at rest."""
        N = self.num_envs
        all_ = idx.size == N
        sub = None if not pins else {k: (v if v.ndim == 0 else v[idx]) for k, v in pins.items()}
        d = draw_episodes([self._rngs[i] for i in idx], self._plan, sub)
        for key in VALVE_KEYS:  # copy on write; read-only, so info can share them
            new = self._valve[key].copy()
            new[idx] = getattr(d, key)
            new.flags.writeable = False
            self._valve[key] = new
        self.model = replace(self.config.model, valve=ValveParams(**self._valve))
        self._plant.set_params(self.model)
        self._plant.set_state(self._rest_state, index=None if all_ else idx)
        self._started = True
        _transpose_into(self._NOISE, d.noise, None if all_ else idx)
        E = d.sp_steps.shape[1]
        self._sp_ev[idx, :E] = d.sp_steps
        self._sp_val[idx, 0] = d.sp_0
        self._sp_val[idx, 1:] = d.sp_vals
        self._sp_ptr[idx] = 0
        self._sp_next[idx] = d.sp_steps[:, 0]
        E = d.load_steps.shape[1]
        self._ld_ev[idx, :E] = d.load_steps
        self._ld_val[idx, 0] = 0.0
        self._ld_val[idx, 1:] = d.load_vals
        self._ld_ptr[idx] = 0
        self._ld_next[idx] = d.load_steps[:, 0]
        for nxt, ptr, ev in ((self._sp_next, self._sp_ptr, self._sp_ev),
                             (self._ld_next, self._ld_ptr, self._ld_ev)):
            while True:  # events due at step 0 (only with intervals below the control period)
                due = idx[nxt[idx] <= 0]
                if not due.size:
                    break
                ptr[due] += 1
                nxt[due] = ev[due, ptr[due]]
        self._k[idx] = 0
        self._autoreset[idx] = False
        # copy on write: arrays handed out in an info stay as they were
        ym = self._y0 + d.noise[:, 0]
        for name, val in (("_sp", self._sp_val[idx, self._sp_ptr[idx]]),
                          ("_load", self._ld_val[idx, self._ld_ptr[idx]]),
                          ("_ym", ym), ("_u", self._h0), ("_upi", self._h0),
                          ("_h", self._stem0), ("_lv", self._level0)):
            arr = getattr(self, name).copy()
            arr[idx] = val
            setattr(self, name, arr)
        if self.residual:
            u, e = self._pi.u.copy(), self._pi.e.copy()
            u[idx] = self._h0
            e[idx] = self._sp[idx] - ym
            self._pi = pi_init(u, e)

    def _obs_now(self):
        return observations(self._ym, self._sp, self._u, self._h, self._plan.measure_stem)

    def _info_now(self, load=None):
        """The info of the current state; ``load`` that of the step just taken.

        The arrays are never written to after they are handed out (the env
        replaces, rather than modifies, its arrays), so they need no copy.
        """
        info = {"setpoint": self._sp, "level": self._lv, "stem": self._h, "u": self._u,
                "t": self._k * self._plan.Tc, "load": self._load if load is None else load}
        if self.residual:
            info["u_pi"] = self._upi
        for key in VALVE_KEYS:
            info[key] = self._valve[key]
        info.update(dict.fromkeys(self._mask_keys, np.ones(self.num_envs, dtype=bool)))
        return info

    def _valve_inputs(self, actions):
        """Validate ``actions`` (N, 1) and turn them into the valve inputs ``u`` (N,) (and the PI's, residual mode)."""
        N = self.num_envs
        a = batch_actions(actions, N)
        u = np.empty(N)
        upi = None
        if self.residual:
            ac = np.empty(N)
            if clip_actions(a, ac):
                raise_nonfinite(actions)
            self._pi, upi = pi_step(self._pi, self._sp - self._ym, self._plan.pi_params)
            residual_inputs(upi, ac, self._plan.scale, u)
        elif direct_inputs(a, u):
            raise_nonfinite(actions)
        return u, upi

    # ------------------------------------------------------------------- step
    def step(self, actions):
        """Step all sub-environments with ``actions`` (N, 1) in [-1, 1] (clipped).

        Returns
        -------
        obs : (N, 4|5) float32
        rewards : (N,) float64
        terminated : (N,) bool, always False
        truncated : (N,) bool, True at ``max_episode_steps``
        info : dict of (N,) arrays (see the class docstring)
        """
        if not self._started:
            raise RuntimeError("call reset() before step()")
        N = self.num_envs
        plan = self._plan
        H = plan.H
        u, upi = self._valve_inputs(actions)
        load = self._load
        Y = np.empty((1, N))
        Hs = np.empty((1, N))
        LV = np.empty((1, N))
        self._plant.advance(u.reshape(1, N), load.reshape(1, N), (Y, Hs, LV))
        obs = np.empty((N, self._nobs), dtype=np.float32)
        reward = np.empty(N)
        ym = np.empty(N)
        sp = np.empty(N)
        new_load = np.empty(N)
        _finish_step(Y, Hs, LV, self._NOISE, self._k, H, self._sp_next, self._sp_ptr, self._sp_ev,
                     self._sp_val, self._ld_next, self._ld_ptr, self._ld_ev, self._ld_val, self._h, u,
                     self._u, plan.ce, plan.wt, plan.wu, obs, reward, ym, sp, new_load)
        k = self._k
        terminated = np.zeros(N, dtype=bool)
        truncated = k >= self.max_episode_steps
        self._ym, self._sp, self._load, self._lv, self._h, self._u = ym, sp, new_load, LV[0], Hs[0], u
        if upi is not None:
            self._upi = upi
        mode = self.autoreset_mode
        final = None
        reset_idx = None
        if mode is AutoresetMode.NEXT_STEP:
            if self._autoreset.any():
                reset_idx = np.flatnonzero(self._autoreset)
                self._reset_envs(reset_idx)
                reward[reset_idx] = 0.0
                truncated[reset_idx] = False
            self._autoreset = truncated.copy()
        elif mode is AutoresetMode.SAME_STEP:
            if truncated.any():
                reset_idx = np.flatnonzero(truncated)
                final = (obs, self._info_now(load), truncated.copy())
                self._reset_envs(reset_idx)
        if reset_idx is not None:
            obs = self._obs_now()
            # the sub-environments that were reset report their new episode
            load = load.copy()
            load[reset_idx] = self._load[reset_idx]
        info = self._info_now(load)
        if final is not None:
            fobs, finfo, done = final
            arr = np.full(N, None, dtype=object)
            for i in np.flatnonzero(done):
                arr[i] = fobs[i]
            for key in [k_ for k_ in finfo if not k_.startswith("_")]:
                finfo["_" + key] = done.copy()
            info["final_obs"] = arr
            info["_final_obs"] = done.copy()
            info["final_info"] = finfo
            info["_final_info"] = done.copy()
        return obs, reward, terminated, truncated, info

    # ----------------------------------------------------------------- render
    def render(self):
        """A tuple of N RGB frames (200, 160, 3) (``render_mode='rgb_array'``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; create the env with "
                            "render_mode='rgb_array'")
            return None
        if not self._started:
            raise RuntimeError("call reset() before render()")
        return tuple(render_frame(float(self._lv[i]), float(self._sp[i]), float(self._h[i]),
                                  float(self._u[i]), self._level_max) for i in range(self.num_envs))
