"""Environment configuration: YAML files onto frozen dataclasses.

A configuration is a tree of frozen dataclasses (:class:`EnvConfig` at the
root, :class:`~valve_gym.params.ModelParams` for the physics). YAML files in
``configs/`` hold nested mappings with the same names; :func:`load_config`
maps them onto the dataclasses, filling every key that is left out with its
default, and :func:`config_to_dict` goes back (to write the configuration used
next to the results of a run).

Mistakes are :class:`ConfigError` (a :class:`ValueError`) naming the full key
path: an unknown or misspelt key, a string where a number belongs, a wrong
type, a value out of its physical range, an integration step ``model.dt`` that
is unstable for the valve time constants the episodes may draw.

.. note::
   PyYAML reads ``1e-3`` (exponent without a dot) as a *string*. Write
   ``1.0e-3``; the loader rejects strings where numbers belong and says so.

Examples
--------
>>> from valve_gym.config import load_config, EnvConfig
>>> cfg = load_config({"model": {"valve": {"tau": 0.2}, "sensor_lag": {"tau_s": 3.0}},
...                    "action_mode": "residual"})
>>> cfg.model.valve.tau, cfg.model.sensor_lag.tau_s, cfg.substeps
(0.2, 3.0, 50)
>>> load_config({"model": {"valve": {"tua": 0.2}}})  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
valve_gym.config.ConfigError: unknown key 'model.valve.tua' (did you mean 'tau'?); the keys of 'model.valve' ...
"""
from __future__ import annotations

import difflib
import math
import os
import re
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, TypeVar, Union

import numpy as np

from .core import check_dt
from .params import PROCESSES, ModelParams, ParameterError, ValveParams

__all__ = [
    "ConfigError", "ValveRandomisation", "SetpointSchedule", "LoadSchedule", "PISettings",
    "RewardWeights", "EnvConfig", "PRESETS", "preset", "load_config", "config_to_dict",
    "save_config", "MAX_EPISODE_STEPS", "check_episode_steps", "MAX_NUM_ENVS", "check_count",
]

Range = tuple[float, float]


class ConfigError(ValueError):
    """A configuration value is unknown, mistyped or out of range (the message names the key path)."""


