r"""The oscillation detector of valve_gym: Thornhill's regularity of the autocorrelation's zero crossings.

One implementation, used by every part that asks "does this loop oscillate?":

============================  ===========================  ==============================================
caller                        rule (:data:`RULES`)          what decides
============================  ===========================  ==============================================
benchmark LC share, ES        ``"benchmark"``               regular, weakly damped (decay ratio > 0.5),
fitness, ``loop_metrics``,                                  both first ACF lobes significant; 5 or more
figures, ``agents.evaluate``                                periods in the record
fleet screen                  ``"screen"``                  regular, ACF at one period >= 0.3, period >= 4
                                                            samples (decides which loops get a diagnosis)
stiction evidence             ``"stiction"``                regular (periods' std floored at one sample),
                                                            3 or more cycles, period >= 4 samples
============================  ===========================  ==============================================

Every rule reads the same numbers from the same steps: the signal is detrended (least-squares
line, :func:`valve_gym.signals.detrend`), its biased autocorrelation ``r[k]`` computed
(:func:`valve_gym.signals.acf`) up to ``max_lag_frac`` of the record, and its zero crossings
``z_0 < z_1 < ...`` interpolated (:func:`valve_gym.signals.acf_zero_crossings`).  From them:

* period estimates ``T_{p,i} = 2 (z_{i+1} - z_i)`` (``intervals="half"``, Thornhill, Huang &
  Zhang 2003) or ``z_{i+2} - z_i`` (``intervals="full"``: whole periods, insensitive to unequal
  half periods), the period ``T = mean(T_p) dt``;
* the regularity

  .. math:: r = \frac{\overline{T_p}}{3\,\max(\sigma_{T_p}, s_0)}

  (``s_0`` the rule's floor in samples; ``r`` is capped at :data:`REGULARITY_CAP` so that it is
  always a finite number);
* Miao & Seborg's decay ratio of the first ACF lobes (measured from lag 1, so that white noise,
  which adds to ``r[0]`` only, does not change it);
* the significance of the first negative and positive lobes (each beyond twice its standard error
  by Bartlett's formula ``var r_k = (1 + 2 sum_{j<k} r_j^2) / N``);
* the ACF at one period and the amplitude: ``"window"`` (median over windows one period long of
  half the range of the signal, smoothed over a tenth of a period when noisy) or ``"autocov"``
  (the sinusoid with the same autocovariance at one period, ``sqrt(2 c(T))``; white noise does not
  enter ``c(T)``).

Each rule is a frozen :class:`OscillationRule`; its thresholds are the published ones (regularity
> 1: Thornhill et al.; decay ratio > 0.5: Miao & Seborg) or the caller's documented choice.

References
----------
.. [1] N.F. Thornhill, B. Huang, H. Zhang, "Detection of multiple oscillations in control loops",
   Journal of Process Control 13(1), 91-100, 2003.
.. [2] R. Miao, D.E. Seborg, "Automatic detection of excessively oscillatory feedback control
   loops", Proc. IEEE Int. Conf. on Control Applications, 359-364, 1999.
.. [3] G.E.P. Box, G.M. Jenkins, G.C. Reinsel, "Time Series Analysis", 4th ed., Wiley, 2008,
   sec. 2.1.6 (Bartlett's standard error of the sample autocorrelation).

Examples
--------
>>> import numpy as np
>>> t = np.arange(3600.0)
>>> e = 0.005 * np.sin(2 * np.pi * t / 120.0) + 0.002 * np.random.default_rng(1).standard_normal(t.size)
>>> osc = detect_oscillation(e, dt=1.0)
>>> osc.present, round(osc.period_s), round(1000 * osc.amplitude, 1)
(True, 120, 5.4)
>>> detect_oscillation(e, dt=1.0, rule="screen").present
True
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .signals import acf, acf_zero_crossings, detrend, moving_average, noise_sigma

__all__ = ["Oscillation", "OscillationRule", "RULES", "BENCHMARK", "SCREEN", "STICTION", "REGULARITY_CAP",
           "detect_oscillation"]

#: Largest regularity reported (a perfectly periodic signal has an infinite one).
REGULARITY_CAP = 99.0
# Amplitude smoothing: only when the noise std exceeds this fraction of the robust range.
_NOISE_FRAC = 0.002


@dataclass(frozen=True)
class OscillationRule:
    """One caller's rule for :func:`detect_oscillation` (see the module table).

    Attributes
    ----------
    name : str
    max_lag_frac : float, the ACF is searched up to lag ``max_lag_frac * (N - 1)`` (0 < . <= 1)
    max_crossings : int, at most this many ACF zero crossings are used
    min_crossings : int, fewer crossings than this: no period is read
    intervals : ``"half"`` or ``"full"``, period estimates from successive crossings (doubled) or
        from crossings two apart
    sd_floor : float, samples, floor of the periods' std in the regularity
    regularity_min : float, the oscillation is regular when ``r`` exceeds it
    decay_min : float or None, the decay ratio must exceed it (None: not tested)
    significance : bool, both first ACF lobes must be significant
    acf_min : float or None, the ACF at one period must be at least this (None: not tested)
    min_period : float, samples, shortest period
    min_cycles : float, fewest periods in the record
    amplitude : ``"window"`` or ``"autocov"`` (see the module docstring)
    min_len : int, shortest record (samples); shorter is "too short"
    """

    name: str
    max_lag_frac: float = 0.5
    max_crossings: int = 11
    min_crossings: int = 6
    intervals: str = "half"
    sd_floor: float = 0.0
    regularity_min: float = 1.0
    decay_min: float | None = 0.5
    significance: bool = True
    acf_min: float | None = None
    min_period: float = 0.0
    min_cycles: float = 0.0
    amplitude: str = "window"
    min_len: int = 16

    def __post_init__(self):
        if not 0.0 < self.max_lag_frac <= 1.0:
            raise ValueError(f"max_lag_frac must be in (0, 1], got {self.max_lag_frac!r}")
        if not 3 <= self.min_crossings <= self.max_crossings:
            raise ValueError(f"need 3 <= min_crossings <= max_crossings, got {self.min_crossings}, "
                             f"{self.max_crossings}")
        if self.intervals not in ("half", "full") or self.amplitude not in ("window", "autocov"):
            raise ValueError(f"intervals must be 'half' or 'full' and amplitude 'window' or 'autocov', got "
                             f"{self.intervals!r}, {self.amplitude!r}")


#: The benchmark's limit-cycle rule (LC share, ES fitness, ``loop_metrics``, figures): silent on
#: noise, on well-damped disturbance responses and on set-point steps; 5 or more periods needed.
BENCHMARK = OscillationRule("benchmark")
#: The fleet screen's rule (which loops go on to a full diagnosis): a regular oscillation that
#: carries a real share of the error's variance (ACF >= 0.3 at one period).
SCREEN = OscillationRule("screen", max_lag_frac=2.0 / 3.0, max_crossings=12, min_crossings=5, intervals="full",
                         decay_min=None, significance=False, acf_min=0.3, min_period=4.0, amplitude="autocov",
                         min_len=20)
#: The stiction evidence's rule (the shape methods need a period in samples and enough cycles).
STICTION = OscillationRule("stiction", max_crossings=12, min_crossings=3, sd_floor=1.0, decay_min=None,
                           significance=False, min_period=4.0, min_cycles=3.0, amplitude="autocov", min_len=4)
#: The rules by name.
RULES = {r.name: r for r in (BENCHMARK, SCREEN, STICTION)}


@dataclass(frozen=True)
class Oscillation:
    """What :func:`detect_oscillation` found in one signal.

    Attributes
    ----------
    present : bool, an oscillation by the rule's test
    period_s : float, s, period read from the ACF (``nan`` when too few zero crossings to read one;
        read also when ``present`` is False)
    regularity : float, Thornhill's ``r`` (``nan`` when no period was read; at most :data:`REGULARITY_CAP`)
    amplitude : float, signal units, amplitude of the oscillation (0 when not present)
    decay_ratio : float, Miao & Seborg's ACF decay ratio (0 when it cannot be measured)
    significant : bool, both first ACF lobes beyond twice their standard error
    acf_at_period : float, ACF at one period (-1..1; ``nan`` when no period was read)
    n_crossings : int, ACF zero crossings used
    n_cycles : float, record length over the period (0 when no period was read)
    dt : float, s, the sample time given
    rule : str, the rule's name
    reason : str, one line: why present or not
    """

    present: bool
    period_s: float
    regularity: float
    amplitude: float
    decay_ratio: float
    significant: bool
    acf_at_period: float
    n_crossings: int
    n_cycles: float
    dt: float
    rule: str
    reason: str

    @property
    def period_samples(self) -> float:
        """The period in samples (``nan`` when none was read)."""
        return self.period_s / self.dt


def _decay_ratio(r: np.ndarray, z: np.ndarray) -> float:
    """Miao & Seborg's decay ratio ``a / b`` of the ACF lobes between the crossings ``z[0..3]``.

    ``m1``, ``p1``, ``m2`` are the first minimum, the following maximum and the next minimum; ``a``
    is the height of ``p1`` above the line ``m1 - m2`` and ``b`` the depth of ``m1`` below the line
    from lag 1 to ``p1``.
    """
    if z.size < 4:
        return 0.0
    zi = np.ceil(z[:4]).astype(int)
    m1 = zi[0] + int(np.argmin(r[zi[0]:zi[1] + 1]))
    p1 = zi[1] + int(np.argmax(r[zi[1]:zi[2] + 1]))
    m2 = zi[2] + int(np.argmin(r[zi[2]:zi[3] + 1]))
    if not (1 < m1 < p1 < m2):
        return 0.0
    a = r[p1] - (r[m1] + (r[m2] - r[m1]) * (p1 - m1) / (m2 - m1))
    b = (r[1] + (r[p1] - r[1]) * (m1 - 1) / (p1 - 1)) - r[m1]
    return float(a / b) if b > 0.0 and a > 0.0 else 0.0


def _lobes_significant(r: np.ndarray, z: np.ndarray, n: int) -> bool:
    """Both first ACF lobes (negative, positive) exceed twice their standard error (Bartlett)."""
    if z.size < 3:
        return False
    zi = np.ceil(z[:3]).astype(int)
    k_min = zi[0] + int(np.argmin(r[zi[0]:zi[1] + 1]))
    k_max = zi[1] + int(np.argmax(r[zi[1]:zi[2] + 1]))
    cum = np.concatenate([[0.0], np.cumsum(r[1:] ** 2)])
    se = np.sqrt((1.0 + 2.0 * cum[np.array([k_min, k_max]) - 1]) / n)
    return bool(-r[k_min] > 2.0 * se[0] and r[k_max] > 2.0 * se[1])


def _window_amplitude(y: np.ndarray, period_samples: float) -> float:
    """Median over windows one period long of half the range of ``y`` (smoothed over period/10 when noisy)."""
    p = max(2, int(round(period_samples)))
    p1, p99 = np.percentile(y, [1.0, 99.0])
    noisy = noise_sigma(y) > _NOISE_FRAC * float(p99 - p1)
    ys = moving_average(y, max(1, int(period_samples / 10.0))) if noisy else y
    n_win = ys.size // p
    if n_win == 0:
        return 0.5 * float(np.ptp(ys))
    w = ys[:n_win * p].reshape(n_win, p)
    return float(np.median(0.5 * (w.max(axis=1) - w.min(axis=1))))


def _as_rule(rule) -> OscillationRule:
    if isinstance(rule, OscillationRule):
        return rule
    if rule in RULES:
        return RULES[rule]
    raise ValueError(f"unknown oscillation rule {rule!r}; known: {', '.join(RULES)} (or an OscillationRule)")


def _verdict(rule: OscillationRule, reg: float, dr: float, sig: bool, a_p: float, tm: float,
             cycles: float) -> tuple[bool, str]:
    """``(present, reason)`` of the rule's tests, in order, on the numbers read."""
    tests = [(reg > rule.regularity_min, f"irregular ACF zero crossings (r = {reg:.2f} <= {rule.regularity_min:g})"),
             (tm >= rule.min_period, f"zero crossings every {tm:.3g} samples (< {rule.min_period:g}): noise, "
                                     f"not an oscillation"),
             (cycles >= rule.min_cycles, f"only {cycles:.3g} cycles in the record (< {rule.min_cycles:g})")]
    if rule.decay_min is not None:
        tests.append((dr > rule.decay_min, f"damped: ACF decay ratio {dr:.2f} <= {rule.decay_min:g}"))
    if rule.significance:
        tests.append((sig, "the first ACF lobes are within twice their standard error (sampling noise)"))
    if rule.acf_min is not None:
        tests.append((a_p >= rule.acf_min, f"weak: ACF at one period {a_p:.2f} < {rule.acf_min:g}"))
    for ok, why in tests:
        if not ok:
            return False, why
    return True, f"regular oscillation: r = {reg:.2f}, decay ratio {dr:.2f}, ACF at one period {a_p:.2f}"


