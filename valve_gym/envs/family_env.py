"""The regulation task over the randomised training family of ``learned`` (``ValveFamilyRegulation-v0``).

Each episode is one loop of :func:`valve_gym.agents.adaptive_train.draw_loop` (the family the adaptive
compensator is trained on: Torricelli, integrating and first-order processes; Riihilahti's, Choudhury's and
Kano's friction models, Karnopp's held out; healthy, sticky and severe bands; scans of 0.5, 1 and 2 s;
constant plus Ornstein-Uhlenbeck loads; 0.5-3 mm of noise; SIMC tuning of each loop), simulated by the
package's physics core (:class:`valve_gym.plant.Plant`). The agent acts through the regulation block
(:class:`valve_gym.envs.regulation.BlockLaw`) tuned with the loop's own ``Kc``, ``Ti`` and scan; the error
scale of the observation is ``e_ref = e_stroke / Kc`` (the error whose proportional action is ``e_stroke``
of stroke), so that the observation means the same on every plant and a trained policy runs on any loop
given only that loop's ``Kc``, ``Ti`` and ``scan_s`` (:meth:`FamilyConfig.block_for`). The reward is the
regulation env's benchmark-aligned one (:func:`~valve_gym.envs.regulation.benchmark_reward`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import SyncVectorEnv

from ..config import ConfigError, load_config
from .regulation import (
    N_ACT,
    BlockLaw,
    BlockSettings,
    References,
    RegulationTaskConfig,
    benchmark_reward,
    check_reward_numbers,
    obs_names,
    pi_action,
)

__all__ = ["FAMILY_ID", "FamilyConfig", "ValveFamilyRegulationEnv", "ValveFamilyRegulationVectorEnv",
           "make_family_config"]

#: The registered id.
FAMILY_ID = "valve_gym/ValveFamilyRegulation-v0"
#: The benchmark tank's tuning (``BlockSettings()``): the block settings stored with an export.
_DEFAULT_LOOP = (1.89, 42.4, 1.0)


@dataclass(frozen=True)
class FamilyConfig:
    """The family regulation task.

    Parameters
    ----------
    steps : int
        Scans per episode (whatever the loop's scan: 600-2400 s with 1200 scans).
    e_stroke : float, fraction of stroke
        Error scale of the observation as proportional action: ``e_ref = e_stroke / Kc`` (0.01 gives 5.3 mm
        on the benchmark tank, the regulation env's 5 mm).
    u_ref : float, fraction of stroke
        Output scale of the observation.
    c_max : float, fraction of stroke
        Bound of the block's correction.
    g_min : float
        Smallest integrator gate.
    r_floor, travel_budget, budget_weight, lc_weight : float
        The benchmark reward's settings (:class:`~valve_gym.envs.regulation.RegulationTaskConfig`).
    """

    steps: int = 1200
    e_stroke: float = 0.01
    u_ref: float = 0.02
    c_max: float = 0.08
    g_min: float = 0.05
    r_floor: float = 0.1
    travel_budget: float = 1.5
    budget_weight: float = 1.0
    lc_weight: float = 0.5

    def __post_init__(self):
        if not (isinstance(self.steps, int) and 64 <= self.steps <= 100_000):
            raise ConfigError(f"steps must be an integer in [64, 100000] (scans per episode), got {self.steps!r}")
        check_reward_numbers(self, ("e_stroke", "u_ref", "r_floor", "travel_budget"))
        self.block_for(*_DEFAULT_LOOP)           # c_max, g_min checked by BlockSettings

    def block_for(self, Kc: float, Ti: float, scan_s: float) -> BlockSettings:
        """The block settings of a loop with PI tuning ``Kc`` [1/pv], ``Ti`` [s] and scan ``scan_s`` [s]."""
        Kc = float(Kc)
        if not (math.isfinite(Kc) and Kc > 0):
            raise ValueError(f"Kc must be a positive number (the loop's PI gain), got {Kc!r}")
        return BlockSettings(Kc=Kc, Ti=float(Ti), scan_s=float(scan_s), c_max=self.c_max, g_min=self.g_min,
                             e_ref=self.e_stroke / Kc, u_ref=self.u_ref, stick_features=True)

    @property
    def block(self) -> BlockSettings:
        """The block settings on the benchmark tank (``Kc`` 1.89 /m, ``Ti`` 42.4 s, 1-s scan)."""
        return self.block_for(*_DEFAULT_LOOP)


def make_family_config(config: FamilyConfig | Mapping | str | None = None) -> FamilyConfig:
    """A :class:`FamilyConfig` from a config, a mapping of keys or a YAML file (``None``: defaults)."""
    if isinstance(config, FamilyConfig):
        return config
    return load_config(config, cls=FamilyConfig)


class _Episode:
    """One drawn loop: its row, signals, plants, block law and references."""

    def __init__(self, cfg: FamilyConfig, rng: np.random.Generator, frictionless: bool):
        from valve_gym.agents.adaptive_train import TrainLoops, _plants, draw_loop

        H = cfg.steps
        row, load, noise = draw_loop(rng, steps=H + 1)
        self.row, self.load, self.noise = row, load, noise
        self.scan = float(row["scan"])
        loops = TrainLoops((row,), (load,), (noise,))
        idx = np.array([0])
        self.settings = cfg.block_for(row["Kc"], row["Ti"], self.scan)
        # references: the SIMC PI on the sticky and on the frictionless valve, same noise and load
        refs = _plants(loops, idx, 2, np.array([False, True]), self.scan)
        err = np.empty((2, H))
        travel = np.zeros(2)
        for cols, plant, lv in refs:
            c = int(cols[0])
            err[c], travel[c] = self._run_pi(plant, lv, H)
        self.refs = References(err[:1], err[1:].sum(axis=1), travel[1:], cfg.r_floor)
        ((_, self.plant, lv),) = _plants(loops, idx, 1, np.array([bool(frictionless)]), self.scan)
        out = self.plant.reset(level=lv)
        self.sp = np.asarray(out.pv, float).copy()
        self.level = self.sp.copy()
        self.stem = np.asarray(out.stem, float).copy()
        self.op0 = np.asarray(out.op, float).copy()
        self.law = BlockLaw(self.settings, 1)
        self.law.reset(self.sp, self.sp + noise[0], self.op0)

    def _run_pi(self, plant, lv, H: int) -> tuple[np.ndarray, float]:
        out = plant.reset(level=lv)
        sp = np.asarray(out.pv, float).copy()
        stem = float(out.stem[0])
        law = BlockLaw(self.settings, 1)
        law.reset(sp, sp + self.noise[0], out.op)
        law.observe(sp, sp + self.noise[0])
        a = pi_action(1)
        err = np.empty(H)
        travel = 0.0
        for k in range(H):
            o = plant.step(law.act(a), self.load[k:k + 1])
            travel += abs(float(o.stem[0]) - stem)
            stem = float(o.stem[0])
            pv = o.pv + self.noise[k + 1]
            err[k] = abs(float(sp[0] - pv[0]))
            law.observe(sp, pv)
        return err, travel


def _spaces():
    obs = spaces.Box(-10.0, 10.0, shape=(len(obs_names(BlockSettings(stick_features=True))),), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, shape=(N_ACT,), dtype=np.float32)
    return obs, act


def _check_render(render_mode, metadata) -> str | None:
    if render_mode is not None and render_mode not in metadata["render_modes"]:
        raise ValueError(f"render_mode must be None or one of {metadata['render_modes']}, got {render_mode!r}")
    return render_mode


class ValveFamilyRegulationEnv(gym.Env):
    r"""Regulation through a sticky valve on a randomised family of plants, by a learned DCS block.

    ## Description

    Each episode draws one loop of the training family of the adaptive compensator
    (:func:`valve_gym.agents.adaptive_train.draw_loop`): a Torricelli tank (area 0.1-1 m^2, full flow
    5-30 L/s, level 0.5-1.5 m), an integrating (pumped-outlet) tank (area 0.3-2 m^2) or a first-order
    process (``K`` 1-3, ``T`` 3-30 s), operating opening 0.3-0.7; a valve of Riihilahti's, Choudhury's or
    Kano's friction model (Karnopp's is held out) with ``S`` healthy (0-0.5 %), sticky (0.5-5 %,
    log-uniform) or severe (5-10 %), ``J`` in [0, S] and a stem lag of 0.1-1.5 s; a scan of 0.5, 1 or 2 s;
    a constant load of 0.2-3 % of full flow plus an Ornstein-Uhlenbeck load (small or large, correlation
    time 60-300 s); measurement noise 0.5-3 mm; the loop's PI tuned by SIMC from its linear model. The
    agent is the inside of the loop's PI block (:class:`~valve_gym.envs.regulation.BlockLaw` with the
    loop's ``Kc``, ``Ti`` and scan).

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: integrator gate and correction, as in
    ``valve_gym/ValveTankRegulation-v0`` (``(1, 0)`` is the loop's plain SIMC PI). Clipped; NaN raises.

    ## Observation Space

    ``Box(-10, 10, (14,), float32)``: the regulation block's 14 observations (SP, PV and its own output
    only), with the error scale ``e_ref = e_stroke / Kc`` of the loop (``FamilyConfig.block_for``), so that
    an error reads as the proportional action it causes whatever the plant's units and gain.

    ## Rewards

    The regulation env's benchmark-aligned reward (:func:`~valve_gym.envs.regulation.benchmark_reward`)
    against the loop's references run at reset (the SIMC PI on the sticky and on the frictionless valve,
    same noise and load): the return is ``R - w_b max(0, T / T_0 - beta) - w_lc [LC]`` (``R``: the
    compensation ratio, 0 for the PI, 1 for the frictionless PI).

    ## Starting State

    Steady state at the set point (the operating level) with the valve resting at the steady opening.

    ## Episode End

    Truncation after ``steps`` scans (1200, the registration's time limit); never terminated. The last
    step's ``info`` has ``R``, ``travel_vs_frictionless`` and ``lc_present``.

    ## Arguments

    config : FamilyConfig, mapping or YAML path, optional
    render_mode : {None, 'rgb_array'}, optional

    ``reset(options={'frictionless': True})`` runs the episode on the loop's frictionless valve.
    ``info`` at reset: ``kind``, ``band``, ``friction_model``, ``S``, ``J``, ``scan_s``, ``Kc``, ``Ti``,
    ``noise_std``, ``setpoint``; per step ``setpoint``, ``pv``, ``stem``, ``op``, ``load``, ``t``.

    ## Version History

    * v0: first version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: FamilyConfig | Mapping | str | None = None, render_mode: str | None = None):
        self.render_mode = _check_render(render_mode, self.metadata)
        self.config = make_family_config(config)
        self.observation_space, self.action_space = _spaces()
        self.episode_steps = self.config.steps
        self._ep: _Episode | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Draw a loop and start it at steady state (``options``: ``{'frictionless': bool}``)."""
        free = False
        if options is not None:
            if not hasattr(options, "items") or any(k != "frictionless" for k in options):
                raise ValueError(f"reset options of {FAMILY_ID}: only {{'frictionless': true/false}}, got {options!r}")
            free = options.get("frictionless", False)
            if not isinstance(free, (bool, np.bool_)):
                raise ValueError(f"reset option 'frictionless' must be true/false, got {free!r}")
        super().reset(seed=seed)
        ep = _Episode(self.config, self.np_random, bool(free))
        self._ep = ep
        self._k = 0
        self._err = np.empty((self.config.steps, 1))
        self._travel = np.zeros(1)
        self._excess = np.zeros(1)
        obs = ep.law.observe(ep.sp, ep.sp + ep.noise[0])
        r = ep.row
        info = {"kind": r["kind"], "band": r["band"], "friction_model": r["model"], "S": float(r["S"]),
                "J": float(r["J"]), "scan_s": ep.scan, "Kc": float(r["Kc"]), "Ti": float(r["Ti"]),
                "noise_std": float(r["noise"]), "setpoint": float(ep.sp[0])}
        return obs[0].astype(np.float32), info

    def step(self, action):
        """One scan: returns ``(obs, reward, False, truncated, info)``."""
        ep = self._ep
        if ep is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=float)
        if a.size != N_ACT:
            raise ValueError(f"action must have shape ({N_ACT},) (gate, correction), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("an action is NaN or inf; pass numbers in [-1, 1] (check the policy for NaN outputs)")
        H = self.config.steps
        k = self._k
        kk = min(k, H - 1)
        u = ep.law.act(a.reshape(1, N_ACT))
        o = ep.plant.step(u, ep.load[kk:kk + 1])
        dh = np.abs(o.stem - ep.stem)
        ep.stem, ep.level = np.asarray(o.stem, float).copy(), np.asarray(o.pv, float).copy()
        self._k = k + 1
        pv = ep.level + ep.noise[min(self._k, H)]
        info: dict[str, Any] = {"setpoint": float(ep.sp[0]), "pv": float(pv[0]), "stem": float(ep.stem[0]),
                                "op": float(u[0]), "load": float(ep.load[kk]), "t": self._k * ep.scan}
        if k < H:
            e = ep.sp - pv
            self._err[k] = e
            self._travel += dh
            lc = None
            if k == H - 1:
                from valve_gym.oscillation import detect_oscillation

                lc = np.array([detect_oscillation(self._err[:, 0], ep.scan, "benchmark").present])
                info["R"] = float((ep.refs.iae_pi[0] - np.abs(self._err).sum()) / ep.refs.denom[0])
                info["travel_vs_frictionless"] = float(self._travel[0] / ep.refs.travel_0[0])
                info["lc_present"] = float(lc[0])
            r, self._excess = benchmark_reward(cast(RegulationTaskConfig, self.config), ep.refs, k, np.abs(e),
                                               self._excess, self._travel, lc)
            reward = float(r[0])
        else:
            reward = 0.0
        obs = ep.law.observe(ep.sp, pv)
        return obs[0].astype(np.float32), reward, False, self._k >= H, info

    def render(self):
        """An RGB frame (200, 160, 3) of the loop: PV, set point, valve output and stem."""
        from .valve_tank import render_frame

        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; create the env with render_mode='rgb_array'")
            return None
        ep = self._ep
        if ep is None:
            raise RuntimeError("call reset() before render()")
        u = float(ep.law.state_arrays()["u"][0])
        return render_frame(float(ep.level[0]), float(ep.sp[0]), float(ep.stem[0]), u, 1.25 * max(float(ep.sp[0]), 1.6))


class ValveFamilyRegulationVectorEnv(SyncVectorEnv):
    """``num_envs`` family regulation loops stepped one after the other (each loop has its own scan).

    ## Description

    :class:`ValveFamilyRegulationEnv` ``num_envs`` times in a Gymnasium ``SyncVectorEnv`` (the loops differ
    in scan time and plant, so they are not batched); sub-env ``i`` reset with ``seed=s`` is seeded ``s + i``.

    ## Action Space

    ``Box(-1, 1, (N, 2), float32)``.

    ## Observation Space

    ``Box(-10, 10, (N, 14), float32)``.

    ## Rewards

    :class:`ValveFamilyRegulationEnv`'s, per sub-env.

    ## Starting State

    Steady state, as the single env's.

    ## Episode End

    Truncation after ``steps`` scans; autoreset as ``SyncVectorEnv``'s (next step).

    ## Arguments

    num_envs : int
    config : FamilyConfig, mapping or YAML path, optional
    max_episode_steps : int, optional (must equal the config's ``steps``)
    render_mode : {None, 'rgb_array'}

    ## Version History

    * v0: first version.
    """

    def __init__(self, num_envs: int = 1, config: FamilyConfig | Mapping | str | None = None,
                 max_episode_steps: int | None = None, render_mode: str | None = None):
        _check_render(render_mode, ValveFamilyRegulationEnv.metadata)
        if not (isinstance(num_envs, (int, np.integer)) and 1 <= num_envs <= 4096):
            raise ValueError(f"num_envs must be an integer in [1, 4096], got {num_envs!r}")
        cfg = make_family_config(config)
        if max_episode_steps is not None and int(max_episode_steps) != cfg.steps:
            raise ValueError(f"max_episode_steps = {max_episode_steps} differs from the task's episode "
                             f"({cfg.steps} scans); set the config's steps instead")
        self.config = cfg
        super().__init__([lambda: ValveFamilyRegulationEnv(cfg, render_mode) for _ in range(int(num_envs))])