# --------------------------------------------------------------------------- #
# The configuration dataclasses
# --------------------------------------------------------------------------- #
def _num(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _check_range(path: str, r, lo=None, lo_open=False, hi=None) -> None:
    if not (isinstance(r, tuple) and len(r) == 2 and all(_num(x) for x in r)):
        raise ConfigError(f"{path} must be a pair [low, high] of numbers, got {r!r}")
    a, b = float(r[0]), float(r[1])
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ConfigError(f"{path} must hold finite numbers, got {list(r)!r}")
    if a > b:
        raise ConfigError(f"{path} must be [low, high] with low <= high, got {list(r)!r}")
    if lo is not None and (a <= lo if lo_open else a < lo):
        rel = ">" if lo_open else ">="
        raise ConfigError(f"{path} must be {rel} {lo}, got {list(r)!r}")
    if hi is not None and b > hi:
        raise ConfigError(f"{path} must be <= {hi}, got {list(r)!r}")


def _check_num(path: str, v, lo=None, lo_open=False, hi=None) -> None:
    if not _num(v) or not math.isfinite(float(v)):
        raise ConfigError(f"{path} must be a finite number, got {v!r}")
    if lo is not None and (v <= lo if lo_open else v < lo):
        rel = ">" if lo_open else ">="
        raise ConfigError(f"{path} must be {rel} {lo}, got {v!r}")
    if hi is not None and v > hi:
        raise ConfigError(f"{path} must be <= {hi}, got {v!r}")


#: Most control steps in one episode.  An episode's measurement noise and schedules are drawn when
#: it starts, as float arrays of one value per step (8 bytes each, several arrays per environment);
#: 10^6 steps (11.6 days at a 1 s scan; the longest documented episode is 3600 s) keep them near
#: 8 MB per array, where 10^12 s asked for 559 GiB.
MAX_EPISODE_STEPS = 1_000_000


def check_episode_steps(path: str, seconds: float, period: float, period_name: str) -> None:
    """A :class:`ConfigError` naming ``path`` when an episode has more than :data:`MAX_EPISODE_STEPS` steps.

    ``seconds`` is the episode length [s], ``period`` the time of one step [s] (``period_name``
    its key).
    """
    steps = float(seconds) / float(period)
    if steps > MAX_EPISODE_STEPS:
        raise ConfigError(
            f"{path} = {float(seconds):g} s is {steps:.3g} steps of {period_name} = {period:g} s; at most "
            f"{MAX_EPISODE_STEPS:,} steps per episode ({MAX_EPISODE_STEPS * period:g} s at this {period_name}): "
            f"each episode's noise and schedules are drawn when it starts as arrays of one value per step, "
            f"which would need about {8 * steps / 2 ** 30:.3g} GiB each per environment; use a shorter "
            f"{path} (run several episodes for a longer record) or a longer {period_name}")


#: Most environments in one vector env (``gym.make_vec(num_envs=...)``, a training config's
#: ``n_envs``).  Every sub-environment holds its plant state, noise and schedule arrays of one value
#: per step (see :data:`MAX_EPISODE_STEPS`); 10^5 of them at the default 3600 scans are a few GiB,
#: where 10^8 grew past 22 GB before the system killed the process without a message.
MAX_NUM_ENVS = 100_000


def check_count(path: str, value, limit: int, what: str) -> int:
    """``value`` as an int when it is an integer from 1 to ``limit``; else a one-line :class:`ConfigError`.

    Checked before anything is allocated, so that a count such as ``1e9`` environments fails at
    once with the limit in the message instead of exhausting the memory.

    Parameters
    ----------
    path : str, the key or argument name (``ppo.n_envs``, ``num_envs``)
    value : the count given
    limit : int, the largest count allowed
    what : str, what one unit of the count costs (said in the message)
    """
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
        ok, value = True, int(value)
    if not ok or value < 1:
        raise ConfigError(f"{path} must be a positive integer, got {value!r}")
    if value > limit:
        raise ConfigError(f"{path} = {int(value):,} is above the limit of {limit:,} ({what}); use at most "
                          f"{limit:,}")
    return int(value)


@dataclass(frozen=True)
class ValveRandomisation:
    """Per-episode draw of the valve parameters (domain randomisation).

    Each range is ``[low, high]``; ``low == high`` fixes the value.

    Parameters
    ----------
    enabled : bool
        Draw the valve each episode. If False the valve of ``model.valve`` is
        used in every episode (the ranges are ignored).
    z_max : (2,) floats, s
        Friction band, drawn **log-uniformly** (``low > 0`` unless
        ``low == high``). The default ``[0.002, 0.5]`` spans a healthy valve
        (``0.005``) to severe stiction.
    e_dead : (2,) floats, fraction of stroke
        Half dead band, uniform (0 .. 0.5).
    tau : (2,) floats, s
        Stem time constant, uniform (> 0; ``model.dt`` must not exceed ``low``).
    v_max : (2,) floats, strokes/s
        Stem speed limit, uniform (> 0).
    """

    enabled: bool = True
    z_max: Range = (0.002, 0.5)
    e_dead: Range = (0.0, 0.02)
    tau: Range = (0.05, 0.2)
    v_max: Range = (0.2, 1.0)

    def __post_init__(self):
        if not isinstance(self.enabled, bool):
            raise ConfigError(f"enabled must be true or false, got {self.enabled!r}")
        _check_range("z_max", self.z_max, lo=0.0)
        if self.z_max[0] == 0.0 and self.z_max[1] > 0.0:
            raise ConfigError(
                f"z_max is drawn log-uniformly and needs low > 0 (or low == high), got "
                f"{list(self.z_max)!r}; use e.g. [0.001, {self.z_max[1]}]")
        _check_range("e_dead", self.e_dead, lo=0.0, hi=0.5)
        _check_range("tau", self.tau, lo=0.0, lo_open=True)
        _check_range("v_max", self.v_max, lo=0.0, lo_open=True)


@dataclass(frozen=True)
class SetpointSchedule:
    """Random set-point schedule of an episode.

    The episode starts at a set point drawn uniformly from ``initial``; after
    intervals drawn uniformly from ``interval`` the set point steps by a size
    drawn uniformly from ``step`` with a random sign (reversed if the step
    would leave ``limits``; the result is kept within ``limits``).

    Parameters
    ----------
    initial : (2,) floats, m
    interval : (2,) floats, s (> 0)
    step : (2,) floats, m (>= 0; ``[0, 0]`` = no steps)
    limits : (2,) floats, m
    """

    initial: Range = (0.7, 1.3)
    interval: Range = (120.0, 240.0)
    step: Range = (0.1, 0.3)
    limits: Range = (0.5, 1.5)

    def __post_init__(self):
        _check_range("initial", self.initial)
        _check_range("interval", self.interval, lo=0.0, lo_open=True)
        _check_range("step", self.step, lo=0.0)
        _check_range("limits", self.limits)
        if not (self.limits[0] <= self.initial[0] and self.initial[1] <= self.limits[1]):
            raise ConfigError(f"initial {list(self.initial)!r} must lie within limits "
                              f"{list(self.limits)!r}")


@dataclass(frozen=True)
class LoadSchedule:
    """Random load disturbance: step changes of an extra inflow ``d``.

    ``d`` (negative = extra offtake) is 0 at the start and jumps, after
    intervals drawn uniformly from ``interval``, to a new value of magnitude
    drawn uniformly from ``magnitude`` with a random sign.

    Parameters
    ----------
    interval : (2,) floats, s (> 0)
    magnitude : (2,) floats, m^3/s (>= 0; ``[0, 0]`` = no load changes)
    """

    interval: Range = (60.0, 240.0)
    magnitude: Range = (0.0005, 0.002)

    def __post_init__(self):
        _check_range("interval", self.interval, lo=0.0, lo_open=True)
        _check_range("magnitude", self.magnitude, lo=0.0)


@dataclass(frozen=True)
class PISettings:
    """Built-in PI controller of the residual action mode (see :mod:`valve_gym.control`).

    Parameters
    ----------
    Kc : float, 1/m
        Gain, valve input fraction per metre of error (> 0 for this inflow valve).
    Ti : float, s
        Integral time (> 0). The sample time is the control period.
    """

    Kc: float = 1.0
    Ti: float = 30.0

    def __post_init__(self):
        _check_num("Kc", self.Kc)
        _check_num("Ti", self.Ti, lo=0.0, lo_open=True)


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward of :class:`~valve_gym.envs.ValveTankEnv`.

    The reward of a step is::

        r = -( error * |sp - L| / error_scale + travel * |dh| + du * |du| )

    Parameters
    ----------
    error : float, -
        Weight of the tracking error (>= 0).
    error_scale : float, m
        Error that costs ``error`` per step (> 0).
    travel : float, per stroke
        Weight of the stem travel ``|h_k+1 - h_k|`` (valve wear, >= 0).
    du : float, per stroke
        Weight of the valve input travel ``|u_k - u_k-1|`` (>= 0).
    """

    error: float = 1.0
    error_scale: float = 0.1
    travel: float = 2.0
    du: float = 0.0

    def __post_init__(self):
        _check_num("error", self.error, lo=0.0)
        _check_num("error_scale", self.error_scale, lo=0.0, lo_open=True)
        _check_num("travel", self.travel, lo=0.0)
        _check_num("du", self.du, lo=0.0)


_ACTION_MODES = ("direct", "residual")


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines the level-control task of :class:`~valve_gym.envs.ValveTankEnv`.

    Parameters
    ----------
    model : ModelParams
        Physics: valve, tank, optional blocks and the Euler step ``dt`` [s].
        Default ``ModelParams()``: tank area 0.2 m^2, ``q_max`` 0.01 m^3/s,
        ``k_out`` 0.005 m^2.5/s, initial level 1.0 m, valve ``tau`` 0.1 s,
        ``v_max`` 0.5 /s, ``dt`` 0.02 s. Its fields must be scalars.
    control_period : float, s
        Time between two actions (default 1.0); an exact multiple of
        ``model.dt`` (``substeps = control_period / dt`` Euler steps).
    episode_seconds : float, s
        Length of an episode (default 600); an exact multiple of
        ``control_period``. The schedules are drawn for this horizon and the
        registered time limit is ``episode_seconds / control_period`` steps.
    randomise : ValveRandomisation
        Per-episode draw of the valve parameters.
    setpoint : SetpointSchedule
    load : LoadSchedule
    noise_std : float, m
        Standard deviation of the white level-measurement noise (default 0.002).
    action_mode : {'direct', 'residual'}
        ``direct``: the action sets the valve input ``u = (a + 1)/2``.
        ``residual``: ``u = clip(u_PI + residual_scale * a, 0, 1)`` with the
        built-in PI controller ``pi`` acting on the measured error.
    residual_scale : float, fraction of the valve range
        Authority of the residual action (default 0.1).
    pi : PISettings
        Tuning of the built-in PI (residual mode).
    measure_stem : bool
        Add the measured stem position to the observation (default False).
    reward : RewardWeights

    Raises
    ------
    ConfigError
        If a value is out of range (the message names the key).
    """

    model: ModelParams = field(default_factory=ModelParams)
    control_period: float = 1.0
    episode_seconds: float = 600.0
    randomise: ValveRandomisation = field(default_factory=ValveRandomisation)
    setpoint: SetpointSchedule = field(default_factory=SetpointSchedule)
    load: LoadSchedule = field(default_factory=LoadSchedule)
    noise_std: float = 0.002
    action_mode: str = "direct"
    residual_scale: float = 0.1
    pi: PISettings = field(default_factory=PISettings)
    measure_stem: bool = False
    reward: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self):
        if not isinstance(self.model, ModelParams):
            raise ConfigError(f"model must be a ModelParams, got {type(self.model).__name__}")
        try:
            nb = self.model.batch_size()
        except ParameterError as exc:
            raise ConfigError(f"model: {exc}") from None
        if nb != 1:
            raise ConfigError(
                "model parameters must be scalars (one valve and tank per environment); vary the "
                "valve between episodes with 'randomise' and between sub-environments by seeding")
        for name, cls in (("randomise", ValveRandomisation), ("setpoint", SetpointSchedule),
                          ("load", LoadSchedule), ("pi", PISettings), ("reward", RewardWeights)):
            if not isinstance(getattr(self, name), cls):
                raise ConfigError(f"{name} must be a {cls.__name__}, got {getattr(self, name)!r}")
        _check_num("control_period", self.control_period, lo=0.0, lo_open=True)
        _check_num("episode_seconds", self.episode_seconds, lo=0.0, lo_open=True)
        check_episode_steps("episode_seconds", self.episode_seconds, self.control_period, "control_period")
        _check_num("noise_std", self.noise_std, lo=0.0)
        _check_num("residual_scale", self.residual_scale, lo=0.0)
        if self.action_mode not in _ACTION_MODES:
            raise ConfigError(f"action_mode must be one of {list(_ACTION_MODES)}, got {self.action_mode!r}")
        if not isinstance(self.measure_stem, bool):
            raise ConfigError(f"measure_stem must be true or false, got {self.measure_stem!r}")
        dt = float(self.model.dt)
        ns = round(self.control_period / dt)
        if ns < 1 or abs(ns * dt - self.control_period) > 1e-9 * self.control_period:
            raise ConfigError(
                f"control_period = {self.control_period} s is not an exact multiple of model.dt = "
                f"{dt} s; choose them so that control_period / dt is an integer (e.g. "
                f"control_period {max(ns, 1) * dt:g} s)")
        for name in ("setpoint", "load"):
            lo = getattr(self, name).interval[0]
            if lo < self.control_period:
                raise ConfigError(f"{name}.interval must not be shorter than control_period = "
                                  f"{self.control_period} s (one change per action at most), got "
                                  f"{list(getattr(self, name).interval)!r}")
        ne = round(self.episode_seconds / self.control_period)
        if ne < 1 or abs(ne * self.control_period - self.episode_seconds) > 1e-9 * self.episode_seconds:
            raise ConfigError(
                f"episode_seconds = {self.episode_seconds} s is not an exact multiple of "
                f"control_period = {self.control_period} s")
        # the step must be stable for the fastest valve an episode can draw
        tau_min = float(self.model.valve.tau)
        if self.randomise.enabled:
            tau_min = min(tau_min, float(self.randomise.tau[0]))
        worst = replace(self.model, valve=replace(self.model.valve, tau=tau_min))
        try:
            check_dt(worst)
        except ParameterError as exc:
            where = (" (the smallest valve tau that randomise.tau can draw)"
                     if tau_min < self.model.valve.tau and "valve tau" in str(exc) else "")
            raise ConfigError(f"model.dt: {exc}{where}") from None

    @property
    def substeps(self) -> int:
        """Euler steps of ``model.dt`` per control period."""
        return int(round(self.control_period / float(self.model.dt)))

    @property
    def episode_steps(self) -> int:
        """Control steps per episode (the registered ``max_episode_steps``)."""
        return int(round(self.episode_seconds / self.control_period))


