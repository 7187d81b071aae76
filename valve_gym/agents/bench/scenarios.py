"""Benchmark scenarios: the valves, set points, loads and noise of every loop, drawn once.

A :class:`Scenarios` holds ``n`` loops of one part (``regulation`` or
``servo``): each loop's valve (friction model, stick band ``S``, slip jump
``J``, band) and its exogenous signals over the record (set point, load
inflow, measurement noise), as arrays. Every controller runs on the same
:class:`Scenarios`, so loop ``i`` sees the same valve, load and noise
realisation under every controller (paired comparisons).

The draw is reproducible: loop ``i`` of a part draws its valve, load and noise
from the streams ``numpy.random.default_rng([seed, part, i, k])``, ``k = 0, 1, 2``,
so a shorter record is a prefix of a longer one and a smaller run
(``--quick``, or a trainer asking for ``n`` loops) gets loops with the same statistics.

The regulation task is also what a learned compensator is trained and
evaluated on: :func:`regulation_scenarios` ``(config, n, seed)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...signals import ou_sequence
from .config import BAND_NAMES, BenchConfig, OULoad

__all__ = ["Scenarios", "regulation_scenarios", "servo_scenarios", "benchmark_scenarios", "PARTS",
           "band_labels", "BenchScenarios"]

#: The two parts, in report order.
PARTS = ("regulation", "servo")
_PART_CODE = {"regulation": 1, "servo": 2}


@dataclass(frozen=True, eq=False)
class Scenarios:
    """``n`` loops of one benchmark part, ``T`` scans each.

    Attributes
    ----------
    part : str
        ``"regulation"`` or ``"servo"``.
    scan_s : float, s
        Controller scan time; sample ``k`` is at ``t = k * scan_s``.
    seed : int
        Seed the loops were drawn with.
    band : (n,) ndarray of str
        Stiction band of each valve (``healthy``, ``sticky``, ``severe``).
    model : (n,) ndarray of str
        Friction model of each valve (a name for :func:`valve_gym.friction.valve_model`).
    S : (n,) ndarray, fraction of stroke
        Stick band (stiction plus dead band).
    J : (n,) ndarray, fraction of stroke
        Slip jump, ``0 <= J <= S``.
    sp : (T, n) ndarray, m
        Set point at each scan.
    load : (T, n) ndarray, m^3/s
        Extra inflow at each scan (held over the scan).
    noise : (T, n) ndarray, m
        Measurement noise added to the level.
    """

    part: str
    scan_s: float
    seed: int
    band: np.ndarray
    model: np.ndarray
    S: np.ndarray
    J: np.ndarray
    sp: np.ndarray
    load: np.ndarray
    noise: np.ndarray

    @property
    def n(self) -> int:
        """Number of loops."""
        return int(self.S.size)

    @property
    def n_steps(self) -> int:
        """Scans per loop ``T``."""
        return int(self.sp.shape[0])

    @property
    def duration_s(self) -> float:
        """Record length ``T * scan_s`` [s]."""
        return self.n_steps * self.scan_s

    def subset(self, idx) -> Scenarios:
        """The loops ``idx`` (an index array or boolean mask) as a new :class:`Scenarios`."""
        idx = np.asarray(idx)
        return Scenarios(self.part, self.scan_s, self.seed, self.band[idx], self.model[idx], self.S[idx],
                         self.J[idx], self.sp[:, idx], self.load[:, idx], self.noise[:, idx])


def band_labels(config: BenchConfig, n: int | None = None) -> np.ndarray:
    """Band of each of ``n`` loops: the configured counts, or ``n`` loops in the same proportions.

    Parameters
    ----------
    config : BenchConfig
    n : int, optional
        Number of loops (default: the sum of ``config.bands.<band>.n``).

    Returns
    -------
    (n,) ndarray of str
        Band names, grouped in the order of :data:`~valve_gym.agents.bench.config.BAND_NAMES`.
    """
    counts = np.array([getattr(config.bands, b).n for b in BAND_NAMES], float)
    if n is None:
        k = counts.astype(int)
    else:
        if n < 1:
            raise ValueError(f"n must be >= 1 loops, got {n}")
        share = counts / counts.sum() * n
        k = np.floor(share).astype(int)
        k[np.argsort(k - share)[: n - k.sum()]] += 1
    return np.repeat(np.array(BAND_NAMES), k)


def _ou(rng: np.random.Generator, load: OULoad, T: int, scan_s: float) -> np.ndarray:
    """Ornstein-Uhlenbeck sequence of ``T`` samples starting at 0 (see :class:`OULoad`)."""
    w = rng.standard_normal(T) * load.sigma          # d[k+1] = a d[k] + sigma sqrt(1 - a^2) w[k]
    return ou_sequence(np.concatenate([[0.0], w[:-1]]), math.exp(-scan_s / load.tau))


def _valve(rng: np.random.Generator, config: BenchConfig, band: str) -> tuple:
    """``(S, J)`` of one valve of ``band``: S uniform or log-uniform in the band, J uniform on [0, S]."""
    b = getattr(config.bands, band)
    lo, hi = b.S
    u = rng.random(2)
    S = lo * (hi / lo) ** u[0] if b.log_uniform else lo + (hi - lo) * u[0]
    return float(S), float(S * u[1])


def _draw(config: BenchConfig, part: str, n: int | None, seed: int | None, duration_s: float,
          load: OULoad, noise_std: float, levels: tuple):
    seed = config.seed if seed is None else int(seed)
    bands = band_labels(config, n)
    T = int(round(duration_s / config.scan_s))
    m = len(config.models)
    cols = []
    for i, band in enumerate(bands):
        key = [seed, _PART_CODE[part], i]
        S, J = _valve(np.random.default_rng(key + [0]), config, band)
        d = _ou(np.random.default_rng(key + [1]), load, T, config.scan_s)
        v = np.random.default_rng(key + [2]).standard_normal(T) * noise_std
        j = int(np.sum(bands[:i] == band))  # index inside the band: models and levels cycle within bands
        cols.append((band, config.models[j % m], S, J, float(levels[(j // m) % len(levels)]), d, v))
    band_a, model_a, S_a, J_a, lv, d_a, v_a = zip(*cols)
    return (seed, np.array(band_a), np.array(model_a), np.array(S_a), np.array(J_a), np.array(lv),
            np.stack(d_a, axis=1), np.stack(v_a, axis=1))


def regulation_scenarios(config: BenchConfig, n: int | None = None, seed: int | None = None) -> Scenarios:
    """The regulation part: constant set point, OU load inflow, white measurement noise.

    Parameters
    ----------
    config : BenchConfig
        ``bands`` (valve population), ``models``, ``regulation`` (record, levels, load, noise).
    n : int, optional
        Number of loops (default: the configured band counts; otherwise the same band proportions).
    seed : int, optional
        Seed of the draw (default ``config.seed``).

    Returns
    -------
    Scenarios
        ``sp`` constant per loop at one of ``config.regulation.levels`` (the loop starts at steady state there).

    Examples
    --------
    >>> from valve_gym.agents.bench.config import BenchConfig
    >>> sc = regulation_scenarios(BenchConfig(), n=6, seed=1)
    >>> sc.n, sc.n_steps, sorted(str(b) for b in set(sc.band))
    (6, 3600, ['healthy', 'severe', 'sticky'])
    >>> bool((sc.J <= sc.S).all()), bool((sc.sp == sc.sp[0]).all())
    (True, True)
    """
    rc = config.regulation
    seed, band, model, S, J, lv, d, v = _draw(config, "regulation", n, seed, rc.duration_s, rc.load,
                                              rc.noise_std, rc.levels)
    sp = np.repeat(lv[None, :], d.shape[0], axis=0)
    return Scenarios("regulation", config.scan_s, seed, band, model, S, J, sp, d, v)


def servo_scenarios(config: BenchConfig, n: int | None = None, seed: int | None = None) -> Scenarios:
    """The servo part: set-point steps ``+step, back, -step, back, ...`` every ``interval_s``.

    Parameters
    ----------
    config : BenchConfig
    n : int, optional
        Number of loops (default: the configured band counts).
    seed : int, optional
        Seed of the draw (default ``config.seed``).

    Returns
    -------
    Scenarios
    """
    sc = config.servo
    seed, band, model, S, J, lv, d, v = _draw(config, "servo", n, seed, sc.duration_s, sc.load,
                                              sc.noise_std, sc.levels)
    t = np.arange(d.shape[0]) * config.scan_s
    k = np.floor(t / sc.interval_s).astype(int)
    offset = np.array([0.0, 1.0, 0.0, -1.0])[k % 4] * sc.step
    sp = lv[None, :] + offset[:, None]
    return Scenarios("servo", config.scan_s, seed, band, model, S, J, sp, d, v)


@dataclass(frozen=True, eq=False)
class BenchScenarios:
    """Both parts of a benchmark run.

    Attributes
    ----------
    regulation, servo : Scenarios
    """

    regulation: Scenarios
    servo: Scenarios

    def part(self, name: str) -> Scenarios:
        """The :class:`Scenarios` of part ``name`` (one of :data:`PARTS`)."""
        if name not in PARTS:
            raise ValueError(f"unknown part {name!r}; the parts are {PARTS}")
        return getattr(self, name)


def benchmark_scenarios(config: BenchConfig) -> BenchScenarios:
    """Both parts with the configured loop counts."""
    return BenchScenarios(regulation_scenarios(config), servo_scenarios(config))
