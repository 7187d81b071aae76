"""Performance and wear metrics for scoring a control loop, and the loop's scores at once.

Pure numpy, no plotting. Every function takes uniformly sampled 1-D signals
(one sample per controller period ``dt`` in seconds) and returns plain Python
``float``/``int``/``bool`` values (or small named tuples of them), never NaN.

Conventions
-----------
* Control error ``e = sp - pv`` in process units (``[e]``).
* Integrals use the rectangle rule ``sum(f(e[k])) * dt`` over all samples.
* The limit cycle is the benchmark rule of the one oscillation detector,
  :func:`valve_gym.oscillation.detect_oscillation`; in :func:`loop_metrics`
  "no limit cycle" is amplitude ``0.0`` and period ``inf``, never NaN.
* Bad input (not 1-D, too short, NaN/inf, ``dt <= 0``, mismatched lengths)
  raises :class:`ValueError` naming the argument and the fix.

Example
-------
>>> import numpy as np
>>> from valve_gym.metrics import iae
>>> t = np.arange(0.0, 200.0, 0.1)
>>> round(iae(np.sin(2 * np.pi * t / 20.0), dt=0.1), 2)   # 4 A / omega per period, 10 periods
127.31
"""
from __future__ import annotations

import math
from typing import NamedTuple, Union

import numpy as np

from .oscillation import detect_oscillation

__all__ = [
    "iae", "ise", "error_std",
    "crest_factor", "waveform_shape", "CREST_FACTORS",
    "HagglundResult", "hagglund_oscillation",
    "travel", "reversals", "reversals_per_hour", "reversal_counts",
    "loop_metrics", "LOOP_METRIC_KEYS",
]

ArrayLike = Union[np.ndarray, list, tuple]  # noqa: UP007 (a runtime alias)

#: Crest factors of the ideal zero-mean periodic waveforms.
CREST_FACTORS = {"square": 1.0, "sine": math.sqrt(2.0), "triangle": math.sqrt(3.0)}

# A signal whose peak-to-peak is below this fraction of its magnitude is "flat".
_FLAT_RTOL = 1e-12