#: Named configurations: ``default`` (randomised friction) and ``fixed``
#: (one sticky valve, fully deterministic episodes, for teaching and debugging).
PRESETS = {
    "default": EnvConfig,
    "fixed": lambda: EnvConfig(
        model=ModelParams(valve=ValveParams(tau=0.1, v_max=0.5, e_dead=0.01, z_max=0.1)),
        randomise=ValveRandomisation(enabled=False),
        setpoint=SetpointSchedule(initial=(1.2, 1.2), interval=(600.0, 600.0), step=(0.0, 0.0)),
        load=LoadSchedule(interval=(600.0, 600.0), magnitude=(0.0, 0.0)),
        noise_std=0.0,
    ),
}


def preset(name: str) -> EnvConfig:
    """The named configuration ``name`` (a key of :data:`PRESETS`)."""
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; known presets: {sorted(PRESETS)}")
    return PRESETS[name]()


# --------------------------------------------------------------------------- #
# Loading
# --------------------------------------------------------------------------- #
def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else str(key)


def _describe(v) -> str:
    return f"{type(v).__name__} {v!r}"


def _as_number(v, path: str):
    if _num(v):
        f = float(v)
        if not math.isfinite(f):
            raise ConfigError(f"{path} must be a finite number, got {v!r}")
        return int(v) if isinstance(v, (int, np.integer)) else f
    if isinstance(v, str):
        try:
            float(v)
        except ValueError:
            raise ConfigError(f"{path} must be a number, got the string {v!r}") from None
        hint = ""
        m = re.match(r"\s*([-+]?\d+)([eE][-+]?\d+)\s*$", v)
        if m is not None:
            hint = (f"; PyYAML reads exponent notation without a decimal point as a string: "
                    f"write {m.group(1)}.0{m.group(2)}")
        raise ConfigError(f"{path} must be a number, got the string {v!r}{hint}")
    raise ConfigError(f"{path} must be a number, got {_describe(v)}")


