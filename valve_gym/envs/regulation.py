"""The regulation task: one module for the rules the regulation envs and the learned block share.

A level loop at a constant set point, a sticky valve of a randomised friction model, an
Ornstein-Uhlenbeck load inflow and measurement noise, started at steady state: the test in
which stiction shows as a limit cycle. This module holds, once, everything the single env
(:class:`~valve_gym.envs.regulation_env.ValveTankRegulationEnv`), the native vector env
(:class:`~valve_gym.envs.regulation_env.ValveTankRegulationVectorEnv`) and the learned DCS
block (:mod:`valve_gym.agents.learned`) must agree on:

* :class:`RegulationTaskConfig` and its validation (the task, loadable from YAML);
* :func:`draw_scenarios` (the per-episode draw from each sub-env's own generator);
* :class:`LoopPlants` (the plants of a batch, grouped by friction model);
* :class:`BlockLaw` (the observation layout and the action scaling: the PI with a gated
  integrator and a bounded additive correction, whose inputs are SP, PV and its own OP only;
  the PI scan itself is :func:`valve_gym.control.pi_scan1`, the one PI law);
* :func:`step_reward` (the reward).

Notes
-----
The controller structure (:class:`BlockLaw`) with error ``e = SP - PV`` [m], action
``a = (a_g, a_c)`` in [-1, 1]^2 and scan time ``T_s``::

    g_k  = g_min + (1 - g_min) (a_g + 1) / 2            integrator gate, in [g_min, 1]
    c_k  = c_max a_c                                     bounded correction [fraction of stroke]
    u_k  = clip(K_c e_k + I_k + c_k, op_lo, op_hi)       output
    I_k+1 = I_k + g_k K_c T_s / T_i e_k                  (back-calculated when u_k is clipped)

``a = (1, 0)`` is the plain PI. As ``g_k >= g_min > 0`` and ``|c_k| <= c_max``, the
integrator keeps integrating any persistent error, so the block has integral action
whatever the network does: the mean error is zero in steady state unless the output
saturates.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import core
from .._numba import njit
from ..config import ConfigError, check_episode_steps
from ..control import integral_gain, pi_scan1
from ..params import ModelParams, SlipJump, ValveParams
from ..signals import ou_sequence

__all__ = ["RegulationTaskConfig", "BlockSettings", "RegulationDraw", "draw_scenarios", "friction_params",
           "LoopPlants", "BlockLaw", "pi_action", "step_reward", "References", "reference_runs", "benchmark_reward",
           "BENCHMARK_FRICTION_MODELS", "REWARDS", "parse_options", "available_friction_models",
           "FRICTION_MODELS_FALLBACK", "N_OBS", "N_ACT",
           "OBS_NAMES", "STICK_OBS_NAMES", "obs_names"]

#: Friction models available without :mod:`valve_gym.friction` (the core's two models).
FRICTION_MODELS_FALLBACK = ("riihilahti", "choudhury")
#: The benchmark's friction models (``configs/benchmark.yaml``), the task's default.
BENCHMARK_FRICTION_MODELS = ("riihilahti", "choudhury", "kano")
#: The reward kinds of :class:`RegulationTaskConfig`.
REWARDS = ("benchmark", "tracking")

Range = tuple[float, float]


def check_reward_numbers(cfg, positive: Sequence[str] = ("r_floor", "travel_budget"),
                         nonnegative: Sequence[str] = ("budget_weight", "lc_weight")) -> None:
    """Check the reward's numbers of a task config: ``positive`` ones finite and > 0, ``nonnegative`` ones >= 0.

    Raises
    ------
    ConfigError
        Naming the field and the value.
    """
    for name in positive:
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ConfigError(f"{name} must be a positive number, got {v!r}")
    for name in nonnegative:
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"{name} must be a number >= 0, got {v!r}")


def _range(name: str, r, lo: float = 0.0, hi: float = math.inf, open_lo: bool = False) -> None:
    a, b = float(r[0]), float(r[1])
    if not (math.isfinite(a) and math.isfinite(b)) or a > b or a < lo or b > hi or (open_lo and a <= lo):
        raise ConfigError(f"{name} must be [low, high] with {lo} {'<' if open_lo else '<='} low <= high <= {hi}, "
                          f"got {[a, b]!r}")


@dataclass(frozen=True)
class BlockSettings:
    """Settings of the block law (:class:`BlockLaw`).

    Parameters
    ----------
    Kc : float, 1/m
        PI gain (SIMC for the default tank: 1.89 /m).
    Ti : float, s
        Integral time (SIMC: 42.4 s).
    scan_s : float, s
        Scan time of the block.
    c_max : float, fraction of stroke
        Bound of the correction ``c``.
    g_min : float
        Smallest integrator gate (> 0: integral action is never switched off).
    op_lo, op_hi : float, fraction of stroke
        Output limits.
    e_ref : float, m
        Error scale of the observation (about the measurement noise).
    u_ref : float, fraction of stroke
        Output scale of the observation.
    stick_features : bool
        Add the stickiness features :data:`STICK_OBS_NAMES` to the observation (from SP, PV and
        the block's own output only); ``False`` keeps the :data:`OBS_NAMES` layout.
    """

    Kc: float = 1.89
    Ti: float = 42.4
    scan_s: float = 1.0
    c_max: float = 0.08
    g_min: float = 0.05
    op_lo: float = 0.0
    op_hi: float = 1.0
    e_ref: float = 0.005
    u_ref: float = 0.02
    stick_features: bool = False

    def __post_init__(self):
        for name in ("Kc", "Ti", "scan_s", "e_ref", "u_ref"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"block.{name} must be a positive number, got {v!r}")
        if not 0 <= self.c_max <= 0.5:
            raise ConfigError(f"block.c_max must be in [0, 0.5] (fraction of stroke), got {self.c_max!r}")
        if not 0 < self.g_min <= 1:
            raise ConfigError(f"block.g_min must be in (0, 1] (0 would switch integral action off), "
                              f"got {self.g_min!r}")
        if not 0 <= self.op_lo < self.op_hi <= 1:
            raise ConfigError(f"block.op_lo, op_hi must satisfy 0 <= op_lo < op_hi <= 1, got "
                              f"{self.op_lo!r}, {self.op_hi!r}")


@dataclass(frozen=True)
class RegulationTaskConfig:
    """The regulation task: the randomised family of regulation loops the envs draw their episodes from.

    How it relates to the benchmark's regulation part
    (:class:`valve_gym.agents.bench.config.RegulationConfig`, inside
    :class:`~valve_gym.agents.bench.config.BenchConfig`): the benchmark fixes one population of
    loops (operating points, one noise level, one load, valves by band and friction model) and runs
    every controller on it; this task draws a loop per episode from *ranges* around it (wider noise,
    load and correlation time by default, a shorter episode) for training and evaluation in the envs.
    :meth:`from_benchmark` gives the task whose draws are the benchmark's regulation loops (the same
    levels' range, noise, load, friction models, bands, band counts and scan time). Formerly also
    named ``RegulationConfig`` (that name is kept, deprecated, for old imports).

    Parameters
    ----------
    episode_s : float, s
        Episode length (the registered time limit is ``episode_s / block.scan_s`` steps).
    levels : (2,) range, m
        Operating points: the constant set point is drawn uniformly here; the loop starts at
        steady state at it.
    noise_std : (2,) range, m
        Standard deviation of the white measurement noise (drawn per episode).
    load_std : (2,) range, m^3/s
        Stationary standard deviation of the Ornstein-Uhlenbeck load inflow (drawn per episode).
    load_tau : (2,) range, s
        Correlation time of the load (drawn log-uniformly per episode).
    friction_models : list of str
        Friction models, drawn uniformly per episode (names of :mod:`valve_gym.friction`, or
        ``riihilahti`` and ``choudhury`` without it).
    S_bands : list of float, fraction of stroke
        Edges of the stiction bands: with ``[0, 0.005, 0.05, 0.10]`` a band (healthy, sticky,
        severe) is drawn with probabilities ``band_weights``, then ``S`` in it.
    band_weights : list of float
        Relative probability of each band (default the benchmark's loop counts 30 : 60 : 45).
    S_log_uniform : list of bool
        Per band: ``S`` log-uniform in the band (``True``; the benchmark's sticky band) or uniform.
    J_frac : (2,) range
        Slip jump as a fraction of ``S`` (``J = S * U(J_frac)``).
    substeps : int
        Euler steps of the plant per scan.
    reward : {'benchmark', 'tracking'}
        ``benchmark`` (default): the episode return is the benchmark's compensation ratio ``R``
        minus a travel-budget and a limit-cycle penalty (:func:`benchmark_reward`);
        ``tracking``: the v0 per-step ``-(|SP - L| / error_scale + travel_weight |dh|)``.
    r_floor : float
        ``benchmark`` reward: floor of ``R``'s denominator as a fraction of the frictionless IAE.
    travel_budget : float
        ``benchmark`` reward: stem travel allowed free, as a multiple of the frictionless PI's travel
        on the same episode.
    budget_weight : float
        ``benchmark`` reward: cost of travel beyond the budget, per frictionless-PI travel.
    lc_weight : float
        ``benchmark`` reward: cost of a limit cycle (the benchmark's detector on the episode's error).
    error_scale : float, m
        ``tracking`` reward: 1 per step at this level error.
    travel_weight : float
        ``tracking`` reward: cost of a full stroke of stem travel, in units of ``error_scale``-seconds.
    block : BlockSettings
    """

    episode_s: float = 1800.0
    levels: Range = (0.6, 1.4)
    noise_std: Range = (0.0003, 0.003)
    load_std: Range = (0.5e-4, 2.0e-4)
    load_tau: Range = (60.0, 300.0)
    friction_models: tuple[str, ...] = BENCHMARK_FRICTION_MODELS
    S_bands: tuple[float, ...] = (0.0, 0.005, 0.05, 0.10)
    band_weights: tuple[float, ...] = (30.0, 60.0, 45.0)
    S_log_uniform: tuple[bool, ...] = (False, True, False)
    J_frac: Range = (0.0, 1.0)
    substeps: int = 20
    reward: str = "benchmark"
    r_floor: float = 0.1
    travel_budget: float = 1.5
    budget_weight: float = 1.0
    lc_weight: float = 0.5
    error_scale: float = 0.01
    travel_weight: float = 2.0
    block: BlockSettings = BlockSettings(stick_features=True)

    def __post_init__(self):
        if not (math.isfinite(self.episode_s) and self.episode_s >= self.block.scan_s):
            raise ConfigError(f"episode_s must be at least one scan, got {self.episode_s!r}")
        check_episode_steps("episode_s", self.episode_s, self.block.scan_s, "block.scan_s")
        _range("levels", self.levels, 0.05, 10.0, open_lo=True)
        _range("noise_std", self.noise_std, 0.0, 1.0)
        _range("load_std", self.load_std, 0.0, 1.0)
        _range("load_tau", self.load_tau, 0.0, 1e6, open_lo=True)
        _range("J_frac", self.J_frac, 0.0, 1.0)
        b = [float(x) for x in self.S_bands]
        if len(b) < 2 or any(y <= x for x, y in zip(b, b[1:])) or b[0] < 0 or b[-1] > 0.5:
            raise ConfigError(f"S_bands must be increasing edges within [0, 0.5], at least two, got {b!r}")
        self._check_bands_and_reward(len(b) - 1, b)
        if not self.friction_models:
            raise ConfigError("friction_models must name at least one friction model")
        known = available_friction_models()
        for m in self.friction_models:
            if m not in known or m == "none":
                raise ConfigError(f"unknown friction model {m!r} in friction_models; available: "
                                  f"{', '.join(x for x in known if x != 'none')}")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ConfigError(f"substeps must be an integer >= 1, got {self.substeps!r}")
        if not self.error_scale > 0 or not self.travel_weight >= 0:
            raise ConfigError("error_scale must be > 0 and travel_weight >= 0")

    def _check_bands_and_reward(self, nb: int, b: list) -> None:
        """Validate ``band_weights``, ``S_log_uniform`` and the reward settings (``nb`` bands, edges ``b``)."""
        w = [float(x) for x in self.band_weights]
        if len(w) != nb or any(not (math.isfinite(x) and x >= 0) for x in w) or sum(w) <= 0:
            raise ConfigError(f"band_weights must be {nb} non-negative numbers (one per band of S_bands) with a "
                              f"positive sum, got {list(self.band_weights)!r}")
        lg = list(self.S_log_uniform)
        if len(lg) != nb or any(not isinstance(x, (bool, np.bool_)) for x in lg):
            raise ConfigError(f"S_log_uniform must be {nb} true/false values (one per band), got {lg!r}")
        if any(x and b[i] <= 0 for i, x in enumerate(lg)):
            raise ConfigError("S_log_uniform: a band starting at S = 0 cannot be log-uniform")
        if self.reward not in REWARDS:
            raise ConfigError(f"reward must be one of {', '.join(REWARDS)}, got {self.reward!r}")
        check_reward_numbers(self, ("r_floor", "travel_budget"))

    @property
    def steps(self) -> int:
        """Scans per episode."""
        return int(round(self.episode_s / self.block.scan_s))

    @classmethod
    def from_benchmark(cls, bench=None, **overrides) -> RegulationTaskConfig:
        """The task of the benchmark's regulation part (``bench``: a BenchConfig, mapping or YAML path).

        Levels drawn in ``[min, max]`` of ``bench.regulation.levels``; the noise, the load's sigma and tau
        fixed at the benchmark's; its friction models; its bands (edges, loop counts as weights, log-uniform
        flags; the bands must be contiguous); ``J`` uniform in ``[0, S]``; an episode of
        ``regulation.duration_s`` at its ``scan_s``; the benchmark reward. ``overrides`` replace fields.

        Examples
        --------
        >>> t = RegulationTaskConfig.from_benchmark()
        >>> t.levels, t.noise_std, t.band_weights, t.steps
        ((0.6, 1.4), (0.002, 0.002), (30.0, 60.0, 45.0), 3600)
        """
        from dataclasses import replace

        from ..agents.bench.config import BAND_NAMES, BenchConfig, load_bench_config

        b = bench if isinstance(bench, BenchConfig) else load_bench_config(bench)
        bands = [getattr(b.bands, name) for name in BAND_NAMES]
        edges = [float(bands[0].S[0])] + [float(x.S[1]) for x in bands]
        if any(float(x.S[0]) != edges[i] for i, x in enumerate(bands)):
            raise ConfigError("the benchmark's bands are not contiguous (each band's S must start where the "
                              "previous one ends); a regulation task needs contiguous S_bands")
        r = b.regulation
        kw = dict(episode_s=float(r.duration_s), levels=(float(min(r.levels)), float(max(r.levels))),
                  noise_std=(float(r.noise_std),) * 2, load_std=(float(r.load.sigma),) * 2,
                  load_tau=(float(r.load.tau),) * 2, friction_models=tuple(b.models), S_bands=tuple(edges),
                  band_weights=tuple(float(x.n) for x in bands),
                  S_log_uniform=tuple(bool(x.log_uniform) for x in bands),
                  J_frac=(0.0, 1.0), reward="benchmark",
                  block=replace(cls.__dataclass_fields__["block"].default, scan_s=float(b.scan_s)))
        kw.update(overrides)
        return cls(**kw)  # type: ignore[arg-type]


def __getattr__(name: str):
    """``RegulationConfig``: the former name of :class:`RegulationTaskConfig` (deprecated)."""
    if name == "RegulationConfig":
        import warnings

        warnings.warn("valve_gym.envs.regulation.RegulationConfig is now RegulationTaskConfig (the benchmark's "
                      "RegulationConfig is its regulation part); import RegulationTaskConfig",
                      DeprecationWarning, stacklevel=2)
        return RegulationTaskConfig
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --------------------------------------------------------------------------- friction
def available_friction_models() -> tuple[str, ...]:
    """Names of the friction models the task can draw."""
    try:
        from ..friction import FRICTION_MODELS  # type: ignore[attr-defined]
    except ImportError:
        return ("none",) + FRICTION_MODELS_FALLBACK
    return tuple(FRICTION_MODELS)


def friction_params(model: str, S, J, base: ModelParams | None = None, dt: float = 0.05) -> ModelParams:
    """Model parameters of valves of friction ``model`` sized by stick band ``S`` and slip jump ``J``.

    Parameters
    ----------
    model : str
        Friction model name.
    S, J : float or (n,) array, fraction of stroke
        Stick band (with dead band) and slip jump, ``0 <= J <= S``.
    base : ModelParams, optional
        Plant (default tank).
    dt : float, s
        Euler step of the plant.

    Returns
    -------
    ModelParams

    Notes
    -----
    Uses :func:`valve_gym.friction.valve_model` where it exists. Without it, ``choudhury``
    is the core's ``slip_jump`` block, and ``riihilahti`` maps ``(S, J)`` onto the paper model
    by a dead band ``2 e_dead = S - J`` and a friction band ``z_max = J^2 / (4 r)`` that gives
    the slip ``J`` for an input ramp of ``r = 1e-3`` stroke/s (about a PI's ramp while stuck).
    """
    from dataclasses import replace

    base = ModelParams() if base is None else base
    try:
        from ..friction import valve_model  # type: ignore[attr-defined]
    except ImportError:
        valve_model = None
    if valve_model is not None:
        p = valve_model(model, S, J, base=base)
        return replace(p, dt=dt)
    S = np.asarray(S, float)
    J = np.asarray(J, float)
    if model == "choudhury":
        return replace(base, dt=dt).with_effect("slip_jump", SlipJump(S=S, J=J, tau_p=0.1))
    if model == "riihilahti":
        v = ValveParams(tau=0.1, v_max=0.5, e_dead=np.maximum(S - J, 0.0) / 2, z_max=J ** 2 / 4e-3)
        return replace(base, valve=v, dt=dt)
    raise ValueError(f"unknown friction model {model!r}; available: {', '.join(FRICTION_MODELS_FALLBACK)}")


# --------------------------------------------------------------------------- draw
class RegulationDraw(NamedTuple):
    """The random quantities of ``n`` regulation episodes (row = episode).

    Fields
    ------
    model : (n,) int, index into ``config.friction_models``
    S, J : (n,) stick band and slip jump [fraction of stroke]
    sp : (n,) constant set point [m]
    noise : (n, H+1) measurement noise of the ``k``-th measurement [m]
    load : (n, H+1) extra inflow during step ``k`` [m^3/s] (``load[:, 0] = 0``: steady start)
    """

    model: np.ndarray
    S: np.ndarray
    J: np.ndarray
    sp: np.ndarray
    noise: np.ndarray
    load: np.ndarray


def draw_scenarios(rngs: Sequence[np.random.Generator], cfg: RegulationTaskConfig) -> RegulationDraw:
    """Draw ``len(rngs)`` episodes, row ``j`` from ``rngs[j]`` only (a batch draw equals single draws).

    Each generator gives 8 uniforms, then ``2 (H + 1)`` standard normals, whatever the values.
    The band is drawn with probabilities ``band_weights``, ``S`` uniformly or (``S_log_uniform``)
    log-uniformly in it.
    """
    n, H = len(rngs), cfg.steps
    U = np.empty((n, 8))
    Z = np.empty((n, 2, H + 1))
    for j, g in enumerate(rngs):
        g.random(out=U[j])
        g.standard_normal(out=Z[j])
    nm = len(cfg.friction_models)
    model = np.minimum((U[:, 0] * nm).astype(np.int64), nm - 1)
    edges = np.asarray(cfg.S_bands, float)
    nb = len(edges) - 1
    w = np.asarray(cfg.band_weights, float)
    if np.all(w == w[0]):
        band = np.minimum((U[:, 1] * nb).astype(np.int64), nb - 1)
    else:
        band = np.minimum(np.searchsorted(np.cumsum(w) / w.sum(), U[:, 1], side="right"), nb - 1)
    lo, hi = edges[band], edges[band + 1]
    S = lo + U[:, 2] * (hi - lo)
    lg = np.asarray(cfg.S_log_uniform, bool)[band]
    if lg.any():
        S = np.where(lg, np.maximum(lo, 1e-300) * (hi / np.maximum(lo, 1e-300)) ** U[:, 2], S)
    J = S * (cfg.J_frac[0] + U[:, 3] * (cfg.J_frac[1] - cfg.J_frac[0]))
    sp = cfg.levels[0] + U[:, 4] * (cfg.levels[1] - cfg.levels[0])
    nstd = cfg.noise_std[0] + U[:, 5] * (cfg.noise_std[1] - cfg.noise_std[0])
    lstd = cfg.load_std[0] + U[:, 6] * (cfg.load_std[1] - cfg.load_std[0])
    lt0, lt1 = cfg.load_tau
    ltau = lt0 * np.exp(U[:, 7] * math.log(lt1 / lt0))
    noise = Z[:, 0] * nstd[:, None]
    load = ou_sequence(Z[:, 1], np.exp(-cfg.block.scan_s / ltau), lstd)
    return RegulationDraw(model=model, S=S, J=J, sp=sp, noise=noise, load=load)


# --------------------------------------------------------------------------- plants
class LoopPlants:
    """The plants of a batch of loops, one packed group per friction model.

    Parameters
    ----------
    cfg : RegulationTaskConfig
    draw : RegulationDraw
        The episodes (their valves and operating points).
    frictionless : (n,) bool array, optional
        Loops run on their frictionless valve (``valve_model('none')``: the same actuator, no friction).

    Attributes
    ----------
    level : (n,) true level [m]
    stem : (n,) stem position [fraction of stroke]
    op0 : (n,) the steady valve input at the set point [fraction of stroke]
    """

    def __init__(self, cfg: RegulationTaskConfig, draw: RegulationDraw, frictionless=None):
        n = draw.sp.shape[0]
        free = np.zeros(n, bool) if frictionless is None else np.broadcast_to(np.asarray(frictionless, bool), (n,))
        self.n = n
        self.substeps = cfg.substeps
        dt = cfg.block.scan_s / cfg.substeps
        self.groups = []
        self.level = np.empty(n)
        self.stem = np.empty(n)
        self.op0 = np.empty(n)
        groups = [(m, name, False) for m, name in enumerate(cfg.friction_models)]
        if free.any():
            groups.append((-1, "none", True))
        for m, name, fl in groups:
            idx = np.flatnonzero(free) if fl else np.flatnonzero((draw.model == m) & ~free)
            if idx.size == 0:
                continue
            params = friction_params(name, draw.S[idx], draw.J[idx], dt=dt)
            pk = core.pack(params, idx.size)
            st = core.initial_state(params, idx.size, level=draw.sp[idx])
            S = core.state_to_array(st)
            buf = np.ascontiguousarray(st.delay_buf, dtype=np.float64)
            out = np.zeros((3, 1, idx.size))
            self.groups.append((idx, pk, S, buf, np.zeros((1, idx.size)), np.zeros((1, idx.size)), out))
            self.level[idx] = st.level
            self.stem[idx] = np.clip(st.h, 0.0, 1.0)
            self.op0[idx] = st.h

    def step(self, u: np.ndarray, d: np.ndarray) -> None:
        """Advance every loop one scan with valve input ``u`` (n,) and extra inflow ``d`` (n,) [m^3/s]."""
        for idx, pk, S, buf, U, D, out in self.groups:
            U[0] = u[idx]
            D[0] = d[idx]
            core.run_packed(pk, S, buf, U, D, self.substeps, out[0], out[1], out[2])
            self.level[idx] = out[2, 0]
            self.stem[idx] = out[1, 0]


# --------------------------------------------------------------------------- block law
#: Names of the observation entries (all from SP, PV and the block's own output).
OBS_NAMES = ("e", "e_ema4", "e_ema16", "e_ema64", "e_ema256", "de_abs_ema64", "u_minus_ema64",
             "u_minus_ema256", "du_ema16", "c_prev", "g_prev")
N_OBS = len(OBS_NAMES)
#: Stickiness features appended when ``BlockSettings.stick_features`` is set: the output's move since
#: the filtered error last changed sign (did the loop respond to what the block did?), the time since
#: then, and the filtered error over the noise estimate (inside or outside the noise band).
STICK_OBS_NAMES = ("u_since_e_flip", "t_since_e_flip", "e_ema16_over_noise")
N_ACT = 2


def obs_names(settings: BlockSettings) -> tuple[str, ...]:
    """Names of the observation entries of a block with ``settings`` (its length is the network's input)."""
    return OBS_NAMES + (STICK_OBS_NAMES if settings.stick_features else ())

_E_TAUS = (4.0, 16.0, 64.0, 256.0)


# state rows of BlockLaw.X and parameter slots of BlockLaw.LP (the compiled law reads them by index)
_XE, _XEP, _XEMA, _XDE, _XU, _XU64, _XU256, _XDU, _XC, _XG, _XI, _XUF, _XTF = \
    0, 1, 2, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15
_NX = 16
_PKC, _PKI, _PTS, _PCM, _PGM, _PLO, _PHI, _PER, _PUR, _PAE, _PA64, _PA256, _PA16, _PSTICK = \
    0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 14, 15, 16
_NP = 17


@njit(cache=True, nogil=True)
def _law_observe(X, LP, sp, pv, obs):  # pragma: no cover - compiled
    """:meth:`BlockLaw.observe` for every loop (columns of ``X``); writes ``obs`` (n, n_obs)."""
    n = X.shape[1]
    e_ref, u_ref, cm, gm = LP[_PER], LP[_PUR], LP[_PCM], LP[_PGM]
    for i in range(n):
        e = sp[i] - pv[i]
        X[_XEP, i] = X[_XE, i]
        X[_XE, i] = e
        e16_prev = X[_XEMA + 1, i]
        for j in range(4):
            X[_XEMA + j, i] += LP[_PAE + j] * (e - X[_XEMA + j, i])
        X[_XDE, i] += LP[_PA64] * (abs(e - X[_XEP, i]) - X[_XDE, i])
        obs[i, 0] = e / e_ref
        for j in range(4):
            obs[i, 1 + j] = X[_XEMA + j, i] / e_ref
        obs[i, 5] = X[_XDE, i] / e_ref
        obs[i, 6] = (X[_XU, i] - X[_XU64, i]) / u_ref
        obs[i, 7] = (X[_XU, i] - X[_XU256, i]) / u_ref
        obs[i, 8] = X[_XDU, i] / (0.1 * u_ref)
        obs[i, 9] = X[_XC, i] / cm if cm > 0 else 0.0
        obs[i, 10] = 2.0 * (X[_XG, i] - gm) / (1.0 - gm) - 1.0 if gm < 1 else 1.0
        if LP[_PSTICK] > 0:
            e16 = X[_XEMA + 1, i]
            if np.sign(e16) != np.sign(e16_prev):
                X[_XUF, i] = X[_XU, i]
                X[_XTF, i] = 0.0
            else:
                X[_XTF, i] = X[_XTF, i] + LP[_PTS]
            obs[i, 11] = (X[_XU, i] - X[_XUF, i]) / u_ref
            obs[i, 12] = X[_XTF, i] / 100.0
            obs[i, 13] = e16 / max(X[_XDE, i], 1e-4)
        for j in range(obs.shape[1]):
            obs[i, j] = min(max(obs[i, j], -10.0), 10.0)


@njit(cache=True, nogil=True)
def _law_act(X, LP, action, first, u_out):  # pragma: no cover - compiled
    """:meth:`BlockLaw.act` for every loop: applies ``action`` (n, 2), writes the output ``u_out`` (n,)."""
    n = X.shape[1]
    kc, ki, cm, gm, lo, hi = LP[_PKC], LP[_PKI], LP[_PCM], LP[_PGM], LP[_PLO], LP[_PHI]
    for i in range(n):
        ag = min(max(action[i, 0], -1.0), 1.0)
        ac = min(max(action[i, 1], -1.0), 1.0)
        g = gm + (1.0 - gm) * 0.5 * (ag + 1.0)
        c = cm * ac
        e = X[_XE, i]
        if first:
            X[_XI, i] = X[_XI, i] - c
        u, X[_XI, i] = pi_scan1(X[_XI, i], e, kc, ki, g, c, lo, hi, False)
        du = u - X[_XU, i]
        X[_XDU, i] += LP[_PA16] * (du - X[_XDU, i])
        X[_XU64, i] += LP[_PA64] * (u - X[_XU64, i])
        X[_XU256, i] += LP[_PA256] * (u - X[_XU256, i])
        X[_XU, i] = u
        X[_XC, i] = c
        X[_XG, i] = g
        u_out[i] = u


class BlockLaw:
    """Observation and output law of the regulation block for ``n`` loops (explicit state arrays).

    Parameters
    ----------
    settings : BlockSettings
    n : int
        Number of loops.

    Notes
    -----
    Observation (``N_OBS`` values, see :data:`OBS_NAMES`), with ``e = SP - PV``, error scale
    ``e_ref`` and output scale ``u_ref``: ``e / e_ref``; exponential moving averages of ``e``
    with time constants 4, 16, 64 and 256 scans, over ``e_ref``; the moving average of
    ``|e_k - e_k-1|`` (64 scans), over ``e_ref`` (a noise estimate); the last output minus its
    moving averages (64, 256 scans), over ``u_ref``; the moving average of the output change
    (16 scans), over ``u_ref / 10``; the last correction over ``c_max`` and the last gate
    mapped to [-1, 1]. With ``stick_features``: ``(u - u_f) / u_ref`` with ``u_f`` the output
    when the 16-scan average of ``e`` last changed sign, the scans since then over 100, and that
    average over ``max(de_abs, 1e-4)``. All clipped to [-10, 10]. The action law is in the module
    Notes. The state is one ``(16, n)`` array ``X`` (the attributes ``e``, ``I``, ``u``, ... are
    views of its rows) advanced by two compiled functions, one call per scan each.
    """

    def __init__(self, settings: BlockSettings, n: int):
        self.s = settings
        self.n = int(n)
        self.ki = integral_gain(settings.Kc, settings.Ti, settings.scan_s)
        self._alpha_e = np.array([1.0 - math.exp(-settings.scan_s / t) for t in _E_TAUS])
        self._a64 = 1.0 - math.exp(-settings.scan_s / 64.0)
        self._a256 = 1.0 - math.exp(-settings.scan_s / 256.0)
        self._a16 = 1.0 - math.exp(-settings.scan_s / 16.0)
        self.n_obs = len(obs_names(settings))
        LP = np.zeros(_NP)
        LP[[_PKC, _PKI, _PTS, _PCM, _PGM, _PLO, _PHI, _PER, _PUR]] = (
            settings.Kc, self.ki, settings.scan_s, settings.c_max, settings.g_min, settings.op_lo, settings.op_hi,
            settings.e_ref, settings.u_ref)
        LP[_PAE:_PAE + 4] = self._alpha_e
        LP[_PA64], LP[_PA256], LP[_PA16] = self._a64, self._a256, self._a16
        LP[_PSTICK] = 1.0 if settings.stick_features else 0.0
        self.LP = LP
        self.X = np.zeros((_NX, self.n))
        self._obs = np.empty((self.n, self.n_obs))
        self._u = np.empty(self.n)
        self._views()

    def _views(self) -> None:
        X = self.X
        for name, row in (("e", _XE), ("e_prev", _XEP), ("de_abs", _XDE), ("u", _XU), ("u_ema64", _XU64),
                          ("u_ema256", _XU256), ("du_ema", _XDU), ("c", _XC), ("g", _XG), ("I", _XI),
                          ("u_flip", _XUF), ("t_flip", _XTF)):
            setattr(self, name, X[row])
        self.ema_e = X[_XEMA:_XEMA + 4].T

    def reset(self, sp, pv, op) -> None:
        """Bumpless start: the output stays at ``op`` on the first scan if ``pv`` does not move.

        The integrator starts at ``op - K_c e`` and absorbs the correction of the first scan.
        """
        sp = np.broadcast_to(np.asarray(sp, float), (self.n,))
        pv = np.broadcast_to(np.asarray(pv, float), (self.n,))
        op = np.broadcast_to(np.asarray(op, float), (self.n,)).astype(float)
        e = sp - pv
        X = self.X
        X[:] = 0.0
        X[_XE] = e
        X[_XEP] = e
        X[_XEMA:_XEMA + 4] = e
        for row in (_XU, _XU64, _XU256, _XUF):
            X[row] = op
        X[_XG] = 1.0
        X[_XI] = op - self.s.Kc * e
        self._first = True

    def observe(self, sp, pv, out: np.ndarray | None = None) -> np.ndarray:
        """Take a measurement; returns the observation ``(n, n_obs)`` float64 for this scan.

        A new array, or ``out`` when given.
        """
        sp = np.broadcast_to(np.asarray(sp, float), (self.n,))
        pv = np.broadcast_to(np.asarray(pv, float), (self.n,))
        obs = np.empty((self.n, self.n_obs)) if out is None else out
        _law_observe(self.X, self.LP, sp, pv, obs)
        return obs

    def act(self, action: np.ndarray) -> np.ndarray:
        """Apply ``action`` (n, 2) in [-1, 1] (clipped) to this scan; returns the output ``u`` (n,)."""
        a = np.asarray(action, float).reshape(self.n, N_ACT)
        u = np.empty(self.n)
        _law_act(self.X, self.LP, a, self._first, u)
        self._first = False
        return u

    def state_arrays(self) -> dict:
        """Copies of the state arrays (for tests and checkpoints)."""
        return {k: np.array(getattr(self, k)) for k in ("e", "e_prev", "ema_e", "de_abs", "u", "u_ema64",
                                                         "u_ema256", "du_ema", "c", "g", "I", "u_flip",
                                                         "t_flip")}


def pi_action(n: int) -> np.ndarray:
    """The action that makes :class:`BlockLaw` the plain PI: gate 1, no correction; shape (n, 2)."""
    a = np.zeros((n, N_ACT))
    a[:, 0] = 1.0
    return a


OPTION_KEYS = ("model", "S", "J", "level", "frictionless")


def parse_options(options, cfg: RegulationTaskConfig, n: int) -> dict:
    """Validate ``reset(options=...)``: pins of the episode's friction model, ``S``, ``J`` and set point.

    Parameters
    ----------
    options : mapping or None
        ``model`` (a name of ``cfg.friction_models``), ``S`` and ``J`` (fraction of stroke,
        ``0 <= J <= S <= 0.5``), ``level`` (set point, m, within ``cfg.levels`` widened to
        [0.05, 10]); each a scalar or an ``(n,)`` array.
    cfg : RegulationTaskConfig
    n : int
        Number of sub-environments.

    Returns
    -------
    dict of str to (n,) arrays (``model`` as indices)

    Raises
    ------
    ValueError
        Naming the option and the allowed values.
    """
    if options is None:
        return {}
    if not hasattr(options, "items"):
        raise ValueError(f"options must be a dict, got {type(options).__name__}")
    pins = {}
    for key, val in options.items():
        if key not in OPTION_KEYS:
            raise ValueError(f"unknown reset option {key!r}; the options are {', '.join(OPTION_KEYS)} "
                             f"(e.g. reset(options={{'model': 'choudhury', 'S': 0.03, 'J': 0.01}}))")
        if key == "frictionless":
            fa = np.broadcast_to(np.asarray(val), (n,)) if np.size(val) in (1, n) else None
            if fa is None or fa.dtype != bool:
                raise ValueError(f"reset option 'frictionless' must be true/false (or {n} of them), got {val!r}")
            pins["frictionless"] = fa.copy()
            continue
        if key == "model":
            names = [val] * n if isinstance(val, str) else list(val) if isinstance(val, (list, tuple)) else None
            if names is None or len(names) != n or any(m not in cfg.friction_models for m in names):
                raise ValueError(f"reset option 'model' must be one of {list(cfg.friction_models)} "
                                 f"(or a list of {n} of them), got {val!r}")
            pins["model"] = np.array([cfg.friction_models.index(m) for m in names])
            continue
        try:
            a = np.broadcast_to(np.asarray(val, dtype=float), (n,)).copy()
        except (TypeError, ValueError):
            raise ValueError(f"reset option {key!r} must be a number or {n} numbers, got {val!r}") from None
        lo, hi = (0.05, 10.0) if key == "level" else (0.0, 0.5)
        if not np.all(np.isfinite(a)) or a.min() < lo or a.max() > hi:
            raise ValueError(f"reset option {key!r} must be finite and within [{lo}, {hi}], got {val!r}")
        pins[key] = a
    if "J" in pins and np.any(pins["J"] > pins.get("S", np.full(n, np.inf)) + 1e-12):
        raise ValueError("reset option 'J' (slip jump) must not exceed 'S' (stick band); pin both, J <= S")
    return pins


def step_reward(cfg: RegulationTaskConfig, level_err: np.ndarray, stem_move: np.ndarray) -> np.ndarray:
    """Reward of one scan: ``-(|SP - L| / error_scale + travel_weight * |dh| / error_scale * ...)``.

    Parameters
    ----------
    cfg : RegulationTaskConfig
    level_err : (n,) true level error ``SP - L`` after the scan [m]
    stem_move : (n,) stem travel during the scan [fraction of stroke]

    Returns
    -------
    (n,) reward

    Notes
    -----
    ``r_k = -(|SP - L_k+1| / e_s + w_h |h_k+1 - h_k|)``: the return is ``-(IAE / (e_s T_s) +
    w_h travel)``, with IAE of the true level (not the noisy measurement) and the stem travel
    (privileged signals: only the policy's inputs are restricted).
    """
    return -(np.abs(level_err) / cfg.error_scale + cfg.travel_weight * np.abs(stem_move))


class References:
    """The benchmark's two references of ``n`` episodes, run once at reset with the episodes' noise and load.

    Attributes
    ----------
    abs_err_pi : (n, H) ``|SP - PV|`` of the SIMC PI (``pi_action``) on the episode's sticky valve after each scan [m]
    iae_pi, iae_0 : (n,) summed ``|SP - PV|`` of that PI and of the PI on the frictionless valve [m scans]
    travel_0 : (n,) stem travel of the PI on the frictionless valve [full strokes]
    denom : (n,) ``max(iae_pi - iae_0, r_floor iae_0)``: ``R``'s denominator
    """

    def __init__(self, abs_err_pi, iae_0, travel_0, r_floor: float):
        self.abs_err_pi = abs_err_pi
        self.iae_pi = abs_err_pi.sum(axis=1)
        self.iae_0 = iae_0
        self.travel_0 = np.maximum(travel_0, 1e-6)
        self.denom = np.maximum(np.maximum(self.iae_pi - iae_0, r_floor * iae_0), 1e-12)


@njit(cache=True, nogil=True)
def _pi_loops(X, LP, S, P, flags, buf, n_sub, dt, stem0, sp, noise, load, obs, err, travel):  # pragma: no cover
    """The SIMC PI (gate 1, no correction) in closed loop with one packed plant group over ``err.shape[1]`` scans.

    Writes ``err[:, k] = |sp - pv|`` after scan ``k`` and the stem travel ``travel`` (n,).
    """
    n, H = err.shape
    act = np.zeros((n, 2))
    act[:, 0] = 1.0
    U = np.empty((1, n))
    D = np.empty((1, n))
    Y = np.empty((1, n))
    Hh = np.empty((1, n))
    LV = np.empty((1, n))
    u = np.empty(n)
    pv = np.empty(n)
    stem = stem0.copy()
    for k in range(H):
        _law_act(X, LP, act, k == 0, u)
        for i in range(n):
            U[0, i] = u[i]
            D[0, i] = load[i, k]
        core._kernel(S, P, U, D, flags, buf, n_sub, dt, Y, Hh, LV)
        for i in range(n):
            travel[i] += abs(Hh[0, i] - stem[i])
            stem[i] = Hh[0, i]
            pv[i] = LV[0, i] + noise[i, k + 1]
            err[i, k] = abs(sp[i] - pv[i])
        _law_observe(X, LP, sp, pv, obs)


@njit(cache=True, nogil=True)
def _scan1(X, LP, A, first, S, P, flags, buf, n_sub, dt, W, load_k, noise_k1, sp, obs):  # pragma: no cover
    """One scan of one loop (one plant group): block law, plant, measurement, observation in one call.

    ``W`` (5, 1) holds the kernel's ``U, D, Y, H, LV`` rows. Returns ``(u, level, stem, pv)``.
    """
    u = np.empty(1)
    _law_act(X, LP, A, first, u)
    W[0, 0] = u[0]
    W[1, 0] = load_k
    core._kernel(S, P, W[0:1], W[1:2], flags, buf, n_sub, dt, W[2:3], W[3:4], W[4:5])
    level = W[4, 0]
    pv = level + noise_k1
    spa = np.empty(1)
    spa[0] = sp
    pva = np.empty(1)
    pva[0] = pv
    _law_observe(X, LP, spa, pva, obs)
    return u[0], level, W[3, 0], pv


def reference_runs(cfg: RegulationTaskConfig, draw: RegulationDraw) -> References:
    """Run the SIMC PI on each episode's sticky valve and on its frictionless valve (the benchmark's references).

    Both see the episode's measurement noise and load, so ``R`` of a controller on the episode is the
    benchmark's paired ratio (:func:`valve_gym.agents.bench.scores.compensation_ratio`). One compiled
    closed-loop run per plant group (:class:`BlockLaw` with the PI action and the core kernel).
    """
    n, H = draw.sp.shape[0], cfg.steps
    d2 = RegulationDraw(*(np.concatenate([a, a]) for a in draw))
    plants = LoopPlants(cfg, d2, frictionless=np.repeat([False, True], n))
    err = np.empty((2 * n, H))
    travel = np.zeros(2 * n)
    noise = np.ascontiguousarray(d2.noise)
    load = np.ascontiguousarray(d2.load)
    for idx, pk, S, buf, _U, _D, _out in plants.groups:
        m = idx.size
        law = BlockLaw(cfg.block, m)
        sp = np.ascontiguousarray(d2.sp[idx])
        law.reset(sp, plants.level[idx] + noise[idx, 0], plants.op0[idx])
        e_g, t_g = np.empty((m, H)), np.zeros(m)
        _pi_loops(law.X, law.LP, S, pk.P, pk.flags, buf, plants.substeps, pk.dt, plants.stem[idx].copy(), sp,
                  noise[idx], load[idx], np.empty((m, law.n_obs)), e_g, t_g)
        err[idx], travel[idx] = e_g, t_g
    return References(err[:n], err[n:].sum(axis=1), travel[n:], cfg.r_floor)


def benchmark_reward(cfg: RegulationTaskConfig, refs: References, k: int, abs_err: np.ndarray,
                     excess_prev: np.ndarray, travel: np.ndarray, lc_present: np.ndarray | None = None):
    r"""Reward of scan ``k`` of the ``benchmark`` reward, and the travel excess after it.

    Parameters
    ----------
    cfg : RegulationTaskConfig
    refs : References
        The episode's references (:func:`reference_runs`).
    k : int
        Scan index (0-based).
    abs_err : (n,) ``|SP - PV|`` after the scan [m]
    excess_prev : (n,) travel beyond the budget before the scan [full strokes]
    travel : (n,) stem travel of the episode so far, this scan included [full strokes]
    lc_present : (n,) bool, optional
        The limit-cycle verdict on the episode's error; given on the last scan only.

    Returns
    -------
    reward : (n,)
    excess : (n,)

    Notes
    -----
    .. math::

        r_k = \frac{|e^{PI}_k| - |e_k|}{D}
              - w_b \frac{x_k - x_{k-1}}{T_0}
              - w_{lc} [\text{LC}]_{k = H-1},\qquad
        x_k = \max(0, T_k - \beta T_0)

    with ``D = max(IAE_PI - IAE_0, f IAE_0)`` (``f = r_floor``), ``T_k`` the stem travel so far and
    ``T_0`` the frictionless PI's travel over the episode. The return is therefore

    .. math:: G = R - w_b \max(0, T / T_0 - \beta) - w_{lc} [\text{LC}]

    where ``R`` is the benchmark's compensation ratio of the episode (1: all of stiction's IAE cost
    removed, 0: the PI's, < 0 worse), ``beta = travel_budget``, ``w_b = budget_weight`` and
    ``w_lc = lc_weight``.
    """
    excess = np.maximum(travel - cfg.travel_budget * refs.travel_0, 0.0)
    r = (refs.abs_err_pi[:, k] - abs_err) / refs.denom - cfg.budget_weight * (excess - excess_prev) / refs.travel_0
    if lc_present is not None:
        r = r - cfg.lc_weight * np.asarray(lc_present, float)
    return r, excess