# --------------------------------------------------------------------------- #
# Input validation
# --------------------------------------------------------------------------- #
def _as_signal(x, name: str, min_len: int = 2) -> np.ndarray:
    """``x`` as a finite 1-D float array of at least ``min_len`` samples."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"`{name}` must be a 1-D array of real numbers; it could not be "
            f"converted to floats ({exc})") from None
    if a.ndim != 1:
        raise ValueError(
            f"`{name}` must be a 1-D array (one sample per time step), got an array "
            f"of shape {a.shape}; pass one signal at a time (e.g. x[:, i] or np.ravel(x))")
    if a.size < min_len:
        raise ValueError(
            f"`{name}` needs at least {min_len} samples, got {a.size}; "
            f"pass a longer record")
    finite = np.isfinite(a)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise ValueError(
            f"`{name}` contains {bad.size} non-finite value(s) (NaN or inf), the first "
            f"at index {bad[0]}; remove or interpolate them before computing metrics")
    return a


def _as_scalar(value, name: str) -> float:
    if isinstance(value, (bool, np.bool_)) or np.ndim(value) != 0:
        raise ValueError(f"`{name}` must be a real scalar, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be a real scalar, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"`{name}` must be finite, got {value!r}")
    return v


def _positive(value, name: str, unit: str = "") -> float:
    v = _as_scalar(value, name)
    if v <= 0.0:
        raise ValueError(
            f"`{name}` must be > 0{(' ' + unit) if unit else ''}, got {value!r}")
    return v


def _check_dt(dt) -> float:
    try:
        return _positive(dt, "dt", "(the sample time in seconds)")
    except ValueError as exc:
        raise ValueError(
            f"{exc}; pass the sample time in seconds, e.g. dt=0.1") from None


def _nonnegative(value, name: str) -> float:
    v = _as_scalar(value, name)
    if v < 0.0:
        raise ValueError(f"`{name}` must be >= 0, got {value!r}")
    return v


def _same_length(ref_name: str, ref: np.ndarray, name: str, a: np.ndarray) -> None:
    if a.size != ref.size:
        raise ValueError(
            f"`{name}` has {a.size} samples but `{ref_name}` has {ref.size}; all "
            f"signals must be sampled on the same time grid (trim or resample them)")


def _is_flat(x: np.ndarray, scale: float | None = None) -> bool:
    """``x`` varies by no more than rounding error of ``scale`` (default max|x|)."""
    if scale is None:
        scale = float(np.max(np.abs(x)))
    return float(np.ptp(x)) <= _FLAT_RTOL * scale


# --------------------------------------------------------------------------- #
# Integral criteria
# --------------------------------------------------------------------------- #
def iae(e: ArrayLike, dt: float) -> float:
    r"""Integral of the absolute error, rectangle rule.

    .. math:: \mathrm{IAE} = \sum_{k=0}^{N-1} |e_k|\,\Delta t
              \approx \int_0^{N\Delta t} |e(t)|\,dt

    Parameters
    ----------
    e : (N,) array_like, [e]
        Control error ``sp - pv`` (N >= 2), uniformly sampled.
    dt : float, s
        Sample time (> 0).

    Returns
    -------
    float, [e]*s
        The IAE.

    Raises
    ------
    ValueError
        If ``e`` is not 1-D, has fewer than 2 samples or non-finite values, or
        ``dt <= 0``.

    References
    ----------
    .. [1] D.E. Seborg, T.F. Edgar, D.A. Mellichamp, F.J. Doyle III, "Process
       Dynamics and Control", 3rd ed., Wiley, 2011, sec. 12.2 (integral error
       criteria).

    Examples
    --------
    A sine of amplitude A and angular frequency w gives 4*A/w per period:

    >>> import numpy as np
    >>> w = 2 * np.pi / 10.0
    >>> t = np.arange(0.0, 10.0, 0.001)
    >>> round(iae(2.0 * np.sin(w * t), 0.001), 3), round(4 * 2.0 / w, 3)
    (12.732, 12.732)
    """
    e = _as_signal(e, "e")
    dt = _check_dt(dt)
    return float(np.sum(np.abs(e)) * dt)


def ise(e: ArrayLike, dt: float) -> float:
    r"""Integral of the squared error, rectangle rule.

    .. math:: \mathrm{ISE} = \sum_{k=0}^{N-1} e_k^2\,\Delta t
              \approx \int_0^{N\Delta t} e(t)^2\,dt

    Parameters
    ----------
    e : (N,) array_like, [e]
        Control error ``sp - pv`` (N >= 2), uniformly sampled.
    dt : float, s
        Sample time (> 0).

    Returns
    -------
    float, [e]^2*s
        The ISE.

    Raises
    ------
    ValueError
        If ``e`` is not 1-D, has fewer than 2 samples or non-finite values, or
        ``dt <= 0``.

    References
    ----------
    .. [1] D.E. Seborg, T.F. Edgar, D.A. Mellichamp, F.J. Doyle III, "Process
       Dynamics and Control", 3rd ed., Wiley, 2011, sec. 12.2.

    Examples
    --------
    A sine of amplitude A over a whole number of periods gives A**2/2 per second:

    >>> import numpy as np
    >>> t = np.arange(0.0, 20.0, 0.01)
    >>> round(ise(3.0 * np.sin(2 * np.pi * t / 5.0), 0.01), 6)
    90.0
    """
    e = _as_signal(e, "e")
    dt = _check_dt(dt)
    return float(np.sum(e * e) * dt)


def error_std(e: ArrayLike) -> float:
    r"""Standard deviation of the error about its mean (population, ``ddof=0``).

    .. math:: \sigma_e = \sqrt{\tfrac{1}{N}\sum_k (e_k - \bar e)^2}

    Parameters
    ----------
    e : (N,) array_like, [e]
        Control error (N >= 2).

    Returns
    -------
    float, [e]
        ``numpy.std(e)``.

    Raises
    ------
    ValueError
        If ``e`` is not 1-D, has fewer than 2 samples or non-finite values.

    References
    ----------
    .. [1] M. Jelali, "Control Performance Management in Industrial
       Automation", Springer, 2013, ch. 2 (variance-based indices).

    Examples
    --------
    >>> error_std([1.0, -1.0, 1.0, -1.0])
    1.0
    """
    e = _as_signal(e, "e")
    return float(np.std(e))


# --------------------------------------------------------------------------- #
# Zero crossings
# --------------------------------------------------------------------------- #
def _crossings(x: np.ndarray, h: float):
    """Zero crossings of ``x`` with a Schmitt-trigger band ``[-h, +h]``.

    A crossing is confirmed when ``x`` goes from below ``-h`` to above ``+h`` (or
    back). Its position is the linearly interpolated zero crossing just before
    the confirmation, in fractional samples. Returns ``(pos, j)``: ``pos`` the
    positions and ``j`` the last sample before each crossing (``pos`` lies in
    ``[j, j + 1)``). Successive crossings alternate in direction.
    """
    n = x.size
    idx = np.arange(n)
    s = np.zeros(n, dtype=np.int8)
    s[x > h] = 1
    s[x < -h] = -1
    held = np.maximum.accumulate(np.where(s != 0, idx, 0))
    state = s[held]
    k = np.flatnonzero((state[1:] != state[:-1]) & (state[:-1] != 0)) + 1
    if k.size == 0:
        return np.empty(0), np.empty(0, dtype=int)
    last_nonpos = np.maximum.accumulate(np.where(x <= 0.0, idx, -1))
    last_nonneg = np.maximum.accumulate(np.where(x >= 0.0, idx, -1))
    rising = state[k] > 0
    j = np.where(rising, last_nonpos[k - 1], last_nonneg[k - 1])
    x0, x1 = x[j], x[j + 1]
    pos = j + x0 / (x0 - x1)
    return pos, j


# --------------------------------------------------------------------------- #
# Waveform shape
# --------------------------------------------------------------------------- #
def crest_factor(x: ArrayLike) -> float:
    r"""Crest factor: peak over RMS of the mean-removed signal.

    .. math:: C = \frac{\max_k |x_k - \bar x|}
                       {\sqrt{\tfrac{1}{N}\sum_k (x_k - \bar x)^2}}

    Ideal periodic waves have ``C = 1`` (square), ``sqrt(2) = 1.414`` (sine)
    and ``sqrt(3) = 1.732`` (triangle); Gaussian noise about 3 to 4.

    Parameters
    ----------
    x : (N,) array_like
        Signal, N >= 2, ideally a whole number of cycles of an oscillation.

    Returns
    -------
    float, dimensionless
        ``C >= 1``, or ``0.0`` (a sentinel, not a crest factor) for a flat
        signal whose RMS is zero.

    Raises
    ------
    ValueError
        If ``x`` is not 1-D, has fewer than 2 samples or non-finite values.

    References
    ----------
    .. [1] IEC 60050-103:2009, International Electrotechnical Vocabulary,
       item 103-07-12 "peak factor / crest factor".
    .. [2] M. Jelali, B. Huang (eds.), "Detection and Diagnosis of Stiction in
       Control Loops", Springer, 2010 (square/triangular limit cycles of
       sticky valves).

    Examples
    --------
    >>> import numpy as np
    >>> crest_factor([1.0, -1.0, 1.0, -1.0])
    1.0
    >>> t = np.arange(1000) / 1000
    >>> round(crest_factor(np.sin(2 * np.pi * 5 * t)), 3)
    1.414
    """
    x = _as_signal(x, "x")
    if _is_flat(x):
        return 0.0
    y = x - x.mean()
    rms = math.sqrt(float(np.mean(y * y)))
    if rms == 0.0:  # pragma: no cover - excluded by _is_flat
        return 0.0
    return float(np.max(np.abs(y)) / rms)


def waveform_shape(e: ArrayLike, *, tol: float | None = None) -> str:
    """Classify a waveform as square, sine or triangle by its crest factor.

    The class is the one whose ideal crest factor (:data:`CREST_FACTORS`:
    1, 1.414, 1.732) is nearest to :func:`crest_factor` of ``e``. A sticky valve
    in a flow loop tends to give a square-ish ``pv`` and a triangular ``op``.

    Parameters
    ----------
    e : (N,) array_like
        Signal, N >= 2, best a whole number of cycles of an oscillation (check
        with :func:`valve_gym.oscillation.detect_oscillation` first: noise is classified too, usually as
        'triangle').
    tol : float, optional
        If given, return ``'none'`` when the crest factor is farther than
        ``tol`` from the nearest ideal value (e.g. ``tol=0.15``).

    Returns
    -------
    {'square', 'sine', 'triangle', 'none'}
        ``'none'`` for a flat signal (or outside ``tol``).

    Raises
    ------
    ValueError
        If ``e`` is not 1-D, has fewer than 2 samples or non-finite values, or
        ``tol < 0``.

    References
    ----------
    .. [1] A. Singhal, T.I. Salsbury, "A simple method for detecting valve
       stiction in oscillating control loops", Journal of Process Control
       15(4), 371-382, 2005.
    .. [2] M. Jelali, B. Huang (eds.), "Detection and Diagnosis of Stiction in
       Control Loops", Springer, 2010.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(2000) / 1000
    >>> waveform_shape(np.sign(np.sin(2 * np.pi * 4 * t + 0.1)))
    'square'
    >>> waveform_shape(np.sin(2 * np.pi * 4 * t))
    'sine'
    >>> waveform_shape(np.zeros(10))
    'none'
    """
    c = crest_factor(e)
    if tol is not None:
        tol = _nonnegative(tol, "tol")
    if c == 0.0:
        return "none"
    name, ideal = min(CREST_FACTORS.items(), key=lambda kv: abs(c - kv[1]))
    if tol is not None and abs(c - ideal) > tol:
        return "none"
    return name


# --------------------------------------------------------------------------- #
# Hägglund's load-disturbance / oscillation detector
# --------------------------------------------------------------------------- #
class HagglundResult(NamedTuple):
    """Result of :func:`hagglund_oscillation`.

    Attributes
    ----------
    n_detections : int
        Load disturbances detected (half cycles with IAE > ``iae_lim``).
    alarm : bool
        More than ``n_lim`` detections fell inside some window of length
        ``t_sup``.
    iae_lim : float, [e]*s
        ``2 a / omega_u``.
    detection_times : (n_detections,) ndarray, s
        Time of the zero crossing that ends each detected half cycle, from the
        first sample (t = 0).
    n_alarms : int
        Alarm episodes: detections at which the windowed count rises above
        ``n_lim``.
    max_count : int
        Largest number of detections inside one window of length ``t_sup``.
    omega_u : float, rad/s
        Ultimate frequency used (given or estimated).
    t_sup : float, s
        Supervision time used.
    """

    n_detections: int
    alarm: bool
    iae_lim: float
    detection_times: np.ndarray
    n_alarms: int
    max_count: int
    omega_u: float
    t_sup: float


def hagglund_oscillation(e: ArrayLike, dt: float, a: float | None = None,
                         span: float = 1.0, omega_u: float | None = None,
                         t_sup: float | None = None,
                         n_lim: float = 10) -> HagglundResult:
    r"""Hägglund's (1995) oscillation detector of a control-loop performance monitor.

    Between successive zero crossings ``t_{i-1}, t_i`` of the control error

    .. math:: \mathrm{IAE}_i = \int_{t_{i-1}}^{t_i} |e(t)|\,dt

    and a *load disturbance* is detected when

    .. math:: \mathrm{IAE}_i > \mathrm{IAE}_{lim} = \frac{2a}{\omega_u}

    which is the IAE of one half period of a sine of amplitude ``a`` at the
    ultimate frequency ``omega_u``. An *oscillation alarm* is raised when more
    than ``n_lim`` detections occur within a supervision time ``T_sup``.

    Parameters
    ----------
    e : (N,) array_like, [e]
        Control error ``sp - pv``, uniformly sampled, N >= 2. Its zero crossings
        are used as they are (no detrending or band): with integral action the
        error is zero on average.
    dt : float, s
        Sample time (> 0).
    a : float, [e], optional
        Acceptable oscillation amplitude (> 0). Default ``0.01 * span`` (1 % of
        the span, as in the paper).
    span : float, [e], optional
        Measurement span (> 0), used only for the default ``a``.
    omega_u : float, rad/s, optional
        Ultimate frequency of the loop (> 0), e.g. from a relay auto-tuning
        experiment. If None it is estimated as ``2 pi / period`` of the limit
        cycle found in ``e`` by :func:`valve_gym.oscillation.detect_oscillation`
        (benchmark rule): a loop in a limit cycle
        oscillates close to its ultimate (phase-crossover) frequency, and then
        ``IAE_i > IAE_lim`` reduces to "oscillation amplitude > a" for a
        sine. If no limit cycle is found a ValueError asks for ``omega_u``.
    t_sup : float, s, optional
        Supervision time (> 0). Default ``50 T_u`` with ``T_u = 2 pi / omega_u``.
    n_lim : float, optional
        Detections tolerated within ``t_sup`` (>= 0, default 10).

    Returns
    -------
    HagglundResult
        ``n_detections``, ``alarm``, ``iae_lim``, ``detection_times`` and the
        diagnostics ``n_alarms``, ``max_count``, ``omega_u``, ``t_sup``.

    Raises
    ------
    ValueError
        On bad ``e``/``dt``, non-positive ``a``, ``span``, ``omega_u`` or
        ``t_sup``, negative ``n_lim``, or when ``omega_u`` is None and ``e``
        holds no limit cycle to estimate it from.

    Notes
    -----
    Crossings are the sign changes of ``e``, located by linear interpolation.
    ``IAE_i`` uses the rectangle rule over the samples strictly between two
    crossings, so only *complete* half cycles are scored (the stretches before
    the first and after the last crossing are not). The paper counts
    detections with an exponentially forgotten sum; here the count is exact
    over a sliding window: at each detection time ``t_d`` the detections in
    ``(t_d - t_sup, t_d]`` are counted and the alarm is raised if that count
    exceeds ``n_lim``. A sustained sine of amplitude ``A > a`` at ``omega_u``
    is detected at every half period.

    References
    ----------
    .. [1] T. Hägglund, "A control-loop performance monitor", Control
       Engineering Practice 3(11), 1543-1551, 1995.
    .. [2] N.F. Thornhill, T. Hägglund, "Detection and diagnosis of oscillation
       in control loops", Control Engineering Practice 5(10), 1343-1354, 1997.

    Examples
    --------
    A 2 % oscillation (a = 1 % of span) with a 10 s period over 200 s:

    >>> import numpy as np
    >>> t = np.arange(0.0, 200.0, 0.01)
    >>> res = hagglund_oscillation(0.02 * np.sin(2 * np.pi * t / 10 + 0.3), dt=0.01)
    >>> res.n_detections, res.alarm, round(res.iae_lim, 4)
    (39, True, 0.0318)
    """
    x = _as_signal(e, "e")
    dt = _check_dt(dt)
    span = _positive(span, "span")
    a = 0.01 * span if a is None else _positive(a, "a")
    if n_lim is None or isinstance(n_lim, (bool, np.bool_)):
        raise ValueError(f"`n_lim` must be a number >= 0, got {n_lim!r}")
    n_lim = _nonnegative(n_lim, "n_lim")
    if omega_u is None:
        lc = detect_oscillation(x, dt, "benchmark")
        if not lc.present:
            raise ValueError(
                "`omega_u` was not given and no limit cycle was found in `e` to "
                "estimate it from; pass omega_u in rad/s (e.g. the ultimate "
                "frequency from a relay test, 2*pi/T_u)")
        omega_u = 2.0 * math.pi / lc.period_s
    else:
        omega_u = _positive(omega_u, "omega_u", "rad/s")
    t_sup = 50.0 * 2.0 * math.pi / omega_u if t_sup is None else _positive(t_sup, "t_sup", "s")
    iae_lim = 2.0 * a / omega_u

    pos, j = _crossings(x, 0.0)
    if pos.size >= 2:
        S = np.concatenate([[0.0], np.cumsum(np.abs(x))])
        iae_half = dt * (S[j[1:] + 1] - S[j[:-1] + 1])
        hit = iae_half > iae_lim
        det_t = pos[1:][hit] * dt
    else:
        det_t = np.empty(0)
    if det_t.size:
        first_in = np.searchsorted(det_t, det_t - t_sup, side="right")
        count = np.arange(det_t.size) - first_in + 1
        alarm_on = count > n_lim
        n_alarms = int(np.count_nonzero(alarm_on & (count - 1 <= n_lim)))
        max_count = int(count.max())
    else:
        n_alarms, max_count = 0, 0
    return HagglundResult(
        n_detections=int(det_t.size), alarm=bool(max_count > n_lim),
        iae_lim=float(iae_lim), detection_times=det_t, n_alarms=n_alarms,
        max_count=max_count, omega_u=float(omega_u), t_sup=float(t_sup))


# --------------------------------------------------------------------------- #
# Valve / controller output wear
# --------------------------------------------------------------------------- #
def travel(x: ArrayLike) -> float:
    r"""Total travel (accumulated distance moved) of a signal.

    .. math:: \mathrm{travel} = \sum_{k=0}^{N-2} |x_{k+1} - x_k|

    Parameters
    ----------
    x : (N,) array_like, [x]
        Controller output or valve stem position, N >= 2.

    Returns
    -------
    float, [x]
        Travel, e.g. in % of stroke (divide by 200 % for full-stroke cycles).

    Raises
    ------
    ValueError
        If ``x`` is not 1-D, has fewer than 2 samples or non-finite values.

    References
    ----------
    .. [1] M. Jelali, "Control Performance Management in Industrial
       Automation", Springer, 2013 (valve travel and reversal indices).

    Examples
    --------
    >>> travel([0.0, 1.0, 0.0, 2.0, 2.0, -1.0])
    7.0
    """
    x = _as_signal(x, "x")
    return float(np.sum(np.abs(np.diff(x))))


def _reversals(x: np.ndarray, deadband: float) -> int:
    if deadband == 0.0:
        d = np.diff(x)
        d = d[d != 0.0]
        return int(np.count_nonzero((d[1:] > 0) != (d[:-1] > 0)))
    vals = x.tolist()
    lo = hi = vals[0]
    direction = 0
    ext = 0.0
    n = 0
    for v in vals[1:]:
        if direction == 0:
            if v - lo > deadband:
                direction, ext = 1, v
            elif hi - v > deadband:
                direction, ext = -1, v
            else:
                lo, hi = min(lo, v), max(hi, v)
        elif direction > 0:
            if v > ext:
                ext = v
            elif ext - v > deadband:
                n += 1
                direction, ext = -1, v
        else:
            if v < ext:
                ext = v
            elif v - ext > deadband:
                n += 1
                direction, ext = 1, v
    return n


def reversals(x: ArrayLike, deadband: float = 0.0) -> int:
    """Number of direction changes of a signal, with a dead band (hysteresis).

    A move counts only once the signal has gone *more than* ``deadband`` from
    its last extreme (peak or trough); a reversal is counted when a counted
    move is opposite to the previous one. With ``deadband = 0`` every sign
    change of the non-zero increments ``x[k+1] - x[k]`` counts (flat stretches
    are skipped).

    Parameters
    ----------
    x : (N,) array_like, [x]
        Controller output or valve stem position, N >= 2.
    deadband : float, [x], optional
        Moves of at most this size are ignored (>= 0, default 0). Set it just
        above the noise or the resolution of the signal.

    Returns
    -------
    int
        Number of reversals.

    Raises
    ------
    ValueError
        If ``x`` is bad (see :func:`travel`) or ``deadband < 0``.

    References
    ----------
    .. [1] M. Jelali, "Control Performance Management in Industrial
       Automation", Springer, 2013 (valve travel and reversal indices).

    Examples
    --------
    >>> x = [0.0, 1.0, 0.8, 2.0, 1.5, 1.7, 0.0]
    >>> reversals(x), reversals(x, deadband=0.3)
    (5, 1)
    """
    x = _as_signal(x, "x")
    deadband = _nonnegative(deadband, "deadband")
    return _reversals(x, deadband)


def reversals_per_hour(x: ArrayLike, dt: float, deadband: float = 0.0) -> float:
    """Reversal rate: :func:`reversals` per hour of record.

    ``reversals(x, deadband) / ((N - 1) * dt / 3600)``; the record lasts
    ``(N - 1) dt`` seconds from the first to the last sample.

    Parameters
    ----------
    x : (N,) array_like, [x]
        Controller output or valve stem position, N >= 2.
    dt : float, s
        Sample time (> 0).
    deadband : float, [x], optional
        See :func:`reversals`.

    Returns
    -------
    float, 1/h
        Reversals per hour.

    Raises
    ------
    ValueError
        On bad ``x``, ``dt <= 0`` or ``deadband < 0``.

    References
    ----------
    .. [1] M. Jelali, "Control Performance Management in Industrial
       Automation", Springer, 2013.

    Examples
    --------
    Three reversals in one hour (samples every 15 min):

    >>> reversals_per_hour([0.0, 1.0, 0.0, 1.0, 0.0], dt=900.0)
    3.0
    """
    x = _as_signal(x, "x")
    dt = _check_dt(dt)
    deadband = _nonnegative(deadband, "deadband")
    return float(_reversals(x, deadband) * 3600.0 / ((x.size - 1) * dt))


def reversal_counts(x: ArrayLike, deadband: float = 0.0) -> np.ndarray:
    """:func:`reversals` of each column of a ``(T, n)`` array at once.

    Parameters
    ----------
    x : (T, n) array_like, [x]
        ``n`` signals of ``T >= 2`` samples each (time along axis 0).
    deadband : float, [x], optional
        See :func:`reversals` (>= 0).

    Returns
    -------
    (n,) ndarray of int
        The same counts as ``reversals(x[:, i], deadband)``.

    Raises
    ------
    ValueError
        If ``x`` is not 2-D, has fewer than 2 rows or non-finite values, or ``deadband < 0``.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.0, 1.0, 0.8, 2.0, 1.5, 1.7, 0.0]]).T
    >>> reversal_counts(x).tolist(), reversal_counts(x, 0.3).tolist()
    ([5], [1])
    """
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[0] < 2:
        raise ValueError(f"`x` must be a (T, n) array with T >= 2 (time along axis 0), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("`x` contains NaN or inf; remove or interpolate them before counting reversals")
    db = _nonnegative(deadband, "deadband")
    lo, hi = a[0].copy(), a[0].copy()
    direction = np.zeros(a.shape[1])
    ext = a[0].copy()
    count = np.zeros(a.shape[1], dtype=np.int64)
    for v in a[1:]:
        idle = direction == 0
        start_up = idle & (v - lo > db)
        start_dn = idle & ~start_up & (hi - v > db)
        lo = np.where(idle, np.minimum(lo, v), lo)
        hi = np.where(idle, np.maximum(hi, v), hi)
        if db == 0.0:
            turn_up = (direction < 0) & (v > ext)
            turn_dn = (direction > 0) & (v < ext)
        else:
            turn_up = (direction < 0) & (v - ext > db)
            turn_dn = (direction > 0) & (ext - v > db)
        count += turn_up | turn_dn
        new_dir = np.where(start_up | turn_up, 1.0, np.where(start_dn | turn_dn, -1.0, direction))
        grow = ((direction > 0) & (v > ext)) | ((direction < 0) & (v < ext))
        ext = np.where(start_up | start_dn | turn_up | turn_dn | grow, v, ext)
        direction = new_dir
    return count


# --------------------------------------------------------------------------- #
# Everything at once
# --------------------------------------------------------------------------- #
#: Keys of :func:`loop_metrics` (the last two only when ``mv`` is given).
LOOP_METRIC_KEYS = (
    "iae", "ise", "error_std",
    "lc_present", "lc_amplitude", "lc_period", "lc_n_cycles", "lc_regularity",
    "crest_factor", "hagglund_detections", "hagglund_alarms",
    "op_travel", "op_reversals_per_hour",
    "valve_travel", "valve_reversals_per_hour",
)


def _dt_from(t_or_dt, n: int) -> float:
    if np.ndim(t_or_dt) == 0:
        try:
            return _positive(t_or_dt, "t_or_dt", "(a sample time in seconds)")
        except ValueError as exc:
            raise ValueError(
                f"{exc}; pass the sample time dt in s or the (N,) time vector") from None
    t = _as_signal(t_or_dt, "t_or_dt")
    if t.size != n:
        raise ValueError(
            f"`t_or_dt` has {t.size} time stamps but `pv` has {n} samples; pass "
            f"the time vector of the signals or a scalar dt")
    d = np.diff(t)
    if np.any(d <= 0.0):
        raise ValueError(
            "`t_or_dt` must be strictly increasing; sort the record or pass a scalar dt")
    dt = float(t[-1] - t[0]) / (t.size - 1)
    if np.max(np.abs(d - dt)) > 1e-6 * dt:
        raise ValueError(
            "`t_or_dt` is not uniformly sampled; resample the signals onto a "
            "uniform grid (e.g. numpy.interp) and pass that grid or its dt")
    return dt


def loop_metrics(t_or_dt, sp, pv, op, mv=None, span: float = 1.0, *,
                 omega_u: float | None = None, deadband: float = 0.0) -> dict:
    """All loop scores at once, as a flat dict of floats.

    Parameters
    ----------
    t_or_dt : float or (N,) array_like, s
        Sample time ``dt`` (> 0), or the uniformly spaced time vector.
    sp : float or (N,) array_like, [pv]
        Set point (a scalar is a constant set point).
    pv : (N,) array_like, [pv]
        Process variable, N >= 2.
    op : (N,) array_like, [op]
        Controller output.
    mv : (N,) array_like, [op], optional
        Measured valve stem position.
    span : float, [pv], optional
        Measurement span (> 0); Hägglund's ``a`` is 1 % of it.
    omega_u : float, rad/s, optional
        Ultimate frequency for :func:`hagglund_oscillation`; default
        ``2 pi / period`` of the limit cycle of ``e``.
    deadband : float, [op], optional
        Dead band of :func:`reversals` for ``op`` and ``mv`` (default 0).

    Returns
    -------
    dict of str to float
        With ``e = sp - pv``:

        ``iae`` [pv]*s, ``ise`` [pv]^2*s, ``error_std`` [pv]
            :func:`iae`, :func:`ise`, :func:`error_std` of ``e``.
        ``lc_present`` (0.0 or 1.0), ``lc_amplitude`` [pv], ``lc_period`` [s],
        ``lc_n_cycles``, ``lc_regularity``
            the limit cycle of ``e`` by the benchmark rule of
            :func:`valve_gym.oscillation.detect_oscillation` (``lc_amplitude = 0.0``
            and ``lc_period = inf`` without a limit cycle; ``lc_n_cycles`` the
            record length over the period, ``lc_regularity`` Thornhill's ``r``,
            both 0.0 when no period could be read).
        ``crest_factor``
            :func:`crest_factor` of ``e`` (0.0 if ``e`` is flat).
        ``hagglund_detections``, ``hagglund_alarms``
            ``n_detections`` and ``n_alarms`` (alarm episodes) of
            :func:`hagglund_oscillation`; both 0.0 when ``omega_u`` is None
            and ``e`` has no limit cycle to estimate it from.
        ``op_travel`` [op], ``op_reversals_per_hour`` [1/h]
            :func:`travel` and :func:`reversals_per_hour` of ``op``.
        ``valve_travel`` [op], ``valve_reversals_per_hour`` [1/h]
            the same for ``mv``; present only when ``mv`` is given.

        The keys are listed in :data:`LOOP_METRIC_KEYS`, in that order.

    Raises
    ------
    ValueError
        On any bad signal, mismatched lengths, a non-uniform time vector,
        ``dt <= 0`` or ``span <= 0``.

    References
    ----------
    See the individual functions.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0.0, 600.0, 0.5)
    >>> pv = 50.0 + 2.0 * np.sin(2 * np.pi * t / 60.0)
    >>> op = 40.0 + 5.0 * np.cos(2 * np.pi * t / 60.0)
    >>> m = loop_metrics(t, 50.0, pv, op, span=100.0)
    >>> m["lc_present"], round(m["lc_amplitude"], 2), round(m["lc_period"], 1)   # 2 m, within 1 %
    (1.0, 1.99, 60.0)
    >>> round(m["op_reversals_per_hour"])    # 19 extremes in 599.5 s
    114
    """
    pv = _as_signal(pv, "pv")
    dt = _dt_from(t_or_dt, pv.size)
    if np.ndim(sp) == 0:
        sp = np.full(pv.size, _as_scalar(sp, "sp"))
    else:
        sp = _as_signal(sp, "sp")
        _same_length("pv", pv, "sp", sp)
    op = _as_signal(op, "op")
    _same_length("pv", pv, "op", op)
    if mv is not None:
        mv = _as_signal(mv, "mv")
        _same_length("pv", pv, "mv", mv)
    span = _positive(span, "span")
    deadband = _nonnegative(deadband, "deadband")
    if omega_u is not None:
        omega_u = _positive(omega_u, "omega_u", "rad/s")

    e = sp - pv
    lc = detect_oscillation(e, dt, "benchmark")
    if omega_u is None and lc.present:
        omega_u = 2.0 * math.pi / lc.period_s
    if omega_u is not None:
        hg = hagglund_oscillation(e, dt, span=span, omega_u=omega_u)
        n_det, n_alarms = hg.n_detections, hg.n_alarms
    else:
        n_det, n_alarms = 0, 0
    out = {
        "iae": iae(e, dt),
        "ise": ise(e, dt),
        "error_std": error_std(e),
        "lc_present": float(lc.present),
        "lc_amplitude": float(lc.amplitude),
        "lc_period": float(lc.period_s) if lc.present else math.inf,
        "lc_n_cycles": float(lc.n_cycles),
        "lc_regularity": float(lc.regularity) if math.isfinite(lc.regularity) else 0.0,
        "crest_factor": crest_factor(e),
        "hagglund_detections": float(n_det),
        "hagglund_alarms": float(n_alarms),
        "op_travel": travel(op),
        "op_reversals_per_hour": reversals_per_hour(op, dt, deadband),
    }
    if mv is not None:
        out["valve_travel"] = travel(mv)
        out["valve_reversals_per_hour"] = reversals_per_hour(mv, dt, deadband)
    return out
