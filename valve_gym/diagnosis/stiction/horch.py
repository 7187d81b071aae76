"""Horch's tests: cross-correlation (self-regulating loops) and PV-derivative shape (integrating).

Self-regulating loops: the cross-correlation of OP and PV is odd behind a
sticking valve and even for oscillations from tuning or disturbances
(:func:`valve_gym.diagnosis.indices.horch_ccf`, Horch 1999).  Integrating
loops (levels): the PV is the integral of the valve's square wave, so the
derivative of the (smoothed) PV is square and its distribution has two peaks
(Horch 2000); a sinusoidal oscillation gives the arcsine distribution and
noise a Gaussian.  The two peaks are measured by Sarle's bimodality
coefficient ``b = (g^2 + 1) / kappa`` (skewness ``g``, kurtosis ``kappa``):
1 for two spikes, 2/3 for a sine, 1/3 for a Gaussian.

References
----------
.. [1] A. Horch, "A simple method for detection of stiction in control valves",
   Control Engineering Practice 7(10) (1999) 1221-1231.
.. [2] A. Horch, "Condition monitoring of control loops", PhD thesis, KTH
   Stockholm, 2000 (integrating processes: distribution of the PV's derivative).
"""
from __future__ import annotations

import numpy as np

from ..indices import horch_ccf
from ._base import Evidence, check_signals, not_applicable, oscillation, reliability

__all__ = ["horch_evidence"]

CITE_CCF = "Horch 1999, Control Engineering Practice 7, 1221-1231"
CITE_INT = "Horch 2000, PhD thesis KTH (integrating loops: PV-derivative distribution)"
DOC_CCF = ("phase index |tau_r - tau_l|/(tau_r + tau_l) of the OP-PV cross-correlation, 0 (even) .. 1 "
           "(odd); > 2/3 stiction, < 1/3 no stiction")
DOC_INT = ("bimodality coefficient (g^2 + 1)/kurtosis of the smoothed PV derivative: 1 two peaks "
           "(stiction), 0.67 sine, 0.33 noise; > 0.8 stiction, < 0.7 no stiction")


def _smooth(x, w):
    if w <= 1:
        return x
    k = np.ones(w) / w
    return np.convolve(x, k, mode="valid")


def _integrating(pv) -> Evidence:
    osc = oscillation(pv)
    if not osc.present:
        return not_applicable("horch", CITE_INT, "the PV does not oscillate regularly", DOC_INT)
    w = max(1, int(round(osc.period_samples / 12)))
    d = np.diff(_smooth(pv, w))
    d = d - d.mean()
    s = d.std()
    if s <= 0:
        return not_applicable("horch", CITE_INT, "the PV derivative is constant", DOC_INT)
    g = float(np.mean(d ** 3) / s ** 3)
    kap = float(np.mean(d ** 4) / s ** 4)
    b = (g * g + 1.0) / kap
    verdict = "stiction" if b > 0.8 else ("no stiction" if b < 0.7 else "undetermined")
    return Evidence("horch", CITE_INT, True, float(b), reliability(osc), verdict,
                    "two-peaked PV slope: square valve moves" if verdict == "stiction" else
                    "the PV slope is not two-valued", DOC_INT,
                    {"period_samples": osc.period_samples, "regularity": osc.regularity})


def horch_evidence(op, pv, dt: float = 1.0, plant: str = "first_order") -> Evidence:
    """Horch's stiction test suited to the plant.

    Parameters
    ----------
    op, pv : (T,) arrays, controller output and process variable
    dt : float, sample time [s]
    plant : str, ``'integrating'`` uses the PV-derivative test, any other the
        cross-correlation test

    Returns
    -------
    Evidence, ``value`` the phase index (self-regulating) or the bimodality
    coefficient (integrating)
    """
    op, pv = check_signals(op, pv, dt)
    if plant == "integrating":
        return _integrating(pv)
    h = horch_ccf(op, pv, dt, plant)
    if h["phase_index"] is None:
        return not_applicable("horch", CITE_CCF, h["reason"], DOC_CCF)
    osc = oscillation(pv)
    rel = max(reliability(osc), 0.3)
    return Evidence("horch", CITE_CCF, True, float(h["phase_index"]), rel,
                    h["verdict"], h["reason"], DOC_CCF,
                    {"tau_left_s": h["tau_left_s"], "tau_right_s": h["tau_right_s"],
                     "ccf_at_zero": h["ccf_at_zero"]})
