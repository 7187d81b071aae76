"""Regulation environments: constant set point, sticky valve, load and noise (single and native vector).

Both envs are thin shells over :class:`RegulationLoops`, which runs ``n`` loops with the rules of
the task module :mod:`valve_gym.envs.regulation` (draw, plants, block law, reward). A vector env
sub-env seeded with ``s`` is step-for-step the single env reset with ``seed=s``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..config import MAX_NUM_ENVS, check_count, load_config
from .regulation import (
    N_ACT,
    BlockLaw,
    LoopPlants,
    RegulationDraw,
    RegulationTaskConfig,
    _scan1,
    benchmark_reward,
    draw_scenarios,
    obs_names,
    parse_options,
    reference_runs,
    step_reward,
)

__all__ = ["ValveTankRegulationEnv", "ValveTankRegulationVectorEnv", "RegulationLoops", "make_regulation_config"]


def make_regulation_config(config: RegulationTaskConfig | Mapping | str | None = None) -> RegulationTaskConfig:
    """A :class:`RegulationTaskConfig` from a config, a mapping of keys or a YAML file (``None``: defaults)."""
    if isinstance(config, RegulationTaskConfig):
        return config
    return load_config(config, cls=RegulationTaskConfig)


def _apply_pins(d: RegulationDraw, pins: dict) -> RegulationDraw:
    if not pins:
        return d
    S = pins.get("S", d.S)
    if "J" in pins:
        J = pins["J"]
    else:
        J = S * np.where(d.S > 0, d.J / np.maximum(d.S, 1e-300), 0.0)
    return d._replace(model=pins.get("model", d.model), S=S, J=np.minimum(J, S), sp=pins.get("level", d.sp))


class RegulationLoops:
    """``n`` regulation loops: plants, block laws and the episode's draw, stepped together.

    Parameters
    ----------
    cfg : RegulationTaskConfig
    n : int
    """

    def __init__(self, cfg: RegulationTaskConfig, n: int):
        self.cfg = cfg
        self.n = int(n)
        self.H = cfg.steps
        self.draw: RegulationDraw | None = None

    def reset(self, rngs: Sequence[np.random.Generator], pins: dict | None = None) -> np.ndarray:
        """Start all loops at steady state; returns the observation (n, n_obs) float32.

        With the ``benchmark`` reward the references (:func:`~valve_gym.envs.regulation.reference_runs`)
        are run here, on the drawn episodes.
        """
        pins = dict(pins or {})
        free = pins.pop("frictionless", None)
        d = _apply_pins(draw_scenarios(rngs, self.cfg), pins)
        self.draw = d
        self.plants = LoopPlants(self.cfg, d, frictionless=free)
        self.law = BlockLaw(self.cfg.block, self.n)
        self.k = 0
        pv = self.plants.level + d.noise[:, 0]
        self.law.reset(d.sp, pv, self.plants.op0)
        if self.cfg.reward == "benchmark":
            self.refs = reference_runs(self.cfg, d)
            self.err = np.empty((self.H, self.n))
            self.travel = np.zeros(self.n)
            self.excess = np.zeros(self.n)
        self._one = None
        if self.n == 1 and len(self.plants.groups) == 1:      # the single env's compiled scan (step1)
            _idx, pk, S, buf, _U, _D, _out = self.plants.groups[0]
            self._one = (self.law.X, self.law.LP, S, pk.P, pk.flags, buf, self.plants.substeps, pk.dt,
                         np.zeros((5, 1)), self.law._obs)
            self._one_state = [float(self.plants.stem[0]), 0.0, 0.0]    # stem, travel, excess
            c = self.cfg
            self._one_lists = (d.load[0].tolist(), d.noise[0].tolist(), float(d.sp[0]))
            if c.reward == "benchmark":
                t0 = float(self.refs.travel_0[0])
                self._one_refs = (self.refs.abs_err_pi[0].tolist(), float(self.refs.denom[0]), t0,
                                  c.travel_budget * t0, c.budget_weight)
        return self.law.observe(d.sp, pv).astype(np.float32)

    def step(self, actions: np.ndarray):
        """One scan; returns ``(obs (n, n_obs) float32, reward (n,), truncated (bool), info dict of (n,))``."""
        d = self.draw
        if d is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(actions, dtype=float)
        if a.size != self.n * N_ACT:
            raise ValueError(f"actions must have shape ({self.n}, {N_ACT}) (gate, correction per loop), "
                             f"got an array of shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("an action is NaN or inf; pass numbers in [-1, 1] (check the policy for NaN "
                             "outputs, e.g. from diverging training)")
        k = self.k
        kk = min(k, self.H)
        u = self.law.act(a.reshape(self.n, N_ACT))
        stem0 = self.plants.stem.copy()
        load = d.load[:, kk]
        self.plants.step(u, load)
        self.k = k + 1
        kn = min(self.k, self.H)
        level = self.plants.level
        pv = level + d.noise[:, kn]
        info = {"setpoint": d.sp.copy(), "level": level.copy(), "pv": pv, "stem": self.plants.stem.copy(),
                "op": u, "load": load.copy(), "t": np.full(self.n, self.k * self.cfg.block.scan_s)}
        if self.cfg.reward == "benchmark":
            reward = self._benchmark_reward(k, d.sp - pv, self.plants.stem - stem0, info)
        else:
            reward = step_reward(self.cfg, d.sp - level, self.plants.stem - stem0)
        obs = self.law.observe(d.sp, pv).astype(np.float32)
        return obs, reward, self.k >= self.H, info

    def step1(self, action):
        """:meth:`step` of one loop (``n == 1``) in one compiled call, the numbers of :meth:`step` bit for bit.

        Returns ``(obs (n_obs,), reward, truncated, info of floats)``.
        """
        one = self._one
        if one is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=float)
        if a.size != N_ACT:
            raise ValueError(f"actions must have shape ({self.n}, {N_ACT}) (gate, correction per loop), "
                             f"got an array of shape {np.shape(action)}")
        a = a.reshape(1, N_ACT)
        if not (math.isfinite(a[0, 0]) and math.isfinite(a[0, 1])):
            raise ValueError("an action is NaN or inf; pass numbers in [-1, 1] (check the policy for NaN "
                             "outputs, e.g. from diverging training)")
        H = self.H
        k = self.k
        kk = k if k < H else H
        X, LP, S, P, flags, buf, n_sub, dt, W, obs = one
        law = self.law
        loads, noises, sp = self._one_lists
        load = loads[kk]
        self.k = k + 1
        kn = self.k if self.k < H else H
        u, level, stem, pv = _scan1(X, LP, a, law._first, S, P, flags, buf, n_sub, dt, W, load, noises[kn], sp, obs)
        law._first = False
        self.plants.level[0] = level
        self.plants.stem[0] = stem
        st = self._one_state
        dh = stem - st[0]
        st[0] = stem
        info = {"setpoint": sp, "level": level, "pv": pv, "stem": stem, "op": u, "load": load,
                "t": self.k * self.cfg.block.scan_s}
        if self.cfg.reward == "benchmark":
            if k >= H:
                r = 0.0
            else:
                e = sp - pv
                self.err[k, 0] = e
                st[1] = st[1] + abs(dh)
                err_pi, denom, t0, budget, wb = self._one_refs
                excess = max(st[1] - budget, 0.0)
                r = (err_pi[k] - abs(e)) / denom - wb * (excess - st[2]) / t0
                st[2] = excess
                self.travel[0], self.excess[0] = st[1], excess
                if k == H - 1:
                    extra: dict = {}
                    lc = self._last_scan(extra)
                    r = r - self.cfg.lc_weight * float(lc[0])
                    info.update({key: float(v[0]) for key, v in extra.items()})
        else:
            r = -(abs(sp - level) / self.cfg.error_scale + self.cfg.travel_weight * abs(dh))
        return obs[0].astype(np.float32), float(r), self.k >= H, info

    def _last_scan(self, info: dict) -> np.ndarray:
        """The limit-cycle verdict of the episode's error (per loop).

        Puts ``R``, ``travel_vs_frictionless`` and ``lc_present`` into ``info``.
        """
        from valve_gym.oscillation import detect_oscillation

        scan = self.cfg.block.scan_s
        lc = np.array([detect_oscillation(self.err[:, i], scan, "benchmark").present for i in range(self.n)])
        refs = self.refs
        info["R"] = (refs.iae_pi - np.abs(self.err).sum(axis=0)) / refs.denom
        info["travel_vs_frictionless"] = self.travel / refs.travel_0
        info["lc_present"] = np.asarray(lc, float)
        return lc

    def _benchmark_reward(self, k: int, e: np.ndarray, dh: np.ndarray, info: dict) -> np.ndarray:
        """The ``benchmark`` reward of scan ``k`` (error ``e = SP - PV`` after it, stem move ``dh``).

        On the last scan of the episode ``info`` gets the episode's ``R``, ``travel_vs_frictionless``
        and ``lc_present`` (the benchmark's scores of the episode).
        """
        if k >= self.H:
            return np.zeros(self.n)
        self.err[k] = e
        self.travel += np.abs(dh)
        lc = self._last_scan(info) if k == self.H - 1 else None
        r, self.excess = benchmark_reward(self.cfg, self.refs, k, np.abs(e), self.excess, self.travel, lc)
        return r

    def episode_info(self) -> dict:
        """The drawn quantities of the episode (friction model name, ``S``, ``J``, set point)."""
        d = self.draw
        assert d is not None
        return {"friction_model": np.array([self.cfg.friction_models[i] for i in d.model]),
                "S": d.S.copy(), "J": d.J.copy(), "setpoint": d.sp.copy()}


def _spaces(cfg: RegulationTaskConfig):
    obs = spaces.Box(-10.0, 10.0, shape=(len(obs_names(cfg.block)),), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, shape=(N_ACT,), dtype=np.float32)
    return obs, act


class ValveTankRegulationEnv(gym.Env):
    r"""Regulation of a level loop through a sticky valve by a learned DCS block: the benchmark's regulation task.

    ## Description

    The default tank (:class:`valve_gym.params.TankParams`) at a constant set point, fed through a
    valve with stiction, disturbed by an Ornstein-Uhlenbeck load inflow and white measurement noise,
    started at steady state: the regulation part of the compensator benchmark
    (:mod:`valve_gym.agents.bench`, ``configs/benchmark.yaml``) as a family that contains it. Per
    episode: friction model uniform in the benchmark's ``riihilahti``, ``choudhury``, ``kano``; band
    healthy / sticky / severe with the benchmark's weights 30 : 60 : 45 and ``S`` uniform in
    [0, 0.5] %, log-uniform in [0.5, 5] %, uniform in [5, 10] % of stroke; ``J`` uniform in [0, S];
    set point uniform in [0.6, 1.4] m (benchmark: 0.6, 1.0, 1.4); noise std uniform in [0.3, 3] mm
    (benchmark: 2 mm); load std in [0.05, 0.2] L/s (benchmark: 0.1) and correlation time
    log-uniform in [60, 300] s (benchmark: 120 s). The agent is the inside of a PI block
    (:class:`~valve_gym.envs.regulation.BlockLaw`): it gates the integrator and adds a bounded
    correction to the output, so the block keeps integral action whatever the agent does.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: integrator gate ``a_g`` and correction ``a_c``:
    ``u = clip(Kc e + I + c_max a_c)``, ``I += g Kc Ts / Ti e`` with ``g = g_min + (1 - g_min)(a_g + 1)/2``
    (:mod:`valve_gym.envs.regulation`); ``(1, 0)`` is the plain SIMC PI. Clipped; NaN raises.

    ## Observation Space

    ``Box(-10, 10, (14,), float32)``: what a DCS block sees, computed from SP, PV and the block's own
    past output only, never the stem or the friction: the error and its moving averages, a noise
    estimate, the output's moves, the last action, and the stickiness features (output move and time
    since the filtered error last turned, filtered error over noise); names in
    :data:`~valve_gym.envs.regulation.OBS_NAMES` + :data:`~valve_gym.envs.regulation.STICK_OBS_NAMES`
    (11 without ``block.stick_features``).

    ## Rewards

    Aligned with the benchmark's score (``reward: benchmark``, :func:`~valve_gym.envs.regulation.benchmark_reward`).
    At reset the env runs the benchmark's two references on the episode's noise and load: the SIMC PI
    on the sticky valve (error ``e^PI``) and on the frictionless valve (IAE ``IAE_0``, travel ``T_0``).
    Per scan, with ``e_k = SP - PV`` after the scan and ``T_k`` the stem travel so far:

    .. math::

        r_k = \frac{|e^{PI}_k| - |e_k|}{D} - w_b \frac{x_k - x_{k-1}}{T_0} - w_{lc}\,[LC]_{k=H-1},
        \quad x_k = \max(0, T_k - \beta T_0),\quad D = \max(IAE_{PI} - IAE_0, f\,IAE_0)

    so that the return is :math:`G = R - w_b \max(0, T/T_0 - \beta) - w_{lc}[LC]`: the episode's
    compensation ratio ``R`` (1: stiction's whole IAE cost removed, 0: the PI, < 0: worse), minus the
    stem travel beyond ``beta = 1.5`` times the frictionless PI's (``w_b = 1``), minus 0.5 if the
    benchmark's limit-cycle detector fires on the episode's error (last scan). The plain PI scores 0,
    the PI on a frictionless valve 1. ``reward: tracking`` gives v0's ``-(|SP - L| / error_scale +
    travel_weight |dh|)``.

    ## Starting State

    Steady state at the set point with the valve at the steady input (stuck, friction state 0).

    ## Episode End

    Truncation after ``episode_s / scan_s`` scans (1800 by default, the registration's time limit);
    never terminated. The last step's ``info`` has the episode's ``R``, ``travel_vs_frictionless`` and
    ``lc_present``.

    ## Arguments

    config : RegulationTaskConfig, mapping or YAML path, optional
        The task (:class:`~valve_gym.envs.regulation.RegulationTaskConfig`): ranges of the draw, reward
        weights, block settings.
    render_mode : {None, 'rgb_array'}, optional

    ``reset(options={'model': 'choudhury', 'S': 0.03, 'J': 0.01, 'level': 1.0, 'frictionless': False})``
    pins any subset. ``info`` has ``setpoint``, ``level``, ``pv``, ``stem``, ``op``, ``load``, ``t``
    and, at reset, ``friction_model``, ``S``, ``J``.

    ## Version History

    * v0 (this release): the default task became the benchmark's regulation part (Kano's model added,
      band weights and log-uniform sticky band, 0.3-3 mm noise, the 14 observations with the
      stickiness features) and the reward the benchmark-aligned one; ``render_mode='rgb_array'``.
      The id keeps ``-v0`` as no release published the earlier default; ``RegulationTaskConfig(
      friction_models=('riihilahti', 'choudhury'), noise_std=(0.002, 0.002), band_weights=(1, 1, 1),
      S_log_uniform=(False, False, False), reward='tracking', block=BlockSettings())`` is the earlier one.
    * v0 (first): two friction models, 2 mm noise, 11 observations, tracking reward.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: RegulationTaskConfig | Mapping | str | None = None, render_mode: str | None = None):
        self.render_mode = _check_render(render_mode, self.metadata)
        self.config = make_regulation_config(config)
        self.observation_space, self.action_space = _spaces(self.config)
        self._loops = RegulationLoops(self.config, 1)
        self.episode_steps = self.config.steps

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode at steady state (see the class docstring for ``options``)."""
        pins = parse_options(options, self.config, 1)
        super().reset(seed=seed)
        obs = self._loops.reset([self.np_random], pins)
        info = {k: (v[0].item() if hasattr(v[0], "item") else v[0]) for k, v in self._loops.episode_info().items()}
        return obs[0], info

    def step(self, action):
        """One scan: returns ``(obs, reward, False, truncated, info)``."""
        loops = self._loops
        if getattr(loops, "_one", None) is not None:
            obs, r, trunc, info = loops.step1(action)
            return obs, r, False, trunc, info
        obs, r, trunc, info = loops.step(np.asarray(action, dtype=float).reshape(1, -1)
                                         if np.size(action) == N_ACT else np.asarray(action, dtype=float))
        return obs[0], float(r[0]), False, bool(trunc), {k: float(v[0]) for k, v in info.items()}

    def render(self):
        """An RGB frame (200, 160, 3) of tank, set point, valve output and stem (``render_mode='rgb_array'``)."""
        return _render(self, 0)


def _check_render(render_mode, metadata) -> str | None:
    """``render_mode`` if it is None or one of ``metadata['render_modes']``, else a one-line ValueError."""
    if render_mode is not None and render_mode not in metadata["render_modes"]:
        raise ValueError(f"render_mode must be None or one of {metadata['render_modes']}, got {render_mode!r}")
    return render_mode


def _render(env, i: int):
    """Frame of loop ``i`` of ``env._loops`` (None, with a warning, without a render mode)."""
    from .valve_tank import render_frame

    if env.render_mode is None:
        gym.logger.warn("render() called without a render_mode; create the env with render_mode='rgb_array'")
        return None
    loops = env._loops
    if loops.draw is None:
        raise RuntimeError("call reset() before render()")
    lv_max = 1.25 * max(loops.cfg.levels[1], 1.6)
    return render_frame(float(loops.plants.level[i]), float(loops.draw.sp[i]), float(loops.plants.stem[i]),
                        float(loops.law.u[i]), lv_max)


class ValveTankRegulationVectorEnv(VectorEnv):
    """``num_envs`` regulation loops in one batch (native vector env of ``ValveTankRegulation-v0``).

    All sub-environments share the horizon, so they end together; autoreset is ``SAME_STEP``:
    the step that truncates returns the first observation of the next episodes, with the last
    ones in ``info['final_obs']``. Sub-env ``i`` reset with ``seed=s`` (int) is seeded ``s + i``;
    a list gives each its seed; generators continue across autoresets.

    ## Description

    The task of :class:`ValveTankRegulationEnv` for ``num_envs`` loops, one compiled block-law call
    and one plant call per friction model per step.

    ## Action Space

    ``Box(-1, 1, (N, 2), float32)``: gate and correction per sub-env.

    ## Observation Space

    ``Box(-10, 10, (N, 14), float32)``: the block's observation per sub-env.

    ## Rewards

    :class:`ValveTankRegulationEnv`'s (the return is the episode's ``R`` minus the travel-budget and
    limit-cycle penalties), per sub-env; the truncating step's ``info['final_info']`` has ``R``,
    ``travel_vs_frictionless`` and ``lc_present``.

    ## Starting State

    Steady state; sub-env ``i`` with seed ``s`` equals the single env reset with ``seed=s``.

    ## Episode End

    Truncation of all sub-envs together after ``episode_s / scan_s`` scans (1800).

    ## Arguments

    num_envs : int
    config : RegulationTaskConfig, mapping or YAML path, optional
    max_episode_steps : int, optional (must equal the config's episode)
    render_mode : {None, 'rgb_array'}

    ## Version History

    * v0: as :class:`ValveTankRegulationEnv`'s.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10, "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int = 1, config: RegulationTaskConfig | Mapping | str | None = None,
                 max_episode_steps: int | None = None, render_mode: str | None = None):
        self.render_mode = _check_render(render_mode, self.metadata)
        if not (isinstance(num_envs, (int, np.integer)) and num_envs >= 1):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        self.config = make_regulation_config(config)
        if max_episode_steps is not None and int(max_episode_steps) != self.config.steps:
            raise ValueError(f"max_episode_steps = {max_episode_steps} differs from the task's episode "
                             f"({self.config.steps} scans); set the config's episode_s instead")
        self.num_envs = check_count("num_envs", num_envs, MAX_NUM_ENVS, "each loop holds its own plant and arrays")
        self.single_observation_space, self.single_action_space = _spaces(self.config)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._loops = RegulationLoops(self.config, self.num_envs)
        self._rngs = [seeding.np_random(None)[0] for _ in range(self.num_envs)]
        self.episode_steps = self.config.steps

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        """Reset all sub-envs; ``options`` as the single env's (scalars or ``(num_envs,)`` arrays)."""
        pins = parse_options(options, self.config, self.num_envs)
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, (int, np.integer)) else list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed must be an int or a list of {self.num_envs} seeds, got {len(seeds)}")
            self._rngs = [seeding.np_random(None if s is None else int(s))[0] for s in seeds]
        obs = self._loops.reset(self._rngs, pins)
        return obs, self._loops.episode_info()

    def step(self, actions):
        """One scan of every loop; returns ``(obs, rewards, terminated, truncated, infos)``."""
        obs, r, trunc, info = self._loops.step(actions)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.full(self.num_envs, bool(trunc))
        if trunc:
            info["final_obs"] = obs
            info["final_info"] = dict(info)
            obs = self._loops.reset(self._rngs)
            info.update({f"next_{k}": v for k, v in self._loops.episode_info().items()})
        return obs, r, terminated, truncated, info

    def render(self):
        """A tuple of one RGB frame (200, 160, 3) per sub-env (``render_mode='rgb_array'``)."""
        if self.render_mode is None:
            return _render(self, 0)
        return tuple(_render(self, i) for i in range(self.num_envs))
