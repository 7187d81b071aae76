r"""Curve fitting of the oscillation's half-cycles: triangle vs sine (He et al. 2007).

Behind a sticking valve the signal that integrates the valve's jumps is
triangular: the OP of a self-regulating loop (the PI integrates a
square-ish error), the PV of an integrating loop.  An oscillation from
tuning or from a smooth disturbance is closer to a sine.  Each half-cycle
(between zero crossings of the detrended, lightly smoothed signal) is
fitted by least squares with a half sine and with a triangle whose peak
position is free.

Notes
-----
.. math:: SI = \frac{MSE_{sin}}{MSE_{sin} + MSE_{tri}}

summed over the half-cycles.  Published bands: ``SI > 0.6`` stiction,
``SI < 0.4`` no stiction, undetermined between.  Half-cycles shorter than 4
samples are skipped.  A square wave reads as a sine here (both fit it
equally badly), hence the choice of signal above.

References
----------
.. [1] Q.P. He, J. Wang, M. Pottmann, S.J. Qin, "A curve fitting method for
   detecting valve stiction in oscillating control loops", Industrial &
   Engineering Chemistry Research 46 (2007) 4549-4560.
"""
from __future__ import annotations

import numpy as np

from ...signals import detrend
from ._base import Evidence, check_signals, not_applicable, oscillation, reliability

__all__ = ["stiction_shape_index", "waveform_evidence"]

CITE = "He, Wang, Pottmann & Qin 2007, Ind. Eng. Chem. Res. 46, 4549-4560"
DOC = "SI = MSE_sin/(MSE_sin + MSE_tri) over half-cycles; > 0.6 stiction, < 0.4 no stiction"

_PEAKS = np.linspace(0.1, 0.9, 17)


def _fit_half(x):
    """Squared errors of the best half sine and best triangle through one half-cycle."""
    L = len(x)
    t = (np.arange(L) + 0.5) / L
    b = np.sin(np.pi * t)
    a = (x @ b) / (b @ b)
    e_sin = float(np.sum((x - a * b) ** 2))
    tri = np.where(t[None, :] < _PEAKS[:, None], t[None, :] / _PEAKS[:, None],
                   (1 - t[None, :]) / (1 - _PEAKS[:, None]))
    at = (tri @ x) / np.sum(tri * tri, axis=1)
    e_tri = float(np.min(np.sum((x[None, :] - at[:, None] * tri) ** 2, axis=1)))
    return e_sin, e_tri


def stiction_shape_index(x, period: float):
    """He's index of ``x`` (T,) oscillating with ``period`` samples.

    Returns
    -------
    si : float, 0..1 (nan when fewer than 2 half-cycles could be fitted)
    n_half : int, half-cycles fitted
    """
    x = detrend(x)
    w = max(1, int(round(period / 10)))
    xs = np.convolve(x, np.ones(w) / w, mode="same") if w > 1 else x
    s = np.sign(xs)
    zc = np.nonzero(s[1:] * s[:-1] < 0)[0] + 1
    e_sin = e_tri = 0.0
    n = 0
    for a, b in zip(zc[:-1], zc[1:]):
        if b - a < 4 or b - a < period / 6:
            continue
        es, et = _fit_half(x[a:b])
        e_sin += es
        e_tri += et
        n += 1
    if n < 2 or e_sin + e_tri <= 0:
        return float("nan"), n
    return e_sin / (e_sin + e_tri), n


def waveform_evidence(op, pv, dt: float = 1.0, plant: str = "first_order") -> Evidence:
    """He et al.'s curve-fitting test on the OP (self-regulating) or the PV (integrating).

    Parameters
    ----------
    op, pv : (T,) arrays
    dt : float, sample time [s]
    plant : str, ``'integrating'`` fits the PV, any other plant the OP

    Returns
    -------
    Evidence, ``value`` = SI (0..1); ``details``: ``n_half_cycles``, ``period_samples``
    """
    op, pv = check_signals(op, pv, dt)
    x, name = (pv, "PV") if plant == "integrating" else (op, "OP")
    osc = oscillation(x)
    if not osc.present:
        osc2 = oscillation(pv if name == "OP" else op)
        if not osc2.present:
            return not_applicable("waveform", CITE, f"the {name} does not oscillate regularly", DOC)
        osc = osc2
    si, nh = stiction_shape_index(x, osc.period_samples)
    if not np.isfinite(si):
        return not_applicable("waveform", CITE, f"fewer than 2 half-cycles of the {name} to fit", DOC)
    verdict = "stiction" if si > 0.6 else ("no stiction" if si < 0.4 else "undetermined")
    return Evidence("waveform", CITE, True, float(si), reliability(osc) * min(1.0, nh / 6), verdict,
                    f"{name} half-cycles fit a {'triangle' if si > 0.5 else 'sine'} better", DOC,
                    {"n_half_cycles": float(nh), "period_samples": osc.period_samples})
