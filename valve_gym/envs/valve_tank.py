"""Level control through a sticky valve: the single Gymnasium environment.

The plant is a :class:`valve_gym.plant.Plant` of one loop (the one physics core,
:func:`valve_gym.core.run_packed`); the task around it (the per-episode draw of
the valve, set-point schedule, load disturbance and measurement noise from
``self.np_random``, the options, the action scaling, the observation and the
reward) is :mod:`valve_gym.envs.task`, shared with the native vector env
(:class:`~valve_gym.envs.vector.ValveTankVectorEnv`). That is why a
sub-environment of the vector env with seed ``s`` follows the same trajectory
as this environment reset with seed ``s``.

:data:`VALVE_KEYS`, :data:`NEVER`, :class:`EpisodeDraw`, :func:`draw_episodes`,
:func:`schedule` and :func:`make_config` are re-exported from
:mod:`valve_gym.envs.task`.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from functools import partial

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import core
from ..config import EnvConfig
from ..control import pi_init, pi_step
from ..params import ValveParams
from ..plant import Plant
from .task import (
    NEVER,
    VALVE_KEYS,
    EpisodeDraw,
    TaskPlan,
    check_options,
    direct_input,
    draw_episodes,
    make_config,
    observation,
    observation_space,
    parse_options,
    residual_input,
    scalar_action,
    schedule,
    step_reward,
)

__all__ = ["ValveTankEnv", "EpisodeDraw", "draw_episodes", "schedule", "make_config", "VALVE_KEYS", "NEVER"]


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

    Notes
    -----
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
        self._plan = plan = TaskPlan(cfg)
        self._H = plan.H
        self._Tc = plan.Tc
        self.substeps = cfg.substeps
        self.episode_steps = cfg.episode_steps
        self.model = cfg.model
        self.residual = plan.residual
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = observation_space(cfg)
        # the config and check_options() validate every valve an episode can have: no check per reset
        self._plant = Plant(cfg.model, 1, scan_s=cfg.control_period, check=False)
        # the plant at rest (independent of the drawn friction parameters), restored at each reset
        rest = self._plant.reset(**plan.rest_levels())
        self._rest_state = self._plant.state
        self._h0, self._stem0 = float(rest.op[0]), float(rest.stem[0])
        self._level0, self._y0 = float(rest.pv[0]), float(rest.y[0])
        self._pi_params = plan.pi_params
        self._ce, self._wt, self._wu = plan.ce, plan.wt, plan.wu
        self._scale = plan.scale
        self._measure_stem = plan.measure_stem
        self._U = np.zeros((1, 1))
        self._D = np.zeros((1, 1))
        self._out = np.zeros((3, 1))
        self._views()
        self._scan = None
        self._level_max = 1.25 * cfg.setpoint.limits[1]

    def _views(self):
        """The plant's output rows ``(y, stem, level)`` as views of one (3, 1) array (one ``tolist`` per step)."""
        self._outf = self._out.reshape(3)
        self._rows = (self._out[0:1], self._out[1:2], self._out[2:3])

    def __getstate__(self):
        # the output rows are views of one array and the scan holds them: rebuilt on unpickling
        state = self.__dict__.copy()
        for key in ("_outf", "_rows", "_scan"):
            state.pop(key, None)
        state["_started"] = self._scan is not None
        return state

    def __setstate__(self, state):
        started = state.pop("_started")
        self.__dict__.update(state)
        self._views()
        self._scan = self._scan_fn() if started else None

    def _scan_fn(self):
        """One scan of the plant from ``_U``, ``_D`` into ``_rows``, as a call without arguments.

        A core call on the plant's arrays (:meth:`Plant.scan_args`: :meth:`Plant.advance` without
        its Python frame), or :meth:`Plant.advance` for a friction model with a per-scan law.
        """
        plant = self._plant
        if plant.sample_law is not None:
            return partial(plant.advance, self._U, self._D, self._rows)
        return partial(core.run_packed, *plant.scan_args(self._U, self._D, self._rows))

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode; see the class docstring for ``options`` and ``info``."""
        pins = parse_options(options, None, allow_nan=False)
        check_options(pins, self.config.model)
        super().reset(seed=seed)
        plan = self._plan
        d = draw_episodes([self.np_random], plan, pins)
        vp = {k: float(getattr(d, k)[0]) for k in VALVE_KEYS}
        self.model = replace(self.config.model, valve=ValveParams(**vp))
        plant = self._plant
        plant.set_params(self.model)
        plant.set_state(self._rest_state)
        self._scan = self._scan_fn()
        h0 = self._h0
        H = plan.H
        self._sp = schedule(d.sp_0, d.sp_steps, d.sp_vals, H)[0].tolist()
        self._load = schedule(np.zeros(1), d.load_steps, d.load_vals, H)[0].tolist()
        self._noise = d.noise[0].tolist()
        self._k = 0
        self._u = h0
        self._h = self._stem0
        level0 = self._level0
        sp = self._sp[0]
        ym = self._y0 + self._noise[0]
        if self.residual:
            self._pi = pi_init(h0, sp - ym)
        self._valve_vals = tuple(vp[k] for k in VALVE_KEYS)
        self._last = (ym, sp, level0, self._h, self._u)
        info = {"setpoint": sp, "level": level0, "stem": self._h, "u": self._u,
                "t": 0.0, "load": self._load[0]}
        if self.residual:
            info["u_pi"] = h0
        info.update(vp)
        return observation(ym, sp, self._u, self._h, self._measure_stem), info

    # ------------------------------------------------------------------- step
    def step(self, action):
        """Apply ``action`` for one control period; returns ``(obs, reward, False, False, info)``."""
        scan = self._scan
        if scan is None:
            raise RuntimeError("call reset() before step()")
        a = scalar_action(action)
        k = self._k
        H = self._H
        kk = k if k < H else H
        if self.residual:
            e_meas = self._last[1] - self._last[0]
            self._pi, upi = pi_step(self._pi, e_meas, self._pi_params)
            u_pi = float(upi[0])
            u = residual_input(u_pi, a, self._scale)
        else:
            u = direct_input(a)
        self._U[0, 0] = u
        load = self._load[kk]
        self._D[0, 0] = load
        scan()
        y, h, lv = self._outf.tolist()
        k += 1
        self._k = k
        if k <= H:
            sp = self._sp[k]
            ym = y + self._noise[k]
        else:
            sp = self._sp[H]
            ym = y + self._noise[k % (H + 1)]
        reward = step_reward(sp, lv, h, self._h, u, self._u, self._ce, self._wt, self._wu)
        self._h = h
        self._u = u
        self._last = (ym, sp, lv, h, u)
        z, e, tau, vm = self._valve_vals
        info = {"setpoint": sp, "level": lv, "stem": h, "u": u, "t": k * self._Tc, "load": load,
                "z_max": z, "e_dead": e, "tau": tau, "v_max": vm}
        if self.residual:
            info["u_pi"] = u_pi
        return observation(ym, sp, u, h, self._measure_stem), reward, False, False, info

    # ----------------------------------------------------------------- render
    def render(self):
        """An RGB frame (200, 160, 3) of tank, set point, valve input and stem (``render_mode='rgb_array'``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; create the env with "
                            "render_mode='rgb_array'")
            return None
        if self._scan is None:
            raise RuntimeError("call reset() before render()")
        ym, sp, lv, h, u = self._last
        return render_frame(lv, sp, h, u, self._level_max)