_UNIONS = (Union, getattr(types, "UnionType", Union))


def _is_optional(tp) -> tuple[bool, Any]:
    if typing.get_origin(tp) in _UNIONS:
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return len(args) < len(typing.get_args(tp)), args
    return False, [tp]


def _convert_dataclass(dcs: list, v, path: str, base, parent_data: Mapping, owner) -> Any:
    """A nested dataclass field (``ModelParams.process``: the class is chosen by ``process_kind``)."""
    if len(dcs) > 1:
        kind = parent_data.get("process_kind", getattr(owner, "process_kind", "tank"))
        cls = PROCESSES.get(kind)
        if cls is None:
            raise ConfigError(f"{_join(path.rpartition('.')[0], 'process_kind')} must be one "
                              f"of {sorted(PROCESSES)}, got {kind!r}")
    else:
        cls = dcs[0]
    if isinstance(v, cls):
        return v
    if v is True:  # `sensor_lag: true` switches a block on with defaults
        v = {}
    if not isinstance(v, Mapping):
        raise ConfigError(f"{path} must be a mapping of {cls.__name__} fields, got {_describe(v)}")
    return _build(cls, v, path, base if isinstance(base, cls) else None)


def _convert_tuple(tp, v, path: str) -> tuple:
    targs = typing.get_args(tp)
    if not isinstance(v, (list, tuple)):
        raise ConfigError(f"{path} must be a list, got {_describe(v)}")
    if len(targs) == 2 and targs[1] is Ellipsis:
        types = [targs[0]] * len(v)
    elif targs:
        if len(v) != len(targs):
            what = "[low, high]" if len(targs) == 2 else f"of {len(targs)} values"
            raise ConfigError(f"{path} must be a list {what}, got {_describe(v)}")
        types = list(targs)
    else:
        types = [Any] * len(v)
    return tuple(_convert(t, x, f"{path}[{i}]", None, {}, None) for i, (t, x) in enumerate(zip(types, v)))