def detect_oscillation(x, dt: float = 1.0, rule: str | OscillationRule = "benchmark", **overrides) -> Oscillation:
    """The oscillation of ``x`` by one caller's rule (see the module docstring).

    Parameters
    ----------
    x : (N,) array_like, any units (the control error ``SP - PV``, a PV, an OP); finite
    dt : float, s, sample time (> 0)
    rule : str or OscillationRule, ``"benchmark"``, ``"screen"``, ``"stiction"`` or a rule
    **overrides
        Fields of the rule to change for this call (e.g. ``min_crossings=4``).

    Returns
    -------
    Oscillation

    Raises
    ------
    ValueError
        ``x`` not a finite 1-D array, ``dt <= 0`` or an unknown rule or field.
    """
    ru = _as_rule(rule)
    if overrides:
        ru = replace(ru, **overrides)
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or not np.isfinite(x).all():
        raise ValueError(f"x must be a finite 1-D array, got shape {x.shape}"
                         + ("" if x.ndim != 1 else " with NaN or inf values"))
    if not (isinstance(dt, (int, float, np.integer, np.floating)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    dt = float(dt)
    nan = float("nan")

    def none(why: str, n_z: int = 0) -> Oscillation:
        return Oscillation(False, nan, nan, 0.0, 0.0, False, nan, n_z, 0.0, dt, ru.name, why)

    n = x.size
    if n < ru.min_len:
        return none(f"too short ({n} samples < {ru.min_len})")
    y = detrend(x)
    scale = float(np.max(np.abs(x)))
    if float(np.ptp(y)) <= 1e-12 * scale or not np.any(y):
        return none("constant (after removing a straight line)")
    r = acf(y, max(4, int(ru.max_lag_frac * (n - 1))))
    z = acf_zero_crossings(r, ru.max_crossings)
    if z.size < ru.min_crossings:
        return none(f"the ACF crosses zero {z.size} times (< {ru.min_crossings}) within "
                    f"{ru.max_lag_frac:.2g} of the record: no regular oscillation", int(z.size))
    tp = 2.0 * np.diff(z) if ru.intervals == "half" else z[2:] - z[:-2]
    tm = float(np.mean(tp))
    sd = max(float(np.std(tp)), ru.sd_floor)
    reg = REGULARITY_CAP if sd == 0.0 else min(tm / (3.0 * sd), REGULARITY_CAP)
    dr = _decay_ratio(r, z)
    sig = _lobes_significant(r, z, n)
    lag = int(round(tm))
    c = acf(y, lag, normalise=False) if lag < n else np.zeros(1)
    a_p = float(c[lag] / c[0]) if lag < n and c[0] > 0 else nan
    cycles = n / tm if tm > 0 else 0.0
    present, why = _verdict(ru, reg, dr, sig, a_p, tm, cycles)
    amp = 0.0
    if present:
        amp = (_window_amplitude(y, tm) if ru.amplitude == "window"
               else math.sqrt(2.0 * max(float(c[lag]), 0.0)))
    return Oscillation(present, tm * dt, float(reg), amp, dr, sig, a_p, int(z.size), float(cycles), dt, ru.name,
                       why)
