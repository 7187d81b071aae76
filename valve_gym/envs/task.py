"""The level-control task: one module for the rules the single and the native vector env share.

:class:`~valve_gym.envs.ValveTankEnv` (one loop, plain Python per step) and
:class:`~valve_gym.envs.ValveTankVectorEnv` (``N`` loops, one compiled pass per
step) run the same task; everything they must agree on is written here, once:

* :class:`TaskPlan`: the numbers of an :class:`~valve_gym.config.EnvConfig` the
  task needs, computed once (episode draw sizes, action mode, reward weights);
* :func:`draw_episodes` (the per-episode draw from each env's own generator,
  :class:`EpisodeDraw`) and :func:`schedule`;
* :func:`parse_options` and :func:`check_options` (``reset(options=...)``);
* the observation: :data:`OBS_NAMES`, :func:`obs_names`, :func:`observation_space`
  and the builders :func:`observation` (one loop), :func:`observations` (a
  batch) and :func:`write_observation` (one row, compiled);
* the action: :func:`scalar_action` and :func:`batch_actions` (validation),
  :func:`direct_input` and :func:`residual_input` (the scaling of one action),
  :func:`direct_inputs`, :func:`clip_actions` and :func:`residual_inputs` (the
  same rules over a batch, compiled);
* the reward: :func:`step_reward` (scalars or arrays) and its compiled form
  :func:`step_reward_nb` for the vector env's bookkeeping pass.

The scalar rules are plain Python functions; the batch loops call compiled
copies of the same functions (``njit`` of the one definition), so the single
and the vector env compute every number with the same operations.

Notes
-----
With the measured level ``y_m``, set point ``sp``, applied valve input ``u``
and stem position ``h``, the observation is ``(y_m, sp, sp - y_m, u[, h])``
(``h`` with ``measure_stem``). An action ``a`` in [-1, 1] (clipped; NaN or inf
refused) gives the valve input ``u = (a + 1)/2`` (``action_mode='direct'``) or
``u = clip(u_PI + residual_scale a, 0, 1)`` (``'residual'``). The reward of a
step, with the true level ``L`` after it::

    r = -( c_e |sp - L| + w_h |h_k+1 - h_k| + w_u |u_k - u_k-1| ),   c_e = w_e / e_scale
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from .. import core
from .._numba import njit
from ..config import EnvConfig, load_config
from ..config import preset as _preset
from ..control import PIParams
from ..params import ModelParams, ParameterError

__all__ = ["VALVE_KEYS", "NEVER", "ACTION_MODES", "OBS_NAMES", "STEM_OBS_NAME", "obs_names", "make_config",
           "TaskPlan", "EpisodeDraw", "draw_episodes", "schedule", "parse_options", "check_options",
           "level_bounds", "observation_space", "observation", "observations", "write_observation",
           "scalar_action", "batch_actions", "direct_input", "residual_input", "direct_inputs", "clip_actions",
           "residual_inputs", "raise_nonfinite", "step_reward", "step_reward_nb"]

_INF = math.inf

#: Valve parameters drawn each episode, reported in ``info`` and pinnable
#: through ``reset(options=...)``.
VALVE_KEYS = ("z_max", "e_dead", "tau", "v_max")

#: Step index of an event that never happens (after the horizon).
NEVER = np.iinfo(np.int64).max

#: The action modes (``config.action_mode``).
ACTION_MODES = ("direct", "residual")

#: The observation entries, in order: measured level [m], set point [m],
#: measured error ``sp - y_m`` [m], last applied valve input [-].
OBS_NAMES = ("level_measured", "setpoint", "error_measured", "u")
#: The entry appended with ``measure_stem``: stem position [-].
STEM_OBS_NAME = "stem"


def obs_names(measure_stem: bool) -> tuple[str, ...]:
    """Names of the observation entries (4, or 5 with ``measure_stem``)."""
    return OBS_NAMES + ((STEM_OBS_NAME,) if measure_stem else ())


def make_config(config: EnvConfig | Mapping | str | None = None, preset: str = "default") -> EnvConfig:
    """The :class:`EnvConfig` of an environment.

    Parameters
    ----------
    config : EnvConfig, mapping, str or path, optional
        A config, or keys (mapping or YAML file) applied over the preset.
    preset : {'default', 'fixed'}
        Base configuration (see :data:`valve_gym.config.PRESETS`).
    """
    if isinstance(config, EnvConfig):
        return config
    return load_config(config, base=_preset(preset))


# --------------------------------------------------------------------------- #
# The plan and the per-episode draw
# --------------------------------------------------------------------------- #
class TaskPlan:
    """Numbers of an :class:`EnvConfig` that the task needs, computed once.

    Attributes
    ----------
    cfg : EnvConfig
    H : int
        Steps per episode.
    Tc : float, s
        Control period.
    E_sp, E_ld : int
        Set-point and load events drawn per episode (enough for the horizon).
    K : int
        Uniforms drawn per episode before the noise.
    residual : bool
        ``action_mode == 'residual'``.
    scale : float
        ``residual_scale``.
    ce, wt, wu : float
        Reward weights: error per m (``w_e / e_scale``), stem travel, input change.
    measure_stem : bool
    n_obs : int
        Length of an observation.
    pi_params : PIParams
        The built-in PI of the residual mode.
    """

    def __init__(self, cfg: EnvConfig):
        self.cfg = cfg
        self.H = cfg.episode_steps
        self.Tc = float(cfg.control_period)
        T = float(cfg.episode_seconds)
        self.E_sp = int(math.floor(T / cfg.setpoint.interval[0])) + 1
        self.E_ld = int(math.floor(T / cfg.load.interval[0])) + 1
        self.K = 5 + 3 * self.E_sp + 3 * self.E_ld
        r = cfg.randomise
        self.randomise = r.enabled
        zlo, zhi = r.z_max
        self.zlo = float(zlo)
        self.zlog = math.log(zhi / zlo) if zhi > zlo else 0.0
        v = cfg.model.valve
        self.fixed_valve = {k: float(getattr(v, k)) for k in VALVE_KEYS}
        self.residual = cfg.action_mode == "residual"
        self.scale = float(cfg.residual_scale)
        rw = cfg.reward
        self.ce = float(rw.error) / float(rw.error_scale)
        self.wt = float(rw.travel)
        self.wu = float(rw.du)
        self.measure_stem = bool(cfg.measure_stem)
        self.n_obs = len(obs_names(self.measure_stem))
        self.pi_params = PIParams(Kc=cfg.pi.Kc, Ti=cfg.pi.Ti, Ts=cfg.control_period)

    def rest_levels(self) -> dict[str, float]:
        """Levels of the plant at the start of an episode, as :meth:`valve_gym.plant.Plant.reset` takes them.

        The measured tank at ``model.process.level0`` (the lower tank at
        ``model.cascade.level2_0`` and the upper at ``process.level0`` for a
        cascade), the valve resting at the input that holds the measured level.
        """
        m = self.cfg.model
        if m.process_kind == "cascade":
            assert m.cascade is not None
            return {"level": float(m.cascade.level2_0), "level_upper": float(m.process.level0)}
        return {"level": float(m.process.level0)}


class EpisodeDraw(NamedTuple):
    """The random quantities of ``n`` episodes, each row one episode.

    Set point and load are piecewise constant: ``*_0`` from the start, then
    ``*_vals[:, e]`` from control step ``*_steps[:, e]`` on (the step that
    starts at ``t = steps * control_period``; events after the horizon carry
    the step :data:`NEVER`).

    Fields
    ------
    z_max, e_dead, tau, v_max : (n,) valve parameters [s, -, s, 1/s]
    sp_0 : (n,) initial set point [m]
    sp_steps : (n, E_sp) int64, sp_vals : (n, E_sp) [m]
    load_steps : (n, E_ld) int64, load_vals : (n, E_ld) extra inflow [m^3/s]
        (the load is 0 before the first event)
    noise : (n, H+1) measurement noise of the ``k``-th observation [m]
    """

    z_max: np.ndarray
    e_dead: np.ndarray
    tau: np.ndarray
    v_max: np.ndarray
    sp_0: np.ndarray
    sp_steps: np.ndarray
    sp_vals: np.ndarray
    load_steps: np.ndarray
    load_vals: np.ndarray
    noise: np.ndarray


def schedule(v0, steps, vals, H):
    """Dense ``(n, H+1)`` piecewise-constant schedule of an :class:`EpisodeDraw` event list.

    Entry ``[j, k]`` is ``v0[j]`` before the first event of row ``j`` and
    ``vals[j, e]`` once ``e + 1`` events have their step ``<= k``.
    """
    allv = np.concatenate([np.asarray(v0, float)[:, None], vals], axis=1)
    ks = np.arange(H + 1)
    idx = np.stack([np.searchsorted(row, ks, side="right") for row in np.sort(steps, axis=1)])
    return np.take_along_axis(allv, idx, axis=1)


def _lin(u, r):
    return r[0] + u * (r[1] - r[0])


def _event_steps(times, plan):
    steps = np.ceil(times / plan.Tc - 1e-9).astype(np.int64)
    steps[steps > plan.H] = NEVER
    return steps


def _draw_valves(U: np.ndarray, plan: TaskPlan, pins) -> dict[str, np.ndarray]:
    """Valve parameters ``{key: (n,)}`` from the first four uniforms of each row, pins applied."""
    n = U.shape[0]
    r = plan.cfg.randomise
    if plan.randomise:
        zlo, zlog, exp = plan.zlo, plan.zlog, math.exp
        z = np.array([zlo * exp(x * zlog) for x in U[:, 0].tolist()])
        valve = {"z_max": z, "e_dead": _lin(U[:, 1], r.e_dead), "tau": _lin(U[:, 2], r.tau),
                 "v_max": _lin(U[:, 3], r.v_max)}
    else:
        valve = {k: np.full(n, v) for k, v in plan.fixed_valve.items()}
    if pins:
        for k, v in pins.items():
            v = np.broadcast_to(np.asarray(v, dtype=float), (n,))
            valve[k] = np.where(np.isnan(v), valve[k], v)
    return valve


def draw_episodes(rngs, plan: TaskPlan, pins: Mapping[str, np.ndarray] | None = None) -> EpisodeDraw:
    """Draw ``len(rngs)`` episodes, one from each generator.

    Each generator gives, in this order, ``rng.random(K)`` uniforms (valve,
    initial set point, set-point and load events; ``K`` fixed by the config)
    and ``rng.standard_normal(H + 1)`` for the noise. The number of draws never
    depends on the values or on the pinned options, so pinning one parameter
    leaves everything else of the episode unchanged. The transformation of
    the uniforms is element-wise, so row ``j`` depends on ``rngs[j]`` only:
    a batch draw equals single draws.

    Parameters
    ----------
    rngs : sequence of numpy.random.Generator
    plan : TaskPlan
    pins : mapping of str to (n,) float arrays, optional
        Valve parameters that replace the drawn ones where finite (NaN = drawn).

    Returns
    -------
    EpisodeDraw
    """
    cfg = plan.cfg
    n = len(rngs)
    H = plan.H
    U = np.empty((n, plan.K))
    noise = np.empty((n, H + 1))
    for j, g in enumerate(rngs):
        g.random(out=U[j])
        g.standard_normal(out=noise[j])
    valve = _draw_valves(U, plan, pins)
    # set point: steps of random size and sign, reflected at the limits
    sp = cfg.setpoint
    lo, hi = sp.limits
    sp0 = _lin(U[:, 4], sp.initial)
    c = 5
    E = plan.E_sp
    times = np.cumsum(_lin(U[:, c:c + 3 * E:3], sp.interval), axis=1)
    sizes = _lin(U[:, c + 1:c + 3 * E:3], sp.step)
    signs = np.where(U[:, c + 2:c + 3 * E:3] < 0.5, -1.0, 1.0)
    sp_vals = np.empty((n, E))
    cur = sp0
    for e in range(E):
        cand = cur + signs[:, e] * sizes[:, e]
        out = (cand > hi) | (cand < lo)
        cand = np.where(out, cur - signs[:, e] * sizes[:, e], cand)
        cur = np.minimum(np.maximum(cand, lo), hi)
        sp_vals[:, e] = cur
    sp_steps = _event_steps(times, plan)
    # load: jumps of the extra inflow to a random value
    ld = cfg.load
    c = 5 + 3 * E
    E = plan.E_ld
    times = np.cumsum(_lin(U[:, c:c + 3 * E:3], ld.interval), axis=1)
    mags = _lin(U[:, c + 1:c + 3 * E:3], ld.magnitude)
    load_vals = np.where(U[:, c + 2:c + 3 * E:3] < 0.5, -mags, mags)
    load_steps = _event_steps(times, plan)
    noise *= float(cfg.noise_std)
    return EpisodeDraw(sp_0=sp0, sp_steps=sp_steps, sp_vals=sp_vals, load_steps=load_steps,
                       load_vals=load_vals, noise=noise, **valve)


# --------------------------------------------------------------------------- #
# reset(options=...)
# --------------------------------------------------------------------------- #
def _option_value(key: str, val, n: int | None, allow_nan: bool) -> np.ndarray:
    """One pinned valve parameter: a number (``n`` None) or a number / ``(n,)`` array."""
    try:
        a = np.asarray(val, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"reset option {key!r} must be a number, got {val!r}") from None
    if n is None:
        if a.ndim != 0 and a.size != 1:
            raise ValueError(f"reset option {key!r} must be a single number, got {val!r}")
        a = a.reshape(())
    elif a.ndim != 0 and a.shape != (n,):
        raise ValueError(f"reset option {key!r} must be a number or an array of shape "
                         f"({n},) (one per sub-environment), got shape {a.shape}")
    if np.isinf(a).any() or (np.isnan(a).any() and not allow_nan):
        raise ValueError(f"reset option {key!r} must be finite, got {val!r}"
                         + ("; use NaN to leave a sub-environment unpinned" if allow_nan else ""))
    return a


def parse_options(options, n: int | None, allow_nan: bool) -> dict[str, np.ndarray] | None:
    """Validate ``reset(options)``: the pinnable valve parameters (:data:`VALVE_KEYS`) only.

    Parameters
    ----------
    options : mapping or None
    n : int or None
        ``None`` for the single env (each option one number); the number of
        sub-environments for the vector env (a number or an ``(n,)`` array).
    allow_nan : bool
        NaN entries leave a sub-environment unpinned (vector env).

    Returns
    -------
    dict of str to float arrays, or None when nothing is pinned

    Raises
    ------
    ValueError
        Not a mapping, an unknown key, or a value that is not a (finite) number of the right shape.
    """
    if options is None:
        return None
    if not isinstance(options, Mapping):
        raise ValueError(f"options must be a dict (e.g. reset(options={{'z_max': 0.2}})), got {type(options).__name__}")
    pins = {}
    for key, val in options.items():
        if key not in VALVE_KEYS:
            raise ValueError(
                f"unknown reset option {key!r}; the options pin the valve of the episode: "
                f"{', '.join(VALVE_KEYS)} (e.g. reset(options={{'z_max': 0.2}}))")
        pins[key] = _option_value(key, val, n, allow_nan)
    return pins or None


def check_options(pins, model: ModelParams) -> None:
    """Raise ValueError naming the option if a pinned valve parameter is out of range for ``model``."""
    if not pins:
        return
    v = model.valve
    for key, a in pins.items():
        a = np.asarray(a, dtype=float)
        a = np.where(np.isnan(a), float(getattr(v, key)), a)
        try:
            vp = replace(v, **{key: a})
            if key == "tau":
                core.check_dt(replace(model, valve=vp))
        except ParameterError as exc:
            raise ValueError(f"reset option {key!r}: {exc}") from None


# --------------------------------------------------------------------------- #
# Observation
# --------------------------------------------------------------------------- #
def level_bounds(cfg: EnvConfig) -> tuple[float, float]:
    """Range of the measured level [m].

    For tanks, the steady level at full inflow (valve open plus the largest load) bounds the true
    level; 10 noise standard deviations are added. Unbounded for the other processes.
    """
    m = cfg.model
    if m.process_kind not in ("tank", "cascade"):
        return -math.inf, math.inf
    pr: Any = m.process                      # TankParams here
    q_in = float(pr.q_max) + float(cfg.load.magnitude[1])
    if m.oscillating_disturbance is not None:
        q_in += float(m.oscillating_disturbance.amplitude)
    if m.process_kind == "cascade" and m.cascade is not None:
        k, L0 = float(m.cascade.k_out2), float(m.cascade.level2_0)
        top = float(m.overflow.L2_max) if m.overflow is not None else math.inf
    else:
        k, L0 = float(pr.k_out), float(pr.level0)
        top = float(m.overflow.L_max) if m.overflow is not None else math.inf
    if k <= 0.0:
        return -math.inf, math.inf
    hi = min(max(L0, (q_in / k) ** 2) * 1.01, top)
    margin = 10.0 * float(cfg.noise_std)
    return -margin, hi + margin


def observation_space(cfg: EnvConfig) -> spaces.Box:
    """The ``Box`` of one observation (entries :func:`obs_names`)."""
    ylo, yhi = level_bounds(cfg)
    lo, hi = cfg.setpoint.limits
    low = [ylo, lo, lo - yhi, 0.0]
    high = [yhi, hi, hi - ylo, 1.0]
    if cfg.measure_stem:
        low.append(0.0)
        high.append(1.0)
    return spaces.Box(np.array(low, dtype=np.float32), np.array(high, dtype=np.float32), dtype=np.float32)


def observation(ym: float, sp: float, u: float, h: float, measure_stem: bool) -> np.ndarray:
    """One observation ``(ym, sp, sp - ym, u[, h])``, float32 (4,) or (5,)."""
    if measure_stem:
        return np.array((ym, sp, sp - ym, u, h), dtype=np.float32)
    return np.array((ym, sp, sp - ym, u), dtype=np.float32)


def observations(ym: np.ndarray, sp: np.ndarray, u: np.ndarray, h: np.ndarray, measure_stem: bool) -> np.ndarray:
    """A batch of observations, float32 ``(N, 4)`` or ``(N, 5)``: one row per loop as :func:`observation`."""
    cols = (ym, sp, sp - ym, u)
    if measure_stem:
        cols += (h,)
    return np.stack(cols, axis=1).astype(np.float32)


@njit(inline="always")
def write_observation(obs, i, ym, sp, u, h):  # pragma: no cover - compiled
    """Row ``i`` of a float32 observation array ``obs`` (N, 4|5), as :func:`observation` (compiled code)."""
    obs[i, 0] = ym
    obs[i, 1] = sp
    obs[i, 2] = sp - ym
    obs[i, 3] = u
    if obs.shape[1] == 5:
        obs[i, 4] = h


# --------------------------------------------------------------------------- #
# Action
# --------------------------------------------------------------------------- #
def _as_scalar(action) -> float:
    try:
        arr = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"action must be a number or an array of shape (1,), got {action!r}") from None
    if arr.size != 1:
        raise ValueError(f"action must have shape (1,) (one valve), got an array of shape {arr.shape}")
    return float(arr.reshape(-1)[0])


def scalar_action(action) -> float:
    """One action as a float in [-1, 1] (clipped); ValueError for NaN, inf or a wrong shape."""
    if type(action) is np.ndarray and action.shape == (1,):
        a = float(action[0])
    else:
        a = _as_scalar(action)
    if not -_INF < a < _INF:
        raise ValueError(
            f"action {action!r} is not finite (NaN or inf); pass a number in [-1, 1] "
            f"(check the policy for NaN outputs, e.g. from diverging training)")
    if a > 1.0:
        return 1.0
    if a < -1.0:
        return -1.0
    return a


def direct_input(a: float) -> float:
    """Valve input of a clipped action in direct mode: ``u = (a + 1)/2``."""
    return (a + 1.0) * 0.5


def residual_input(u_pi: float, a: float, scale: float) -> float:
    """Valve input of a clipped action in residual mode: ``u = clip(u_PI + scale a, 0, 1)``."""
    u = u_pi + scale * a
    if u > 1.0:
        return 1.0
    if u < 0.0:
        return 0.0
    return u


_direct_input_nb = njit(inline="always")(direct_input)
_residual_input_nb = njit(inline="always")(residual_input)


def batch_actions(actions, n: int) -> np.ndarray:
    """Validate the shape and type of a batch of actions; a C-contiguous float ``(n, 1)`` array (no copy if it is one).

    Values are not checked here: the compiled scalings count the non-finite ones
    (:func:`raise_nonfinite` makes the error).
    """
    a = np.asarray(actions)
    if a.dtype != np.float32 and a.dtype != np.float64:
        try:
            a = a.astype(np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"actions must be numbers, got an array of {a.dtype}") from None
    if a.shape != (n, 1):
        if a.shape != (n,):
            raise ValueError(f"actions must have shape ({n}, 1) (one valve per sub-environment), got {a.shape}")
        a = a.reshape(n, 1)
    if not a.flags.c_contiguous:
        a = np.ascontiguousarray(a)
    return a


@njit(cache=True)
def clip_actions(a, out):  # pragma: no cover - compiled
    """``out[i]`` = action ``a[i, 0]`` (N, 1) clipped to [-1, 1] as float64; returns the number of non-finite ones."""
    bad = 0
    for i in range(out.shape[0]):
        x = float(a[i, 0])
        if not (x > -np.inf and x < np.inf):
            bad += 1
            out[i] = 0.0
            continue
        if x > 1.0:
            x = 1.0
        elif x < -1.0:
            x = -1.0
        out[i] = x
    return bad


@njit(cache=True)
def direct_inputs(a, u):  # pragma: no cover - compiled
    """Direct mode over a batch: ``u[i] = direct_input(a[i, 0])`` for actions ``a`` (N, 1), clipped to [-1, 1].

    Returns the number of non-finite actions (their ``u`` is meaningless).
    """
    bad = clip_actions(a, u)
    for i in range(u.shape[0]):
        u[i] = _direct_input_nb(u[i])
    return bad


@njit(cache=True)
def residual_inputs(u_pi, a, scale, u):  # pragma: no cover - compiled
    """Residual mode over a batch: ``u[i] = residual_input(u_pi[i], a[i], scale)`` for clipped actions ``a`` (N,)."""
    for i in range(u.shape[0]):
        u[i] = _residual_input_nb(u_pi[i], a[i], scale)


def raise_nonfinite(actions) -> None:
    """Raise the ValueError for a batch with non-finite actions, naming the sub-environments."""
    flat = np.asarray(actions, dtype=np.float64).reshape(-1)
    idx = np.flatnonzero(~np.isfinite(flat))
    raise ValueError(
        f"actions of sub-environments {idx[:10].tolist()} are not finite "
        f"({flat[idx[:10]].tolist()}); pass numbers in [-1, 1] (check the policy for NaN "
        f"outputs, e.g. from diverging training)")


# --------------------------------------------------------------------------- #
# Reward
# --------------------------------------------------------------------------- #
def step_reward(sp, level, h, h_prev, u, u_prev, ce, wt, wu):
    """Reward of a step: ``-(ce |sp - level| + wt |h - h_prev| + wu |u - u_prev|)``.

    Floats or arrays (element-wise); ``ce = w_e / e_scale``, ``wt = w_h``,
    ``wu = w_u`` (:class:`TaskPlan`). The ``wu`` term is left out when ``wu`` is 0.
    """
    r = ce * abs(sp - level) + wt * abs(h - h_prev)
    if wu != 0.0:
        r += wu * abs(u - u_prev)
    return -r


#: :func:`step_reward` compiled, for the compiled bookkeeping pass of the vector env.
step_reward_nb = njit(inline="always")(step_reward)
