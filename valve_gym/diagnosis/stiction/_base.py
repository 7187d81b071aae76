"""Shared pieces of the stiction methods: the typed evidence record and oscillation analysis.

Every method of :mod:`valve_gym.diagnosis.stiction` returns an :class:`Evidence`:
its own index value, whether the method applies to this record at all and how
reliable its reading is here.  :func:`oscillation` is the ``"stiction"`` rule of the
one oscillation detector (:func:`valve_gym.oscillation.detect_oscillation`,
Thornhill, Huang & Zhang 2003), which most methods need before they can say anything.

References
----------
.. [1] N.F. Thornhill, B. Huang, H. Zhang, "Detection of multiple oscillations
   in control loops", Journal of Process Control 13 (2003) 91-100.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...oscillation import Oscillation, detect_oscillation
from ...signals import detrend

__all__ = ["Evidence", "Oscillation", "oscillation", "bandpass", "check_signals", "not_applicable"]


@dataclass(frozen=True)
class Evidence:
    """What one stiction method says about one record.

    Attributes
    ----------
    method : str, short name (``'horch'``, ``'bicoherence'``, ``'ellipse'``, ``'waveform'``,
        ``'hammerstein'``)
    citation : str, the paper the method follows
    applicable : bool, False when the method's assumptions do not hold here (no
        oscillation, integrating plant for Horch, ...); ``value`` is then nan
    value : float, the method's own index (meaning in ``index_doc``), dimensionless
    reliability : float, 0..1, how much this reading can be trusted on this record
        (regularity of the oscillation, number of cycles, fit quality); 0 when not applicable
    verdict : str, the method's own published decision: ``'stiction'``, ``'no stiction'``,
        ``'undetermined'`` or ``'not applicable'``
    reason : str, one sentence
    index_doc : str, what ``value`` means and its published decision bands
    details : dict of str to float, secondary numbers (units in the key name)
    """

    method: str
    citation: str
    applicable: bool
    value: float
    reliability: float
    verdict: str
    reason: str
    index_doc: str = ""
    details: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready dict (nan becomes None)."""
        def f(x):
            x = float(x)
            return x if np.isfinite(x) else None
        return {"method": self.method, "citation": self.citation, "applicable": self.applicable,
                "value": f(self.value), "reliability": f(self.reliability), "verdict": self.verdict,
                "reason": self.reason, "index": self.index_doc,
                "details": {k: f(v) for k, v in self.details.items()}}


def not_applicable(method: str, citation: str, reason: str, index_doc: str = "") -> Evidence:
    """An :class:`Evidence` for a method whose assumptions do not hold on this record."""
    return Evidence(method, citation, False, float("nan"), 0.0, "not applicable", reason, index_doc)


def check_signals(op, pv, dt: float):
    """Validate and return ``(op, pv)`` as float arrays; clear errors for bad input."""
    op = np.asarray(op, float)
    pv = np.asarray(pv, float)
    if op.ndim != 1 or pv.ndim != 1 or op.shape != pv.shape:
        raise ValueError(f"op and pv must be 1-D arrays of the same length, got shapes {op.shape} "
                         f"and {pv.shape}")
    if len(op) < 20:
        raise ValueError(f"op and pv need at least 20 samples, got {len(op)}")
    if not (np.isfinite(op).all() and np.isfinite(pv).all()):
        raise ValueError("op and pv contain NaN or inf values; repair or drop those samples first "
                         "(load_recording does)")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    return op, pv


def oscillation(x, min_period: float = 4.0) -> Oscillation:
    """The oscillation of ``x`` (T,) [any units] by the stiction evidence's rule, in samples.

    :func:`valve_gym.oscillation.detect_oscillation` with ``rule="stiction"`` and ``dt = 1``
    (so ``period_s`` and :attr:`~valve_gym.oscillation.Oscillation.period_samples` are in
    samples): regular ACF zero crossings (the periods' std floored at one sample), 3 or more
    cycles in the record and a period of at least ``min_period`` samples.
    """
    return detect_oscillation(x, 1.0, "stiction", min_period=min_period)


def bandpass(x, period: float, width: float = 0.6) -> np.ndarray:
    """Zero-phase band-pass of ``x`` around ``1/period`` (FFT mask with cosine edges).

    Parameters
    ----------
    x : (T,) array
    period : float, samples
    width : float, relative half-width of the pass band below the fundamental

    Returns
    -------
    (T,) array, the filtered signal (mean removed)

    Notes
    -----
    Pass band ``f0 (1 - width) .. 3.5 f0`` (the fundamental and the 3rd
    harmonic that shapes a stick-slip cycle); the mask is 1 inside and falls
    off with a raised cosine over 20 % outside.  Zero phase: PV and OP keep
    their relative phase, which the ellipse needs.
    """
    x = detrend(x)
    n = len(x)
    f = np.fft.rfftfreq(n)
    f0 = 1.0 / period
    lo, hi = f0 * (1.0 - width), f0 * 3.5
    m = np.ones_like(f)
    edge_lo, edge_hi = 0.2 * lo, 0.2 * hi

    def ramp(d, w):
        return 0.5 * (1 + np.cos(np.pi * np.clip(d / w, 0, 1)))

    m = np.where(f < lo, ramp(lo - f, max(edge_lo, 1e-12)), m)
    m = np.where(f > hi, ramp(f - hi, max(edge_hi, 1e-12)), m)
    m[0] = 0.0
    return np.fft.irfft(np.fft.rfft(x) * m, n)


def reliability(osc: Oscillation | None) -> float:
    """0..1 trust in a shape method from the regularity and cycle count of the oscillation."""
    if osc is None or not osc.present:
        return 0.0
    r = min(1.0, (osc.regularity - 1.0) / 2.0 + 0.3)
    c = min(1.0, osc.n_cycles / 10.0)
    return float(max(0.0, r) * c)
