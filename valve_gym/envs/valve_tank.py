"""Level control through a sticky valve: the single Gymnasium environment.

The plant is simulated by the one physics core (:func:`valve_gym.core.run_packed`);
this module only adds the task around it: the per-episode draw of the valve,
set-point schedule, load disturbance and measurement noise (all from
``self.np_random``), the action scaling, the observation and the reward.

:func:`draw_episodes` is the per-episode draw shared with the native vector
environment (:class:`~valve_gym.envs.vector.ValveTankVectorEnv`), which is why a
sub-environment of the vector env with seed ``s`` follows the same trajectory
as this environment reset with seed ``s``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import core
from ..config import EnvConfig, load_config
from ..config import preset as _preset
from ..control import PIParams, pi_init, pi_step
from ..params import ModelParams, ParameterError, ValveParams

__all__ = ["ValveTankEnv", "EpisodeDraw", "draw_episodes", "schedule", "make_config", "VALVE_KEYS", "NEVER"]

_INF = math.inf

#: Valve parameters drawn each episode, reported in ``info`` and pinnable
#: through ``reset(options=...)``.
VALVE_KEYS = ("z_max", "e_dead", "tau", "v_max")


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
# The per-episode draw (shared with the vector env)
# --------------------------------------------------------------------------- #
class _Plan:
    """Numbers of an :class:`EnvConfig` that the draw needs, computed once."""

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


#: Step index of an event that never happens (after the horizon).
NEVER = np.iinfo(np.int64).max


def schedule(v0, steps, vals, H):
    """Dense ``(n, H+1)`` piecewise-constant schedule of an :class:`EpisodeDraw` event list."""
    n, E = vals.shape
    allv = np.concatenate([np.asarray(v0, float)[:, None], vals], axis=1)
    cnt = np.zeros((n, H + 2), dtype=np.int64)
    s = np.minimum(steps, H + 1)
    rows = np.arange(n)
    for e in range(E):
        cnt[rows, s[:, e]] += 1
    idx = np.cumsum(cnt[:, :H + 1], axis=1)
    return np.take_along_axis(allv, idx, axis=1)


def _lin(u, r):
    return r[0] + u * (r[1] - r[0])


def _event_steps(times, plan):
    steps = np.ceil(times / plan.Tc - 1e-9).astype(np.int64)
    steps[steps > plan.H] = NEVER
    return steps


def draw_episodes(rngs, plan: _Plan, pins: Mapping[str, np.ndarray] | None = None) -> EpisodeDraw:
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
    plan : _Plan
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
    r = cfg.randomise
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


def _parse_pins(options, n: int | None, allow_nan: bool):
    """Validate ``reset(options)``: the pinnable valve parameters only."""
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
        pins[key] = a
    return pins or None


def _check_pins(pins, model: ModelParams):
    """Raise ValueError naming the option if a pinned valve parameter is out of range."""
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
# Rendering (no dependency: a small RGB drawing)
# --------------------------------------------------------------------------- #
_W, _Hpx = 160, 200


def render_frame(level: float, setpoint: float, stem: float, u: float, level_max: float) -> np.ndarray:
    """Draw a (200, 160, 3) uint8 picture of the loop.

    Tank with water level (blue), set point (red line), valve input (grey bar) and stem position
    (green bar).
    """
    img = np.full((_Hpx, _W, 3), 255, dtype=np.uint8)
    top, bot, x0, x1 = 20, 180, 20, 100

    def row(v):
        f = min(max(v / level_max, 0.0), 1.0)
        return int(round(bot - f * (bot - top)))

    img[top:bot + 1, x0 - 2:x0] = 40
    img[top:bot + 1, x1:x1 + 2] = 40
    img[bot:bot + 2, x0 - 2:x1 + 2] = 40
    img[row(level):bot, x0:x1] = (60, 120, 220)
    r = row(setpoint)
    img[max(r - 1, 0):r + 1, x0 - 6:x1 + 6] = (220, 30, 30)
    for xa, val, col in ((115, u, (150, 150, 150)), (135, stem, (40, 170, 60))):
        img[top:bot + 1, xa:xa + 14] = 230
        f = min(max(val, 0.0), 1.0)
        img[int(round(bot - f * (bot - top))):bot + 1, xa:xa + 14] = col
    return img


# --------------------------------------------------------------------------- #
# The environment
# --------------------------------------------------------------------------- #
class ValveTankEnv(gym.Env):
    """Level control of a tank through a control valve with stiction.

    ## Description

    A tank (area ``A`` = 0.2 m^2, Torricelli outflow ``k_out sqrt(L)``) is fed
    through a control valve with the friction model of Riihilahti as
    implemented by Yamé & El Bahir: dead band ``e_dead``, friction state ``z``
    with band ``z_max``, first-order stem motion (``tau``) with a speed limit
    ``v_max``. A sticky valve makes a PI loop hunt in a stick-slip limit
    cycle; the task is to hold the level at a changing set point against load
    disturbances with little valve travel (wear). The valve parameters are
    drawn each episode (``z_max`` from healthy 0.002 s to severe 0.5 s
    stiction) and not observed: a policy must cope with the valve it has. The
    plant is integrated by explicit Euler with ``dt`` = 0.02 s,
    :attr:`substeps` = 50 steps per action (control period 1 s), in the one
    numba kernel of :mod:`valve_gym.core`.

    ## Action Space

    ``Box(-1, 1, (1,), float32)``; values outside are clipped, NaN or inf
    raise :class:`ValueError`.

    * ``action_mode='direct'``: valve input ``u = (a + 1)/2`` (0 = closed,
      1 = open).
    * ``action_mode='residual'``: ``u = clip(u_PI + residual_scale * a, 0, 1)``
      where ``u_PI`` is the built-in PI controller (:func:`valve_gym.control.pi_step`,
      ``Kc`` = 1.0 /m, ``Ti`` = 30 s by default) acting on the measured error;
      the PI runs on its own output (the residual does not enter its state),
      so ``a = 0`` is exactly the PI loop.

    ## Observation Space

    ``Box(float32)`` of shape (4,) (5 with ``measure_stem``):

    ====  ======================================  =====  ================
    idx   observation                             unit   range
    ====  ======================================  =====  ================
    0     measured level ``y + noise``            m      [-0.02, 5.84]
    1     set point ``sp``                        m      [0.5, 1.5]
    2     measured error ``sp - y_measured``      m      [-5.34, 1.52]
    3     last valve input ``u`` (applied)        -      [0, 1]
    4     stem position ``h`` (``measure_stem``)  -      [0, 1]
    ====  ======================================  =====  ================

    The level range (default config) is that of the tank: up to the steady
    level with the valve open and the largest load inflow, plus 10 noise
    standard deviations (unbounded for the non-tank processes).

    The valve's internal state (``z``, and ``h`` unless measured) is hidden.

    ## Rewards

    With the true level ``L``, stem position ``h`` and input ``u`` after the
    step and the set point ``sp`` at that time (all also in ``info``)::

        r_k = -( w_e * |sp - L| / e_scale + w_h * |h_k+1 - h_k| + w_u * |u_k - u_k-1| )

    defaults ``w_e`` = 1, ``e_scale`` = 0.1 m, ``w_h`` = 2 per stroke,
    ``w_u`` = 0 (``config.reward``). The return of an episode is thus
    ``-(IAE / (e_scale * control_period) + w_h * travel(h) + w_u * travel(u))``
    with the integral absolute error and the valve travel of
    :mod:`valve_gym.metrics` (:func:`~valve_gym.metrics.iae`,
    :func:`~valve_gym.metrics.travel`), the scores of the benchmark: a full
    stroke of stem travel costs as much as 20 s at 1 cm error.

    ## Starting State

    The tank is at rest at ``model.process.level0`` (1.0 m) with the valve at
    the input that holds it (:func:`valve_gym.core.initial_state`, ``z = 0``).
    The initial set point is drawn uniformly from ``setpoint.initial``
    ([0.7, 1.3] m), so most episodes begin with a set-point change. Drawn at
    reset from ``self.np_random`` (see :func:`draw_episodes`): the valve
    ``z_max`` (log-uniform [0.002, 0.5] s), ``e_dead`` ([0, 0.02]), ``tau``
    ([0.05, 0.2] s), ``v_max`` ([0.2, 1.0] /s); the set-point schedule (steps
    of 0.1-0.3 m every 120-240 s within [0.5, 1.5] m); the load (jumps of the
    extra inflow to +-0.5-2 L/s every 60-240 s); the measurement noise (std
    2 mm) of the whole episode.

    ## Episode End

    No termination. Truncation after ``episode_seconds / control_period`` =
    600 steps by the ``TimeLimit`` of the registration; with another
    ``episode_seconds`` pass the matching ``max_episode_steps`` to
    ``gymnasium.make`` (``env.unwrapped.episode_steps``). Stepped beyond the
    horizon, the set point and load hold and the noise sequence repeats.

    ## Arguments

    Parameters
    ----------
    config : EnvConfig, mapping, str or path, optional
        The task (:class:`~valve_gym.config.EnvConfig`), or keys (a mapping or
        a YAML file) applied over the preset, e.g.
        ``{"action_mode": "residual", "model": {"sensor_lag": {"tau_s": 3.0}}}``.
    preset : {'default', 'fixed'}
        ``'fixed'`` is one sticky valve (``z_max`` 0.1 s, ``e_dead`` 0.01),
        a set-point step to 1.2 m, no load and no noise: the same episode for
        every seed.
    render_mode : {None, 'rgb_array'}

    ``reset(seed=..., options={'z_max': 0.2, 'e_dead': ..., 'tau': ..., 'v_max': ...})``
    pins valve parameters for that episode (any subset; the other draws are
    unchanged). ``info`` has, at reset and after each step (floats):

    * ``setpoint`` [m], ``level`` true level [m], ``stem`` true stem position,
      ``u`` applied valve input, ``u_pi`` PI output (residual mode),
      ``t`` time [s], ``load`` extra inflow during the step [m^3/s];
    * ``z_max``, ``e_dead``, ``tau``, ``v_max`` of the episode's valve.

    Attributes
    ----------
    config : EnvConfig
    substeps : int
        Euler steps per action.
    episode_steps : int
        Steps per episode (the registered time limit).
    model : ModelParams
        The physics of the current episode (its drawn valve).

    ## Version History

    * v0: initial version.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import valve_gym
    >>> env = gym.make("valve_gym/ValveTank-v0")
    >>> obs, info = env.reset(seed=1, options={"z_max": 0.2})
    >>> obs.shape, info["z_max"]
    ((4,), 0.2)
    >>> obs, r, terminated, truncated, info = env.step(env.action_space.sample())
    >>> env.unwrapped.substeps, info["t"]
    (50, 1.0)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: EnvConfig | Mapping | str | None = None, *,
                 preset: str = "default", render_mode: str | None = None):
        cfg = make_config(config, preset)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, "
                             f"got {render_mode!r}")
        self.render_mode = render_mode
        self.config = cfg
        self._plan = _Plan(cfg)
        self._H = self._plan.H
        self._Tc = self._plan.Tc
        self.substeps = cfg.substeps
        self.episode_steps = cfg.episode_steps
        self.model = cfg.model
        self.residual = cfg.action_mode == "residual"
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = _observation_space(cfg)
        # the plant at rest (independent of the drawn friction parameters)
        st = core.initial_state(cfg.model, 1)
        self._S0 = core.state_to_array(st)
        self._buf0 = np.ascontiguousarray(st.delay_buf, dtype=np.float64)
        self._h0 = float(st.h[0])
        self._stem0 = min(max(self._h0, 0.0), 1.0)
        self._level0 = float(st.level2[0] if cfg.model.process_kind == "cascade" else st.level[0])
        self._y0 = float(st.y[0])
        self._pi_params = PIParams(Kc=cfg.pi.Kc, Ti=cfg.pi.Ti, Ts=cfg.control_period)
        rw = cfg.reward
        self._ce = float(rw.error) / float(rw.error_scale)
        self._wt = float(rw.travel)
        self._wu = float(rw.du)
        self._scale = float(cfg.residual_scale)
        self._U = np.zeros((1, 1))
        self._D = np.zeros((1, 1))
        self._out = np.zeros((3, 1))
        self._outf = self._out.reshape(3)
        self._Y, self._Hs, self._LV = self._out[0:1], self._out[1:2], self._out[2:3]
        self._measure_stem = cfg.measure_stem
        self._args = None
        self._level_max = 1.25 * cfg.setpoint.limits[1]

    def __getstate__(self):
        # the kernel's output rows are views of one array: rebuilt on unpickling
        state = self.__dict__.copy()
        for key in ("_Y", "_Hs", "_LV", "_outf", "_args"):
            state.pop(key, None)
        state["_plant"] = None if self._args is None else self._args[:3]
        return state

    def __setstate__(self, state):
        plant = state.pop("_plant")
        self.__dict__.update(state)
        self._outf = self._out.reshape(3)
        self._Y, self._Hs, self._LV = self._out[0:1], self._out[1:2], self._out[2:3]
        self._args = None if plant is None else (*plant, self._U, self._D, self.substeps,
                                                 self._Y, self._Hs, self._LV)

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode; see the class docstring for ``options`` and ``info``."""
        pins = _parse_pins(options, None, allow_nan=False)
        _check_pins(pins, self.config.model)
        super().reset(seed=seed)
        d = draw_episodes([self.np_random], self._plan, pins)
        vp = {k: float(getattr(d, k)[0]) for k in VALVE_KEYS}
        self.model = replace(self.config.model, valve=ValveParams(**vp))
        pk = core.pack(self.model, 1)
        S = self._S0.copy()
        buf = self._buf0.copy()
        self._args = (pk, S, buf, self._U, self._D, self.substeps, self._Y, self._Hs, self._LV)
        H = self._plan.H
        self._sp = schedule(d.sp_0, d.sp_steps, d.sp_vals, H)[0].tolist()
        self._load = schedule(np.zeros(1), d.load_steps, d.load_vals, H)[0].tolist()
        self._noise = d.noise[0].tolist()
        self._k = 0
        self._u = self._h0
        self._h = self._stem0
        sp = self._sp[0]
        ym = self._y0 + self._noise[0]
        if self.residual:
            self._pi = pi_init(self._h0, sp - ym)
        self._valve_vals = tuple(vp[k] for k in VALVE_KEYS)
        self._last = (ym, sp, self._level0, self._h, self._u)
        info = {"setpoint": sp, "level": self._level0, "stem": self._h, "u": self._u,
                "t": 0.0, "load": self._load[0]}
        if self.residual:
            info["u_pi"] = self._h0
        info.update(vp)
        return self._obs(ym, sp, self._u), info

    def _obs(self, ym, sp, u):
        if self._measure_stem:
            return np.array((ym, sp, sp - ym, u, self._h), dtype=np.float32)
        return np.array((ym, sp, sp - ym, u), dtype=np.float32)

    # ------------------------------------------------------------------- step
    def step(self, action):
        """Apply ``action`` for one control period; returns ``(obs, reward, False, False, info)``."""
        args = self._args
        if args is None:
            raise RuntimeError("call reset() before step()")
        if type(action) is np.ndarray and action.shape == (1,):
            a = float(action[0])
        else:
            a = _scalar_action(action)
        if not -_INF < a < _INF:
            raise ValueError(
                f"action {action!r} is not finite (NaN or inf); pass a number in [-1, 1] "
                f"(check the policy for NaN outputs, e.g. from diverging training)")
        if a > 1.0:
            a = 1.0
        elif a < -1.0:
            a = -1.0
        k = self._k
        H = self._H
        kk = k if k < H else H
        if self.residual:
            e_meas = self._last[1] - self._last[0]
            self._pi, upi = pi_step(self._pi, e_meas, self._pi_params)
            u_pi = float(upi[0])
            u = u_pi + self._scale * a
            if u > 1.0:
                u = 1.0
            elif u < 0.0:
                u = 0.0
        else:
            u = (a + 1.0) * 0.5
        self._U[0, 0] = u
        load = self._load[kk]
        self._D[0, 0] = load
        core.run_packed(*args)  # pyright: ignore[reportArgumentType]
        y, h, lv = self._outf.tolist()
        k += 1
        self._k = k
        if k <= H:
            sp = self._sp[k]
            ym = y + self._noise[k]
        else:
            sp = self._sp[H]
            ym = y + self._noise[k % (H + 1)]
        reward = self._ce * abs(sp - lv) + self._wt * abs(h - self._h)
        if self._wu:
            reward += self._wu * abs(u - self._u)
        reward = -reward
        self._h = h
        self._u = u
        self._last = (ym, sp, lv, h, u)
        z, e, tau, vm = self._valve_vals
        info = {"setpoint": sp, "level": lv, "stem": h, "u": u, "t": k * self._Tc, "load": load,
                "z_max": z, "e_dead": e, "tau": tau, "v_max": vm}
        if self.residual:
            info["u_pi"] = u_pi
        if self._measure_stem:
            obs = np.array((ym, sp, sp - ym, u, h), dtype=np.float32)
        else:
            obs = np.array((ym, sp, sp - ym, u), dtype=np.float32)
        return obs, reward, False, False, info

    # ----------------------------------------------------------------- render
    def render(self):
        """An RGB frame (200, 160, 3) of tank, set point, valve input and stem (``render_mode='rgb_array'``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; create the env with "
                            "render_mode='rgb_array'")
            return None
        if self._args is None:
            raise RuntimeError("call reset() before render()")
        ym, sp, lv, h, u = self._last
        return render_frame(lv, sp, h, u, self._level_max)


def _scalar_action(action) -> float:
    try:
        arr = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"action must be a number or an array of shape (1,), got {action!r}") from None
    if arr.size != 1:
        raise ValueError(f"action must have shape (1,) (one valve), got an array of shape {arr.shape}")
    return float(arr.reshape(-1)[0])


def _level_bounds(cfg: EnvConfig):
    """Range of the measured level [m].

    For tanks, the steady level at full inflow (valve open plus the largest load) bounds the true
    level; 10 noise standard deviations are added.
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


def _observation_space(cfg: EnvConfig) -> spaces.Box:
    ylo, yhi = _level_bounds(cfg)
    lo, hi = cfg.setpoint.limits
    low = [ylo, lo, lo - yhi, 0.0]
    high = [yhi, hi, hi - ylo, 1.0]
    if cfg.measure_stem:
        low.append(0.0)
        high.append(1.0)
    return spaces.Box(np.array(low, dtype=np.float32), np.array(high, dtype=np.float32), dtype=np.float32)
