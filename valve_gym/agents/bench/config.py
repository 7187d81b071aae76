"""Benchmark configuration: ``configs/benchmark.yaml`` onto frozen dataclasses.

Every number that defines a benchmark run lives here (valve population, the
two parts' scenarios, the controller line-up, the scoring rules), with its
unit. The YAML file holds nested mappings with the same names; keys left out
keep these defaults, and an unknown or mistyped key is a
:class:`~valve_gym.config.ConfigError` naming its key path.

Examples
--------
>>> cfg = load_bench_config({"bands": {"sticky": {"n": 30}}})
>>> cfg.bands.sticky.n, cfg.bands.severe.S
(30, (0.05, 0.1))
>>> try:
...     load_bench_config({"bands": {"stiky": {}}})
... except ValueError as exc:
...     print(exc)
unknown key 'bands.stiky' (did you mean 'sticky'?); the keys of 'bands' are: healthy, sticky, severe
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from valve_gym.config import MAX_EPISODE_STEPS, ConfigError, check_count, config_to_dict, load_config

__all__ = ["Band", "Bands", "OULoad", "RegulationConfig", "ServoConfig", "ControllersConfig", "ScoresConfig",
           "QuickConfig", "BenchConfig", "load_bench_config", "bench_config_to_dict", "DEFAULT_CONFIG_PATH",
           "BAND_NAMES"]

Range = tuple[float, float]

#: Band names, in table order.
BAND_NAMES = ("healthy", "sticky", "severe")

#: The configuration file of a source checkout (equal to the defaults of :class:`BenchConfig`).
DEFAULT_CONFIG_PATH = Path(__file__).resolve().parents[3] / "configs" / "benchmark.yaml"


def _check_range(path: str, r: Range, lo: float, hi: float) -> None:
    if not (lo <= r[0] <= r[1] <= hi):
        raise ConfigError(f"{path} must be [low, high] with {lo} <= low <= high <= {hi}, got {list(r)!r}")


def _check_pos(path: str, v: float, strict: bool = True) -> None:
    if (v <= 0.0) if strict else (v < 0.0):
        raise ConfigError(f"{path} must be {'>' if strict else '>='} 0, got {v!r}")


#: Most valves of one band (per part): the benchmark simulates every one, twice (10^5 loops are days of CPU).
MAX_BAND_N = 100_000
#: Fewest controller scans in a record, a servo interval or a quick record (the oscillation detector needs 16).
MIN_SCANS = 32


@dataclass(frozen=True)
class Band:
    """One stiction band of the valve population.

    Parameters
    ----------
    n : int
        Valves of this band per part (>= 0).
    S : (2,) fraction of stroke
        Range of the stick band ``S`` (0 <= low <= high <= 0.5).
    log_uniform : bool
        Draw ``S`` log-uniformly (needs low > 0), else uniformly. ``J`` is always uniform on ``[0, S]``.
    """

    n: int = 0
    S: Range = (0.0, 0.005)
    log_uniform: bool = False

    def __post_init__(self):
        if self.n < 0:
            raise ConfigError(f"n must be >= 0, got {self.n}")
        if self.n:
            check_count("n", self.n, MAX_BAND_N, "valves per band and part; each is a simulated loop of its own")
        _check_range("S", self.S, 0.0, 0.5)
        if self.log_uniform and self.S[0] <= 0.0:
            raise ConfigError(f"S is drawn log-uniformly and needs low > 0, got {list(self.S)!r}")


@dataclass(frozen=True)
class Bands:
    """The valve population by stiction band (fraction of stroke), the same valves in both parts."""

    healthy: Band = field(default_factory=lambda: Band(n=30, S=(0.0, 0.005)))
    sticky: Band = field(default_factory=lambda: Band(n=60, S=(0.005, 0.05), log_uniform=True))
    severe: Band = field(default_factory=lambda: Band(n=45, S=(0.05, 0.10)))


@dataclass(frozen=True)
class OULoad:
    """Ornstein-Uhlenbeck load inflow ``d`` (extra inflow into the tank).

    ``d[k+1] = a d[k] + sigma sqrt(1 - a^2) w[k]``, ``a = exp(-scan_s / tau)``, ``d[0] = 0``.

    Parameters
    ----------
    sigma : float, m^3/s
        Stationary standard deviation (>= 0).
    tau : float, s
        Correlation time (> 0).
    """

    sigma: float = 1.0e-4
    tau: float = 120.0

    def __post_init__(self):
        _check_pos("sigma", self.sigma, strict=False)
        _check_pos("tau", self.tau)


@dataclass(frozen=True)
class RegulationConfig:
    """Regulation part: constant set point, load and noise, starting at steady state.

    The envs' randomised regulation task is :class:`valve_gym.envs.regulation.RegulationTaskConfig`;
    ``RegulationTaskConfig.from_benchmark(bench_config)`` is the task whose draws are these loops.

    Parameters
    ----------
    duration_s : float, s
        Length of each loop's record (> 0).
    levels : tuple of float, m
        Operating points (constant set points); loops cycle through them.
    load : OULoad
    noise_std : float, m
        White measurement noise on the level (>= 0).
    """

    duration_s: float = 3600.0
    levels: tuple[float, ...] = (0.6, 1.0, 1.4)
    load: OULoad = field(default_factory=OULoad)
    noise_std: float = 0.002

    def __post_init__(self):
        _check_pos("duration_s", self.duration_s)
        if not self.levels or min(self.levels) <= 0.0:
            raise ConfigError(f"levels must be a non-empty list of levels > 0 m, got {list(self.levels)!r}")
        _check_pos("noise_std", self.noise_std, strict=False)


@dataclass(frozen=True)
class ServoConfig:
    """Servo part: set-point steps of alternating sign every ``interval_s``.

    Parameters
    ----------
    duration_s : float, s
    levels : tuple of float, m
        Starting set points (the loop starts at steady state there).
    step : float, m
        Step size (> 0); the set point steps up, back, down, back, ...
    interval_s : float, s
        Time between steps (> 0).
    load : OULoad
    noise_std : float, m
    """

    duration_s: float = 2400.0
    levels: tuple[float, ...] = (0.8, 1.0, 1.2)
    step: float = 0.2
    interval_s: float = 400.0
    load: OULoad = field(default_factory=lambda: OULoad(sigma=0.5e-4))
    noise_std: float = 0.002

    def __post_init__(self):
        _check_pos("duration_s", self.duration_s)
        _check_pos("step", self.step)
        _check_pos("interval_s", self.interval_s)
        if not self.levels or min(self.levels) - self.step <= 0.0:
            raise ConfigError(f"levels must be > step = {self.step} m, got {list(self.levels)!r}")
        _check_pos("noise_std", self.noise_std, strict=False)


@dataclass(frozen=True)
class ControllersConfig:
    """The controller line-up (every block through :func:`valve_gym.agents.load_controller`).

    Parameters
    ----------
    detune : tuple of float
        Factors on the SIMC ``Kc`` of the re-tuned PIs (``Ti`` kept), each in (0, 4] and not 1:
        below 1 the detuned PI (the usual plant answer to a sticky valve), above 1 a tighter PI;
        together they trace the IAE-vs-travel Pareto front over ``Kc`` that any compensator must beat.
    compensators : tuple of str
        Compensator names for ``load_controller``; each gets the loop's stiction estimate ``S``.
    estimate_factors : tuple of float
        The estimate given to each compensator is ``factor * S_true`` (1.0 first: the headline row).
    learned : bool
        Include ``load_controller("learned")`` and every other registered ``learned_*`` block (each
        skipped with a note when it cannot be loaded).
    """

    detune: tuple[float, ...] = (2.0, 1.5, 0.7, 0.5, 0.35, 0.25)
    compensators: tuple[str, ...] = ("knocker", "constant_reinforcement", "two_move", "integral_freeze")
    estimate_factors: tuple[float, ...] = (1.0, 0.5, 1.5)
    learned: bool = True

    def __post_init__(self):
        if any(not (0.0 < k <= 4.0) or k == 1.0 for k in self.detune):
            raise ConfigError(f"detune factors must be in (0, 4] and not 1 (the SIMC PI runs anyway), "
                              f"got {list(self.detune)!r}")
        if not self.estimate_factors or self.estimate_factors[0] != 1.0 or min(self.estimate_factors) <= 0:
            raise ConfigError(f"estimate_factors must start with 1.0 and be > 0, got {list(self.estimate_factors)!r}")


@dataclass(frozen=True)
class ScoresConfig:
    """Scoring rules.

    Parameters
    ----------
    r_floor : float
        Floor of the denominator of the compensation ratio, as a fraction of the frictionless PI's IAE (> 0).
    reversal_deadband : float, fraction of stroke
        Moves of the stem smaller than this are not counted as reversals (>= 0).
    n_boot : int
        Bootstrap resamples of the confidence intervals (>= 100).
    ci : float
        Confidence level (0.5 < ci < 1).
    """

    r_floor: float = 0.1
    reversal_deadband: float = 0.0005
    n_boot: int = 2000
    ci: float = 0.95

    def __post_init__(self):
        _check_pos("r_floor", self.r_floor)
        _check_pos("reversal_deadband", self.reversal_deadband, strict=False)
        if self.n_boot < 100:
            raise ConfigError(f"n_boot must be >= 100, got {self.n_boot}")
        if not 0.5 < self.ci < 1.0:
            raise ConfigError(f"ci must be in (0.5, 1), got {self.ci}")


@dataclass(frozen=True)
class QuickConfig:
    """``--quick``: a smoke run of a few loops (seconds).

    Parameters
    ----------
    n_per_band : int
        Valves per band and part (>= 1).
    duration_s : float, s
        Record length of both parts (> 0).
    n_boot : int
        Bootstrap resamples (>= 100).
    """

    n_per_band: int = 3
    duration_s: float = 600.0
    n_boot: int = 200

    def __post_init__(self):
        if self.n_per_band < 1:
            raise ConfigError(f"n_per_band must be >= 1, got {self.n_per_band}")
        _check_pos("duration_s", self.duration_s)
        if self.n_boot < 100:
            raise ConfigError(f"n_boot must be >= 100, got {self.n_boot}")


@dataclass(frozen=True)
class BenchConfig:
    """Everything that defines a benchmark run (YAML: ``configs/benchmark.yaml``).

    Parameters
    ----------
    seed : int
        Seed of the valve draw, loads, noise and bootstrap.
    scan_s : float, s
        Controller scan time (> 0).
    models : tuple of str
        Friction models (names of :data:`valve_gym.friction.FRICTION_MODELS`); loops cycle through them.
    bands : Bands
    regulation : RegulationConfig
    servo : ServoConfig
    controllers : ControllersConfig
    scores : ScoresConfig
    quick : QuickConfig
    """

    seed: int = 20261123
    scan_s: float = 1.0
    models: tuple[str, ...] = ("riihilahti", "choudhury", "kano")
    bands: Bands = field(default_factory=Bands)
    regulation: RegulationConfig = field(default_factory=RegulationConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    controllers: ControllersConfig = field(default_factory=ControllersConfig)
    scores: ScoresConfig = field(default_factory=ScoresConfig)
    quick: QuickConfig = field(default_factory=QuickConfig)

    def __post_init__(self):
        _check_pos("scan_s", self.scan_s)
        for path, span in (("regulation.duration_s", self.regulation.duration_s),
                           ("servo.duration_s", self.servo.duration_s),
                           ("servo.interval_s", self.servo.interval_s),
                           ("quick.duration_s", self.quick.duration_s)):
            n = span / self.scan_s
            if n < MIN_SCANS:
                raise ConfigError(f"scan_s = {self.scan_s:g} s leaves {path} = {span:g} s only {n:.3g} scans; "
                                  f"give at least {MIN_SCANS} scans (scan_s <= {span / MIN_SCANS:g} s) or a "
                                  f"longer {path}")
            if n > MAX_EPISODE_STEPS:
                raise ConfigError(f"{path} = {span:g} s is {n:.3g} scans of scan_s = {self.scan_s:g} s; at most "
                                  f"{MAX_EPISODE_STEPS:,} per record (each is held in memory); use a longer "
                                  f"scan_s or a shorter {path}")
        if not self.models or "none" in self.models:
            raise ConfigError(f"models must name at least one friction model (not 'none'), got {list(self.models)!r}")
        if sum(getattr(self.bands, b).n for b in BAND_NAMES) == 0:
            raise ConfigError("bands: every band has n = 0; set bands.<band>.n > 0")

    def quick_version(self) -> BenchConfig:
        """The ``--quick`` configuration: ``quick.n_per_band`` valves per band, ``quick.duration_s`` records."""
        q = self.quick
        bands = Bands(**{b: replace(getattr(self.bands, b), n=q.n_per_band) for b in BAND_NAMES})
        return replace(self, bands=bands,
                       regulation=replace(self.regulation, duration_s=q.duration_s),
                       servo=replace(self.servo, duration_s=q.duration_s, interval_s=min(self.servo.interval_s,
                                                                                          q.duration_s / 2)),
                       scores=replace(self.scores, n_boot=q.n_boot))


def load_bench_config(source: str | os.PathLike | Mapping | None = None) -> BenchConfig:
    """Load a :class:`BenchConfig` from a YAML file or a mapping (keys left out keep the defaults).

    Parameters
    ----------
    source : str, path, mapping or None
        YAML file, its content, or None for the defaults.

    Returns
    -------
    BenchConfig

    Raises
    ------
    ConfigError
        On an unknown key (with a suggestion), a string where a number belongs, a wrong type or a
        value out of range; the message names the key path (e.g. ``bands.sticky.S``) and the file.
    """
    if source is not None and not isinstance(source, (str, os.PathLike, Mapping)):
        raise ConfigError(f"a benchmark config is a YAML file or a mapping, got {type(source).__name__}")
    cfg = load_config(source, cls=BenchConfig, base=BenchConfig())  # pyright: ignore[reportArgumentType]
    if not isinstance(cfg, BenchConfig):  # pragma: no cover - load_config returns an instance of cls
        raise ConfigError(f"could not build a benchmark config from {source!r}")
    return cfg


def bench_config_to_dict(cfg: BenchConfig) -> dict:
    """Nested plain dict of ``cfg`` (the inverse of :func:`load_bench_config`)."""
    return config_to_dict(cfg)
