"""Small signal helpers shared by the diagnosis, its stiction evidence and the fleet screen.

One implementation each: the mismatch locator, the stiction methods and the fleet's oscillation
screen read the same detrended signal and autocorrelation, and all three ACF oscillation detectors
(those two and the benchmark's limit-cycle detector in :mod:`valve_gym.metrics`, which keeps its own
checked, power-of-two FFT autocorrelation) the same zero crossings; each computes Thornhill's
regularity from them with its own published rule.
"""
from __future__ import annotations

import numpy as np

__all__ = ["acf", "acf_zero_crossings", "detrend"]


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


def acf(x, max_lag: int) -> np.ndarray:
    """Biased autocorrelation of ``x`` (mean removed) at lags ``0..max_lag``; zeros for a constant ``x``.

    Examples
    --------
    >>> import numpy as np
    >>> r = acf(np.sin(np.arange(200) * 2 * np.pi / 20), 20)
    >>> round(float(r[0]), 6), bool(r[10] < -0.8), bool(r[20] > 0.8)
    (1.0, True, True)
    """
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    a = np.fft.irfft(f * np.conj(f))[: max_lag + 1]
    return a / a[0] if a[0] > 0 else np.zeros(max_lag + 1)


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