def _convert_scalar(tp, v, path: str) -> Any:
    """``bool``, ``str``, ``int`` or a number (``float`` / ``Number``)."""
    if tp is bool:
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        raise ConfigError(f"{path} must be true or false, got {_describe(v)}")
    if tp is str:
        if isinstance(v, str):
            return v
        raise ConfigError(f"{path} must be a string, got {_describe(v)}")
    x = _as_number(v, path)
    if tp is int:
        if isinstance(x, float) and not x.is_integer():
            raise ConfigError(f"{path} must be an integer, got {v!r}")
        return int(x)
    return float(x)      # float or Number = Union[float, np.ndarray]


def _convert(tp, v, path: str, base, parent_data: Mapping, owner) -> Any:
    optional, args = _is_optional(tp)
    if v is None:
        if optional:
            return None
        raise ConfigError(f"{path} must not be empty (null)")
    dcs = [a for a in args if isinstance(a, type) and is_dataclass(a)]
    if dcs:
        return _convert_dataclass(dcs, v, path, base, parent_data, owner)
    tp = args[0] if len(args) == 1 else tp
    if tp is Any or tp is object:
        return v
    origin = typing.get_origin(tp)
    if origin is tuple or tp is tuple:
        return _convert_tuple(tp, v, path)
    if origin is list or tp is list:
        if not isinstance(v, (list, tuple)):
            raise ConfigError(f"{path} must be a list, got {_describe(v)}")
        targs = typing.get_args(tp) or (Any,)
        return [_convert(targs[0], x, f"{path}[{i}]", None, {}, None) for i, x in enumerate(v)]
    if origin in (dict, Mapping) or tp in (dict, Mapping):
        if not isinstance(v, Mapping):
            raise ConfigError(f"{path} must be a mapping, got {_describe(v)}")
        return dict(v)
    return _convert_scalar(tp, v, path)


