"""Evaluate any controller on a batch of valves at once.

One code path for PI, PI + knocker and PPO: a :class:`~valve_gym.envs.ValveTankVectorEnv`
holds one sub-environment per valve, every valve's parameters are pinned
through ``reset(options=...)`` and every sub-environment gets its own seed
(so the set-point schedule, the load and the measurement noise of valve ``i``
are the same for every controller), and the controller's batched
``predict`` is called once per control period for all valves.

Scores are computed on the *true* level (``info['level']``), the valve input
actually applied (``info['u']``, the controller output OP) and the stem
position (``info['stem']``, the valve position MV) with
:func:`valve_gym.metrics.loop_metrics`.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from valve_gym.config import EnvConfig, load_config
from valve_gym.envs.valve_tank import VALVE_KEYS, make_config

__all__ = ["Rollout", "make_eval_env", "env_config_for", "rollout", "episode_metrics", "evaluate",
           "VALVE_KEYS"]


class Rollout(NamedTuple):
    """Signals of one episode on ``n`` valves, time axis first.

    Attributes
    ----------
    t : (T,) s, time at the end of each control period
    setpoint : (T, n) m, set point at the end of each period
    level : (T, n) m, true level at the end of each period
    measured : (T, n) m, measured (noisy) level observed after each period
    u : (T, n) valve input applied during each period (OP, 0..1)
    stem : (T, n) stem position at the end of each period (MV, 0..1)
    load : (T, n) m^3/s, extra inflow during each period
    reward : (T, n) environment reward of each period
    u_pi : (T, n) or None, built-in PI output (residual mode only)
    valves : dict of (n,) arrays, the valve parameters (``z_max``, ``e_dead``, ``tau``, ``v_max``)
    dt : float, s, control period
    """

    t: np.ndarray
    setpoint: np.ndarray
    level: np.ndarray
    measured: np.ndarray
    u: np.ndarray
    stem: np.ndarray
    load: np.ndarray
    reward: np.ndarray
    u_pi: np.ndarray | None
    valves: dict[str, np.ndarray]
    dt: float

    @property
    def n(self) -> int:
        """Number of loops."""
        return self.level.shape[1]


def env_config_for(controller, env_config: EnvConfig | Mapping | str | None = None) -> EnvConfig:
    """The environment configuration a controller is evaluated in.

    ``env_config`` (the scenario: tank, set points, load, noise) with the
    controller's action mode and, for trained policies, the settings they
    were trained with (``controller.env_overrides``: residual scale, built-in
    PI tuning, measured stem).
    """
    base = make_config(env_config)
    over = dict(getattr(controller, "env_overrides", {}) or {})
    mode = getattr(controller, "env_mode", "direct")
    over["action_mode"] = mode
    over.pop("randomise", None)
    try:
        return load_config(over, base=base)
    except ValueError as exc:
        raise ValueError(f"environment settings of controller {getattr(controller, 'name', controller)!r}: "
                         f"{exc}") from None


def make_eval_env(controller, n: int, env_config=None):
    """A vector env of ``n`` valves for ``controller`` (no autoreset)."""
    from valve_gym.envs import ValveTankVectorEnv

    cfg = env_config_for(controller, env_config)
    return ValveTankVectorEnv(num_envs=n, config=cfg, autoreset_mode="disabled")


def _valve_options(valves: Mapping[str, Sequence[float]] | None, n: int) -> dict | None:
    if valves is None:
        return None
    opts = {}
    for k, v in valves.items():
        if k not in VALVE_KEYS:
            raise ValueError(f"unknown valve parameter {k!r}; valves are given by {', '.join(VALVE_KEYS)}")
        a = np.asarray(v, dtype=float).reshape(-1)
        if a.size != n:
            raise ValueError(f"valve parameter {k!r} has {a.size} values, expected {n} (one per valve)")
        opts[k] = a
    return opts


def rollout(controller, env, seeds: int | Sequence[int] | None = 0,
            valves: Mapping[str, Sequence[float]] | None = None, deterministic: bool = True,
            progress=None) -> Rollout:
    """Run one episode of ``controller`` on every sub-environment of ``env``.

    Parameters
    ----------
    controller : Controller
        Anything with the batched ``predict`` of :class:`valve_gym.agents.base.Controller`.
    env : ValveTankVectorEnv
        Built by :func:`make_eval_env` (autoreset disabled).
    seeds : int or sequence of int
        Seeds of the sub-environments (an int ``s`` seeds sub-env ``i`` with ``s + i``).
    valves : mapping of str to (n,) arrays, optional
        Valve parameters to pin (the rest drawn by the env).
    deterministic : bool
        Passed to ``predict``.
    progress : tqdm-like, optional
        Updated by one per control step.

    Returns
    -------
    Rollout
    """
    n = env.num_envs
    opts = _valve_options(valves, n)
    obs, info = env.reset(seed=seeds, options=opts)
    T = int(env.max_episode_steps)
    out = {k: np.empty((T, n)) for k in ("setpoint", "level", "measured", "u", "stem", "load", "reward")}
    upi = np.empty((T, n)) if "u_pi" in info else None
    vparams = {k: np.asarray(info[k], dtype=float).copy() for k in VALVE_KEYS}
    state = None
    start = np.ones(n, dtype=bool)
    for k in range(T):
        act, state = controller.predict(obs, state=state, episode_start=start, deterministic=deterministic)
        start = np.zeros(n, dtype=bool)
        act = np.asarray(act, dtype=np.float32).reshape(n, 1)
        obs, rew, term, trunc, info = env.step(act)
        out["setpoint"][k] = info["setpoint"]
        out["level"][k] = info["level"]
        out["measured"][k] = obs[:, 0]
        out["u"][k] = info["u"]
        out["stem"][k] = info["stem"]
        out["load"][k] = info["load"]
        out["reward"][k] = rew
        if upi is not None:
            upi[k] = info["u_pi"]
        if progress is not None:
            progress.update(1)
    dt = float(env.config.control_period)
    return Rollout(t=dt * np.arange(1, T + 1), u_pi=upi, valves=vparams, dt=dt, **out)


def episode_metrics(ro: Rollout, deadband: float = 0.0, span: float = 1.0):
    """Per-valve loop scores of a rollout as a :class:`pandas.DataFrame`.

    One row per valve: the valve parameters, every key of
    :func:`valve_gym.metrics.loop_metrics` (``iae``, ``ise``, ``error_std``,
    ``lc_*``, ``crest_factor``, ``hagglund_*``, ``op_travel``,
    ``op_reversals_per_hour``, ``valve_travel``, ``valve_reversals_per_hour``)
    and ``return`` (the summed environment reward).

    Parameters
    ----------
    ro : Rollout
    deadband : float, reversal dead band for OP and MV (fraction of stroke)
    span : float, m, measurement span for Hägglund's detector
    """
    import pandas as pd

    from valve_gym.metrics import loop_metrics

    rows = []
    for i in range(ro.n):
        m = loop_metrics(ro.dt, ro.setpoint[:, i], ro.level[:, i], ro.u[:, i], mv=ro.stem[:, i],
                         span=span, deadband=deadband)
        row: dict = {"valve": i}
        row.update({k: float(v[i]) for k, v in ro.valves.items()})
        row.update(m)
        row["return"] = float(ro.reward[:, i].sum())
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate(controller, valves: Mapping[str, Sequence[float]] | None = None, n: int | None = None,
             env_config=None, seed: int | Sequence[int] = 0, deterministic: bool = True,
             deadband: float = 0.0, progress=None, return_rollout: bool = False):
    """Evaluate ``controller`` on a batch of valves; per-valve metrics.

    Parameters
    ----------
    controller : Controller
    valves : mapping of str to (n,) arrays, optional
        Pinned valve parameters (``z_max``, ``e_dead``, ``tau``, ``v_max``);
        without them ``n`` valves are drawn from the env's randomisation.
    n : int, optional
        Number of valves (default: the length of the ``valves`` arrays).
    env_config : EnvConfig, mapping or YAML path, optional
        The scenario (default: the env's default configuration).
    seed : int or sequence of int
        Sub-environment seeds (set points, load, noise of each episode).
    deterministic : bool
    deadband : float, reversal dead band of the wear metrics
    progress : tqdm-like, optional
    return_rollout : bool
        Also return the :class:`Rollout`.

    Returns
    -------
    pandas.DataFrame (and Rollout)

    Examples
    --------
    >>> from valve_gym.agents import BlockPolicy, load_controller
    >>> df = evaluate(BlockPolicy(load_controller("pi")), {"z_max": [0.005, 0.3], "e_dead": [0.0, 0.02]}, seed=1)
    >>> list(df["valve"]), bool(df.loc[1, "iae"] > 0)
    ([0, 1], True)
    """
    if valves is not None:
        sizes = {np.asarray(v).size for v in valves.values()}
        if len(sizes) != 1:
            raise ValueError(f"all valve parameter arrays must have one length, got sizes {sorted(sizes)}")
        nv = sizes.pop()
        if n is not None and n != nv:
            raise ValueError(f"n = {n} but the valve arrays have {nv} entries")
        n = nv
    if n is None or n < 1:
        raise ValueError("give the valves to evaluate (valves=...) or their number n >= 1")
    env = make_eval_env(controller, n, env_config)
    try:
        ro = rollout(controller, env, seed, valves, deterministic=deterministic, progress=progress)
    finally:
        env.close()
    df = episode_metrics(ro, deadband=deadband)
    return (df, ro) if return_rollout else df
