"""Small signal helpers shared by the diagnosis, its stiction evidence and the fleet screen.

One implementation each, so the mismatch locator, the stiction methods and the fleet's
oscillation screen read the same autocorrelation of the same detrended signal.
"""
from __future__ import annotations

import numpy as np

__all__ = ["acf", "detrend"]


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