_PARAM_MSG = re.compile(r"^(?:(\w+)\.)?(\w+) ")


def _under(path: str, msg: str, names: list[str]) -> str:
    """A section's message ``msg`` placed under ``path``: ``path.key ...`` when it starts with one of its keys.

    >>> _under("es", "hidden must be ...", ["hidden"]), _under("es", "es.hidden must be ...", ["hidden"])
    ('es.hidden must be ...', 'es.hidden must be ...')
    >>> _under("task", "unknown friction model 'x'", ["friction_models"])
    "task: unknown friction model 'x'"
    """
    if not path or msg.startswith(path + ".") or msg.startswith(path + ":"):
        return msg
    first = re.split(r"[ .,:;]", msg, maxsplit=1)[0]
    return f"{path}.{msg}" if first in names else f"{path}: {msg}"


def _build(cls, data: Mapping, path: str, base=None):
    hints = typing.get_type_hints(cls)
    names = [f.name for f in fields(cls) if f.init]
    for key in data:
        if key not in names:
            close = difflib.get_close_matches(str(key), names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            where = f"the keys of {path!r} are" if path else "the top-level keys are"
            raise ConfigError(f"unknown key {_join(path, str(key))!r}{hint}; {where}: {', '.join(names)}")
    kwargs = {}
    # process_kind first: it decides the class of `process`
    order = sorted(data, key=lambda k: k != "process_kind")
    for key in order:
        sub_base = getattr(base, key) if base is not None else None
        kwargs[key] = _convert(hints[key], data[key], _join(path, key), sub_base, data, base)
    if cls is ModelParams and "process_kind" in kwargs and "process" not in kwargs:
        want = PROCESSES.get(kwargs["process_kind"])
        cur = base.process if base is not None else None
        if want is not None and not isinstance(cur, want):
            kwargs["process"] = want()
    try:
        return replace(base, **kwargs) if base is not None else cls(**kwargs)
    except ConfigError as exc:
        raise ConfigError(_under(path, str(exc), names)) from None
    except (ParameterError, ValueError, TypeError) as exc:
        msg = str(exc)
        m = _PARAM_MSG.match(msg)
        where = _join(path, m.group(2)) if m and m.group(2) in names else (path or cls.__name__)
        raise ConfigError(f"{where}: {msg}") from None


_EMPTY_HINT = "leave out --config to use the defaults, or write the settings to change into the file"


def _unique_key_loader(yaml, path):
    """PyYAML's SafeLoader that refuses a key given twice in one mapping (YAML keeps the last one silently)."""

    class UniqueKeyLoader(yaml.SafeLoader):
        pass

    def mapping(loader, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":       # '<<: *anchor': merged keys may be overridden
                continue
            key = loader.construct_object(key_node, deep=deep)
            if key in seen:
                raise ConfigError(f"{path}: key {key!r} is given twice (lines {seen[key]} and "
                                  f"{key_node.start_mark.line + 1}); keep one")
            seen.setdefault(key, key_node.start_mark.line + 1)
        return loader.construct_mapping(node, deep=deep)

    UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return UniqueKeyLoader


def read_yaml(path, what: str = "config", empty_hint: str = _EMPTY_HINT) -> Any:
    """Read a YAML file; ``ConfigError`` (naming ``what`` and the file) if missing, a folder, invalid or empty.

    A file with no settings (empty, or only comments or ``null``) is refused: it is almost
    certainly a mistake (a wrong or truncated file), not a request for the defaults.
    ``empty_hint`` says what to do instead.
    """
    try:
        import yaml
    except ImportError:  # pragma: no cover
        raise ImportError("reading YAML configs needs PyYAML: pip install pyyaml") from None
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{what} file {str(p)!r} is a folder, not a file; give the path of a YAML file")
    if not p.is_file():
        raise ConfigError(f"{what} file {str(p)!r} does not exist")
    try:
        with open(p, encoding="utf-8") as fh:
            data = yaml.load(fh, Loader=_unique_key_loader(yaml, p))  # noqa: S506  (a SafeLoader)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} file {str(p)!r} is not a UTF-8 text file ({exc.reason})") from None
    if data is None:
        raise ConfigError(f"{what} file {str(p)!r} is empty (no settings: only blanks, comments or null); "
                          f"{empty_hint}")
    return data


_T = TypeVar("_T")


def load_config(path_or_dict: str | os.PathLike | Mapping | None, cls: type[_T] = EnvConfig,  # type: ignore[assignment]
                base: _T | None = None) -> _T:
    """Load a configuration from a YAML file or a mapping onto frozen dataclasses.

    Parameters
    ----------
    path_or_dict : str, path or mapping
        A YAML file, or its content as nested mappings. Keys left out take the
        value of ``base`` (or the dataclass default).
    cls : dataclass type
        The root dataclass (default :class:`EnvConfig`; e.g.
        :class:`~valve_gym.params.ModelParams` to load a model alone).
    base : instance of ``cls``, optional
        Values for the keys left out (default: the defaults of ``cls``).

    Returns
    -------
    instance of ``cls``

    Raises
    ------
    ConfigError
        On an unknown key (with a suggestion), a string where a number belongs,
        a wrong type, a value out of range or an unstable ``model.dt``; the
        message names the full key path, e.g. ``model.valve.tau``; also on a YAML file that is
        missing, a folder, not valid YAML or empty (no settings: pass ``None`` for the defaults).

    Notes
    -----
    Optional physics blocks of :class:`~valve_gym.params.ModelParams` are set
    by name (``sensor_lag: {tau_s: 3.0}``, ``dead_time: {theta: 2.0}``,
    ``null`` = off, ``true`` or ``{}`` = on with defaults); ``process`` maps
    onto the class named by ``process_kind``.
    """
    if isinstance(path_or_dict, (str, os.PathLike)):
        data = read_yaml(path_or_dict)
        src = f" in {os.fspath(path_or_dict)}"
    elif path_or_dict is None:
        data, src = {}, ""
    else:
        data, src = path_or_dict, ""
    if not isinstance(data, Mapping):
        raise ConfigError(f"a config must be a mapping of keys to values{src}, got {_describe(data)}")
    if base is not None and not isinstance(base, cls):
        raise TypeError(f"base must be a {cls.__name__}, got {type(base).__name__}")
    try:
        return _build(cls, data, "", base)  # type: ignore[return-value]
    except ConfigError as exc:
        if src:
            raise ConfigError(f"{exc}{src}") from None
        raise


def config_to_dict(cfg) -> Any:
    """Nested plain dict (lists for ranges and arrays) of a config dataclass; inverse of :func:`load_config`.

    Examples
    --------
    >>> from valve_gym.config import EnvConfig, config_to_dict, load_config
    >>> d = config_to_dict(EnvConfig())
    >>> d["model"]["valve"]["tau"], d["randomise"]["z_max"]
    (0.1, [0.002, 0.5])
    >>> load_config(d) == EnvConfig()
    True
    """
    if is_dataclass(cfg) and not isinstance(cfg, type):
        return {f.name: config_to_dict(getattr(cfg, f.name)) for f in fields(cfg) if f.init}
    if isinstance(cfg, (list, tuple)):
        return [config_to_dict(x) for x in cfg]
    if isinstance(cfg, np.ndarray):
        return cfg.tolist()
    if isinstance(cfg, np.generic):
        return cfg.item()
    return cfg


def save_config(cfg, path) -> None:
    """Write ``cfg`` as YAML to ``path`` (e.g. next to the results of a run)."""
    import yaml

    from ._io import write_atomic

    text = yaml.safe_dump(config_to_dict(cfg), sort_keys=False)
    write_atomic(path, lambda f: f.write(text.encode("utf-8")))
