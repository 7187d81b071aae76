"""Small signal helpers: one implementation each, shared by every part of valve_gym.

The detrended signal, the autocorrelation (and autocovariance), the zero crossings of an
autocorrelation, a robust white-noise estimate, a moving average and the Ornstein-Uhlenbeck
sequence of the load disturbances.  The oscillation detector built on them is
:mod:`valve_gym.oscillation`.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["acf", "acf_zero_crossings", "detrend", "noise_sigma", "moving_average", "ou_sequence"]


def detrend(x) -> np.ndarray:
    """``x`` (T,) minus its least-squares straight line (same units as ``x``).

    Examples
    --------
    >>> import numpy as np
    >>> np.allclose(detrend(np.arange(5.0) * 2 + 1), 0.0)
    True
    """
    x = np.asarray(x, float)
    t = np.arange(len(x))
    return x - np.polyval(np.polyfit(t, x, 1), t)


def acf(x, max_lag: int, normalise: bool = True, demean: bool = True) -> np.ndarray:
    """Biased autocorrelation of ``x`` (mean removed) at lags ``0..max_lag``; zeros for a constant ``x``.

    ``r[k] = sum_t x_t x_{t+k} / sum_t x_t^2`` by FFT; with ``normalise=False`` the biased
    autocovariance ``c[k] = sum_t x_t x_{t+k} / N`` ([x]^2) instead.  ``max_lag`` is at most
    ``N - 1``.  ``demean=False`` takes ``x`` as already centred (its mean is not subtracted again).

    Examples
    --------
    >>> import numpy as np
    >>> r = acf(np.sin(np.arange(200) * 2 * np.pi / 20), 20)
    >>> round(float(r[0]), 6), bool(r[10] < -0.8), bool(r[20] > 0.8)
    (1.0, True, True)
    """
    x = np.asarray(x, float)
    if demean:
        x = x - np.mean(x)
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    a = np.fft.irfft(f * np.conj(f), 2 * n)[: max_lag + 1]
    if not normalise:
        return a / n
    return a / a[0] if a[0] > 0 else np.zeros(a.size)


def acf_zero_crossings(r, n_max: int | None = None) -> np.ndarray:
    """Interpolated lags (samples) of the first ``n_max`` sign changes of an autocorrelation ``r``.

    A sign change is between lags ``k`` and ``k + 1`` where the sign bit differs; the lag is
    interpolated linearly, ``k + r_k / (r_k - r_{k+1})``.  All of them when ``n_max`` is None.

    Examples
    --------
    >>> import numpy as np
    >>> acf_zero_crossings(np.array([1.0, 0.5, -0.5, -1.0, 1.0]))
    array([1.5, 3.5])
    """
    r = np.asarray(r, float)
    s = np.signbit(r)
    k = np.flatnonzero(s[1:] != s[:-1])
    if n_max is not None:
        k = k[:n_max]
    r0, r1 = r[k], r[k + 1]
    return k + r0 / (r0 - r1)


def noise_sigma(y) -> float:
    """Robust std of white noise on a smooth signal ``y`` (T,), from its second differences ([y]).

    ``var(y[k+1] - 2 y[k] + y[k-1]) = 6 sigma**2`` for white noise, while the second differences
    of a well-sampled oscillation are small except at its corners, which the median ignores.

    Examples
    --------
    >>> import numpy as np
    >>> y = np.sin(np.arange(5000) / 50) + 0.1 * np.random.default_rng(0).standard_normal(5000)
    >>> round(noise_sigma(y), 2)
    0.1
    """
    y = np.asarray(y, float)
    if y.size < 3:
        return 0.0
    d2 = np.diff(y, 2)
    return 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)


def moving_average(x, w: int) -> np.ndarray:
    """Moving average of width ``w`` samples (centred to within half a sample), edges padded with the end values.

    Examples
    --------
    >>> moving_average(np.array([0.0, 0.0, 3.0, 0.0, 0.0]), 3).tolist()
    [0.0, 1.0, 1.0, 1.0, 0.0]
    """
    x = np.asarray(x, float)
    if w <= 1:
        return x
    left = (w - 1) // 2
    xp = np.concatenate([np.full(left, x[0]), x, np.full(w - 1 - left, x[-1])])
    c = np.concatenate([[0.0], np.cumsum(xp)])
    return (c[w:] - c[:-w]) / w


def ou_sequence(w, a: float | np.ndarray, sigma: float | np.ndarray = 1.0) -> np.ndarray:
    r"""Ornstein-Uhlenbeck (first-order autoregressive) sequence driven by white noise ``w``.

    .. math:: x_0 = 0, \qquad x_k = a\,x_{k-1} + \sigma\sqrt{1 - a^2}\;w_k \quad (k \ge 1)

    so that with ``w`` standard normal, ``x`` tends to a stationary std ``sigma`` with correlation
    time ``-dt / ln a`` (``a = exp(-dt / tau)``).  The one load generator of valve_gym (the
    benchmark's loads, the regulation task, the synthetic recordings, the fleet simulator).

    Parameters
    ----------
    w : (..., T) array, white noise (``w[..., 0]`` is not used); time along the last axis
    a : float or (...,) array, pole ``exp(-dt / tau)`` in [0, 1)
    sigma : float or (...,) array, stationary std [units of x]

    Returns
    -------
    (..., T) float array

    Examples
    --------
    >>> ou_sequence(np.array([9.0, 1.0, 0.0, 0.0]), 0.5, sigma=2 / np.sqrt(0.75)).tolist()
    [0.0, 2.0, 1.0, 0.5]
    """
    from scipy.signal import lfilter

    w = np.asarray(w, float)
    a = np.asarray(a, float)
    g = np.asarray(sigma, float) * np.sqrt(1.0 - a * a)
    v = w * (g[..., None] if g.ndim else g)
    v[..., 0] = 0.0
    if a.ndim == 0:
        return np.asarray(lfilter([1.0], [1.0, -float(a)], v, axis=-1), dtype=float)
    out = np.empty_like(v)
    for i in np.ndindex(a.shape):   # one pole per row
        out[i] = lfilter([1.0], [1.0, -float(a[i])], v[i])
    return out
