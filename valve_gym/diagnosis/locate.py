"""Locate the model mismatch: where in time, under which operating conditions.

Given a recording and a free-run simulation, the residual
``r = PV_measured - PV_simulated`` is examined three ways:

* **in time** -- the moving RMS of ``r`` over ``w`` samples is compared with a
  robust threshold (``median + 2 * 1.4826 * MAD`` of the moving RMS, and at
  least twice the measurement-noise level estimated from the sample-to-sample
  differences of ``r``); samples above it form regions, gaps shorter than
  ``w`` are merged, regions shorter than ``w/2`` dropped.  When nothing
  stands out although the residual is far above the noise everywhere (a
  free-run fit that compromises over the whole record), the worst fifth of
  the record is shown instead;
* **by condition** -- the residual's RMS on the samples of each operating
  condition (direction of the controller output, just after its reversals,
  output terciles, high/low PV, after set-point changes, PV at the sensor's
  range end) against the RMS on all other samples, with a z-score of the
  difference of mean squares that uses the effective number of independent
  samples (the residual is autocorrelated);
* **as a signal** -- autocorrelation of ``r`` with the 95 % band
  ``+-1.96/sqrt(N)`` and the Ljung-Box portmanteau test; cross-correlation of
  ``r`` with the controller output with the same band; the dominant period of
  ``r``.

References
----------
.. [1] G.M. Ljung, G.E.P. Box, "On a measure of lack of fit in time series
   models", Biometrika 65(2), 297-303, 1978.
.. [2] L. Ljung, "System identification: theory for the user", 2nd ed.,
   Prentice Hall, 1999, sec. 16.6 (residual analysis).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..signals import acf

__all__ = ["Region", "ConditionStat", "ResidualTests", "MismatchReport", "locate_mismatch",
           "condition_masks", "op_reversals", "dominant_period", "apparent_band", "noise_level"]


@dataclass
class Region:
    """A stretch of the record where the model misses.

    Attributes
    ----------
    t_start, t_end : float, s
    i_start, i_end : int, sample indices (end exclusive)
    rms : float, residual RMS inside [PV]
    mean : float, mean residual inside [PV] (> 0: the model is too low)
    peak : float, largest |residual| inside [PV]
    share_sse : float, fraction of the record's squared error inside
    conditions : dict, fraction of the region's samples in each condition
    """

    t_start: float
    t_end: float
    i_start: int
    i_end: int
    rms: float
    mean: float
    peak: float
    share_sse: float
    conditions: dict[str, float] = field(default_factory=dict)


@dataclass
class ConditionStat:
    """Residual under one operating condition against the rest of the record.

    Attributes
    ----------
    condition : str
    description : str
    n : int, samples in the condition
    fraction : float, of the record
    rms_in, rms_out : float, residual RMS in the condition / elsewhere [PV]
    ratio : float, ``rms_in / rms_out``
    mean_in, mean_out : float, mean residual [PV]
    z : float, z-score of ``ms_in - ms_out`` (effective-sample corrected)
    significant : bool, ``z > 3`` and ``ratio > 1.25``
    """

    condition: str
    description: str
    n: int
    fraction: float
    rms_in: float
    rms_out: float
    ratio: float
    mean_in: float
    mean_out: float
    z: float
    significant: bool


@dataclass
class ResidualTests:
    """Whiteness and input cross-correlation of the residual.

    Attributes
    ----------
    lags : list of int, 1..L
    acf : list of float, residual autocorrelation at ``lags``
    acf_bound : float, 95 % band ``1.96/sqrt(N)``
    acf_outside : float, fraction of ``acf`` outside the band
    ljung_box_q : float, Ljung-Box statistic over ``L`` lags
    ljung_box_p : float, its p-value (chi-square, L degrees of freedom)
    white : bool, ``ljung_box_p > 0.05``
    ccf_lags : list of int, -L..L (positive: input leads the residual)
    ccf : list of float, cross-correlation of residual and controller output
    ccf_bound : float, 95 % band
    ccf_outside : float, fraction outside the band
    ccf_peak_lag : int, lag of the largest |ccf|
    ccf_peak : float
    period : float or None, dominant period of the residual [s]
    noise_std : float, measurement-noise level from sample differences [PV]
    n_eff : float, effective number of independent residual samples
    """

    lags: list[int]
    acf: list[float]
    acf_bound: float
    acf_outside: float
    ljung_box_q: float
    ljung_box_p: float
    white: bool
    ccf_lags: list[int]
    ccf: list[float]
    ccf_bound: float
    ccf_outside: float
    ccf_peak_lag: int
    ccf_peak: float
    period: float | None
    noise_std: float
    n_eff: float


@dataclass
class MismatchReport:
    """Where the model misses: regions in time, conditions, residual tests.

    Attributes
    ----------
    regions : list of Region, largest share of squared error first
    conditions : list of ConditionStat
    tests : ResidualTests
    threshold : float, moving-RMS threshold of the regions [PV]
    window : int, moving-RMS window [samples]
    rms : float, residual RMS of the whole record [PV]
    moving_rms : (T,) ndarray, the moving RMS (for plots)
    """

    regions: list[Region]
    conditions: list[ConditionStat]
    tests: ResidualTests
    threshold: float
    window: int
    rms: float
    moving_rms: np.ndarray | None = field(repr=False, default=None)

    def condition(self, name: str) -> ConditionStat | None:
        """The :class:`ConditionStat` called ``name`` (None if not computed)."""
        for c in self.conditions:
            if c.condition == name:
                return c
        return None

    def to_dict(self) -> dict:
        """JSON-ready dict (no arrays)."""
        return {"regions": [asdict(r) for r in self.regions],
                "conditions": [asdict(c) for c in self.conditions],
                "tests": asdict(self.tests), "threshold": self.threshold,
                "window": self.window, "rms": self.rms}


# --------------------------------------------------------------------------- helpers
def _moving_mean(x, w):
    w = max(1, int(w))
    c = np.cumsum(np.concatenate([[0.0], x]))
    n = len(x)
    lo = np.clip(np.arange(n) - w // 2, 0, n)
    hi = np.clip(np.arange(n) + (w - w // 2), 0, n)
    return (c[hi] - c[lo]) / np.maximum(hi - lo, 1)


def _ccf(r, u, L):
    r = np.asarray(r, float) - np.mean(r)
    u = np.asarray(u, float) - np.mean(u)
    n = len(r)
    den = np.sqrt(np.sum(r * r) * np.sum(u * u))
    lags = np.arange(-L, L + 1)
    out = np.zeros(len(lags))
    if den == 0:
        return lags, out
    for i, k in enumerate(lags):
        if k >= 0:
            out[i] = np.sum(r[k:] * u[: n - k]) / den
        else:
            out[i] = np.sum(r[: n + k] * u[-k:]) / den
    return lags, out


def noise_level(r) -> float:
    """Measurement-noise std of ``r`` from its first differences (robust) [units of r]."""
    d = np.diff(np.asarray(r, float))
    if d.size == 0:
        return 0.0
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / np.sqrt(2.0))


def dominant_period(r, dt: float, min_period: float | None = None,
                    max_period: float | None = None) -> float | None:
    """Period [s] of the strongest periodogram peak of ``r`` (None if flat).

    Frequencies with fewer than 2.5 cycles in the record are skipped; the
    peak is refined by parabolic interpolation of the log power.
    """
    r = np.asarray(r, float)
    n = len(r)
    if n < 16:
        return None
    x = (r - r.mean()) * np.hanning(n)
    nf = 4 * n
    P = np.abs(np.fft.rfft(x, nf)) ** 2
    f = np.fft.rfftfreq(nf, dt)
    lo_f = 2.5 / (n * dt) if max_period is None else max(1.0 / max_period, 2.5 / (n * dt))
    hi_f = 1.0 / (3 * dt) if min_period is None else 1.0 / min_period
    m = (f >= lo_f) & (f <= hi_f)
    if not m.any() or not np.any(P[m] > 0):
        return None
    idx = np.where(m)[0]
    i = idx[np.argmax(P[idx])]
    if 0 < i < len(P) - 1 and P[i - 1] > 0 and P[i + 1] > 0:
        a, b, c = np.log(P[i - 1]), np.log(P[i]), np.log(P[i + 1])
        den = a - 2 * b + c
        off = 0.5 * (a - c) / den if den != 0 else 0.0
        fi = f[i] + np.clip(off, -0.5, 0.5) * (f[1] - f[0])
    else:
        fi = f[i]
    return float(1.0 / fi) if fi > 0 else None


def op_reversals(op, delta: float | None = None) -> np.ndarray:
    """Indices where the controller output reverses direction (with hysteresis).

    A reversal is counted when ``op`` moves back from its last extreme by more
    than ``delta`` (default: 3 times its sample-to-sample noise, at least
    0.1 % of the stroke); the index returned is that of the extreme.
    """
    u = np.asarray(op, float)
    if delta is None:
        delta = max(3.0 * noise_level(u), 0.001)
    out = []
    d = 0
    hi = lo = u[0]
    ihi = ilo = 0
    for i in range(1, len(u)):
        v = u[i]
        if v > hi:
            hi, ihi = v, i
        if v < lo:
            lo, ilo = v, i
        if d >= 0 and hi - v > delta:
            if d == 1:
                out.append(ihi)
            d = -1
            lo, ilo = v, i
        elif d <= 0 and v - lo > delta:
            if d == -1:
                out.append(ilo)
            d = 1
            hi, ihi = v, i
    return np.asarray(out, int)


def condition_masks(op, pv, sp=None, dt: float = 1.0, window: int = 5,
                    sat_hi: float | None = None, sat_lo: float | None = None) -> dict[str, tuple]:
    """Boolean masks ``(T,)`` of the operating conditions, with a description each."""
    u = np.asarray(op, float)
    y = np.asarray(pv, float)
    T = len(u)
    masks: dict[str, tuple] = {}
    us = _moving_mean(u, 3)
    du = np.gradient(us)
    eps = max(noise_level(u), 0.0005 * max(np.ptp(u), 1e-9))
    masks["op_rising"] = (du > eps, "controller output rising")
    masks["op_falling"] = (du < -eps, "controller output falling")
    masks["op_steady"] = (np.abs(du) <= eps, "controller output (nearly) still")
    rev = op_reversals(u)
    near = np.zeros(T, bool)
    span = max(3, int(window))
    for i in rev:
        near[i:i + span] = True
    masks["near_op_reversal"] = (near, f"within {span} samples after a reversal of the controller output")
    q1, q2 = np.quantile(u, [1 / 3, 2 / 3])
    masks["op_low"] = (u <= q1, "controller output in its lowest third")
    masks["op_mid"] = ((u > q1) & (u < q2), "controller output in its middle third")
    masks["op_high"] = (u >= q2, "controller output in its highest third")
    hi, lo = np.quantile(y, [0.9, 0.1])
    masks["pv_high"] = (y >= hi, "PV in its highest 10 %")
    masks["pv_low"] = (y <= lo, "PV in its lowest 10 %")
    if sp is not None:
        s = np.asarray(sp, float)
        ds = np.abs(np.diff(s, prepend=s[0]))
        big = ds > 0.02 * max(np.ptp(y), 1e-12)
        if 0 < big.sum() < 0.2 * T:
            after = np.zeros(T, bool)
            for i in np.where(big)[0]:
                after[i:i + 3 * span] = True
            masks["after_sp_change"] = (after, f"within {3 * span} samples after a set-point change")
    if sat_hi is not None:
        masks["pv_at_upper_range"] = (np.abs(y - sat_hi) <= 1e-9 * max(abs(sat_hi), 1),
                                      "PV pinned at the upper end of its range")
    if sat_lo is not None:
        masks["pv_at_lower_range"] = (np.abs(y - sat_lo) <= 1e-9 * max(abs(sat_lo), 1),
                                      "PV pinned at the lower end of its range")
    return masks


def _regions(r, t, dt, above, w, masks, sse) -> list[Region]:
    """Merge samples flagged ``above`` into regions (gaps < ``w`` merged, < ``w/2`` dropped)."""
    idx = np.flatnonzero(above)
    out: list[Region] = []
    if not idx.size:
        return out
    starts = [idx[0]]
    ends = []
    for a, b in zip(idx[:-1], idx[1:]):
        if b - a > w:
            ends.append(a + 1)
            starts.append(b)
    ends.append(idx[-1] + 1)
    for a, b in zip(starts, ends):
        if b - a < max(2, w // 2):
            continue
        seg = r[a:b]
        out.append(Region(
            t_start=float(t[a]), t_end=float(t[b - 1] + dt), i_start=int(a), i_end=int(b),
            rms=float(np.sqrt(np.mean(seg ** 2))), mean=float(np.mean(seg)),
            peak=float(np.max(np.abs(seg))), share_sse=float(np.sum(seg ** 2) / sse),
            conditions={k: float(np.mean(m[a:b])) for k, (m, _) in masks.items()}))
    return out


# --------------------------------------------------------------------------- main
def locate_mismatch(t, op, pv, y_sim, sp=None, dt: float | None = None, window: int | None = None,
                    max_lag: int | None = None, sat_hi: float | None = None,
                    sat_lo: float | None = None, max_regions: int = 12) -> MismatchReport:
    """Locate where and when the simulation ``y_sim`` misses the measured ``pv``.

    Parameters
    ----------
    t : (T,) sample times [s]
    op : (T,) controller output 0..1
    pv : (T,) measured PV [PV]
    y_sim : (T,) free-run simulated PV [PV]
    sp : (T,) set point [PV], optional
    dt : float, sample time [s] (default from ``t``)
    window : int, moving-RMS window [samples] (default ``N/100``, 5..50)
    max_lag : int, lags of the correlation tests (default ``min(40, N/5)``)
    sat_hi, sat_lo : float, sensor range ends (conditions "PV pinned")
    max_regions : int, regions kept (largest share of squared error)

    Returns
    -------
    MismatchReport

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(500.0); y = np.sin(t / 30)
    >>> ys = y.copy(); ys[200:260] -= 0.5          # the model misses 200..260 s
    >>> rep = locate_mismatch(t, 0.5 + 0.1 * y, y, ys)
    >>> r = rep.regions[0]
    >>> bool(195 <= r.t_start <= 205 and 255 <= r.t_end <= 265)
    True
    """
    from scipy.stats import chi2

    t = np.asarray(t, float)
    y = np.asarray(pv, float)
    u = np.asarray(op, float)
    ys = np.asarray(y_sim, float)
    T = len(y)
    dt = float(np.median(np.diff(t))) if dt is None else float(dt)
    r = y - ys
    w = int(window or np.clip(round(T / 100), 5, 50))
    msq = _moving_mean(r * r, w)
    mrms = np.sqrt(msq)
    sig = noise_level(r)
    med = np.median(mrms)
    mad = np.median(np.abs(mrms - med)) * 1.4826
    thr = float(max(med + 2.0 * mad, 2.0 * sig, 1e-300))
    masks = condition_masks(u, y, sp, dt, w, sat_hi, sat_lo)
    sse = float(np.sum(r * r)) or 1e-300
    regions = _regions(r, t, dt, mrms > thr, w, masks, sse)
    if not regions and med > 3.0 * sig:
        # the model misses everywhere (a free-run compromise): show where it misses most
        thr = float(np.quantile(mrms, 0.8))
        regions = _regions(r, t, dt, mrms > thr, w, masks, sse)
    regions.sort(key=lambda g: -g.share_sse)
    regions = regions[:max_regions]
    # effective samples
    from .fit import effective_n
    neff = effective_n(r)
    conds: list[ConditionStat] = []
    r2 = r * r
    for name, (m, desc) in masks.items():
        nin = int(m.sum())
        if nin < 3 or nin > T - 3:
            continue
        a, b = r2[m], r2[~m]
        ms_in, ms_out = float(a.mean()), float(b.mean())
        f_eff = neff / T
        se = np.sqrt(a.var() / max(nin * f_eff, 1.0) + b.var() / max((T - nin) * f_eff, 1.0))
        z = float((ms_in - ms_out) / se) if se > 0 else 0.0
        rin, rout = np.sqrt(ms_in), np.sqrt(ms_out)
        ratio = float(rin / rout) if rout > 0 else float("inf")
        conds.append(ConditionStat(condition=name, description=desc, n=nin, fraction=nin / T,
                                   rms_in=float(rin), rms_out=float(rout), ratio=ratio,
                                   mean_in=float(np.mean(r[m])), mean_out=float(np.mean(r[~m])),
                                   z=z, significant=bool(z > 3.0 and ratio > 1.25)))
    # residual tests
    L = int(max_lag or max(1, min(40, T // 5)))
    a = acf(r, L)
    bound = 1.96 / np.sqrt(T)
    k = np.arange(1, L + 1)
    Q = float(T * (T + 2) * np.sum(a[1:] ** 2 / (T - k)))
    p = float(chi2.sf(Q, L))
    lags, c = _ccf(r, u, L)
    ip = int(np.argmax(np.abs(c)))
    period = dominant_period(r, dt)
    tests = ResidualTests(lags=k.tolist(), acf=a[1:].tolist(), acf_bound=float(bound),
                          acf_outside=float(np.mean(np.abs(a[1:]) > bound)), ljung_box_q=Q,
                          ljung_box_p=p, white=bool(p > 0.05), ccf_lags=lags.tolist(),
                          ccf=c.tolist(), ccf_bound=float(bound),
                          ccf_outside=float(np.mean(np.abs(c) > bound)),
                          ccf_peak_lag=int(lags[ip]), ccf_peak=float(c[ip]), period=period,
                          noise_std=sig, n_eff=float(neff))
    return MismatchReport(regions=regions, conditions=conds, tests=tests, threshold=thr,
                          window=w, rms=float(np.sqrt(np.mean(r * r))), moving_rms=mrms)


def apparent_band(op, stem, delta: float | None = None) -> dict:
    """Controller-output travel a (simulated) valve needs before it moves after a reversal.

    For every reversal of the controller output ``op`` (hysteresis ``delta``,
    see :func:`op_reversals`) the travel of ``op`` from the reversal until the
    stem ``stem`` leaves its position is measured; a swing through which the
    stem never moves counts with its whole travel (a lower bound).

    Parameters
    ----------
    op, stem : (T,) controller output and stem position, 0..1
    delta : float, reversal hysteresis (default as :func:`op_reversals`)

    Returns
    -------
    dict with ``band`` (median over reversals, fraction of stroke), ``n``
    (reversals used) and ``stuck_through`` (fraction of swings with no stem
    motion at all).

    Examples
    --------
    >>> import numpy as np
    >>> u = 0.5 + 0.05 * np.sin(np.arange(400) / 10)
    >>> b, x, h = 0.02, 0.5, np.empty(400)
    >>> for k in range(400):   # backlash of width b
    ...     x = min(max(x, u[k] - b / 2), u[k] + b / 2); h[k] = x
    >>> bool(abs(apparent_band(u, h)["band"] - b) < 0.003)   # sampled: within one OP step
    True
    """
    u = np.asarray(op, float)
    h = np.asarray(stem, float)
    rev = list(op_reversals(u, delta))
    if len(rev) < 2:
        return {"band": 0.0, "n": 0, "stuck_through": 0.0}
    tol = 1e-6
    bands = []
    stuck = 0
    ends = rev[1:] + [len(u) - 1]
    for i, j in zip(rev, ends):
        seg = np.abs(h[i + 1:j + 1] - h[i]) > tol
        if seg.any():
            k = i + 1 + int(np.argmax(seg))
            bands.append(abs(u[k] - u[i]))
        else:
            bands.append(abs(u[j] - u[i]))
            stuck += 1
    return {"band": float(np.median(bands)), "n": len(bands),
            "stuck_through": stuck / len(bands)}
