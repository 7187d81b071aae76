r"""Fast screening of a loop: whether it oscillates, and whether the oscillation looks like a sticky valve.

A full diagnosis (:func:`valve_gym.diagnosis.diagnose`) fits the simulator many
times and costs seconds per loop.  Most loops of a plant do not oscillate; the
screening stage finds the ones that do in milliseconds, with two model-free
tests, and only those go on to the full diagnosis:

* **oscillation index** (Thornhill, Huang & Zhang 2003 [1]_): the zero
  crossings of the autocorrelation function (ACF) of the control error
  ``e = SP - PV`` (the PV when there is no set point), linearly detrended.
  With ``z_k`` the lags of the crossings, the periods ``T_i = z_{i+2} - z_i``
  and their regularity

  .. math:: r = \frac{\bar T}{3\,\sigma_T}

  a loop oscillates when ``r > 1`` (the crossings are regular), the period is
  at least 4 samples, and the ACF at one period is at least 0.3 (the
  oscillation carries a real share of the error's variance).  The amplitude is
  that of the sinusoid with the same autocovariance at one period,
  ``A = sqrt(2 c(T))``; white measurement noise does not enter ``c(T)``.
* **cross-correlation stiction test** (Horch 1999), from
  :func:`valve_gym.diagnosis.horch_ccf`: the phase index ``0..1`` (odd
  cross-correlation of OP and PV, near 1, behind a sticking valve; even, near 0,
  from tuning or a disturbance).

References
----------
.. [1] N. F. Thornhill, B. Huang and H. Zhang, "Detection of multiple
   oscillations in control loops", Journal of Process Control 13(1), 91-100, 2003.
.. [2] A. Horch, "A simple method for detection of stiction in control
   valves", Control Engineering Practice 7(10), 1221-1231, 1999.

Examples
--------
>>> import numpy as np
>>> t = np.arange(2000.0)
>>> e = 0.05 * np.sin(2 * np.pi * t / 100) + 0.01 * np.random.default_rng(0).normal(size=t.size)
>>> osc = oscillation_index(e, dt=1.0)
>>> osc.oscillating, round(osc.period_s), round(osc.amplitude, 2)
(True, 100, 0.05)
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..diagnosis.recording import Recording
from ..signals import acf_zero_crossings, detrend

__all__ = ["Oscillation", "HorchEvidence", "Screen", "oscillation_index", "screen_recording",
           "R_MIN", "ACF_MIN"]

#: Regularity above which the ACF's zero crossings count as a regular oscillation (Thornhill 2003).
R_MIN = 1.0
#: Smallest ACF at one period for an oscillation worth reporting.
ACF_MIN = 0.3
_MAX_CROSSINGS = 12


class Oscillation(NamedTuple):
    """Result of the oscillation index.

    Attributes
    ----------
    oscillating : bool
    regularity : float, ``r`` (NaN when the ACF crosses zero fewer than 5 times)
    period_s : float, mean period [s] (NaN when not found)
    amplitude : float, amplitude of the oscillation of the signal, its units (0 when not oscillating)
    acf_at_period : float, ACF at one period (-1..1; NaN when not found)
    reason : str, one line
    """

    oscillating: bool
    regularity: float
    period_s: float
    amplitude: float
    acf_at_period: float
    reason: str


class HorchEvidence(NamedTuple):
    """Horch's cross-correlation test, typed.

    Attributes
    ----------
    verdict : str, ``'stiction'``, ``'no stiction'``, ``'undetermined'`` or ``'not applicable'``
    phase_index : float, 0..1 (NaN when the test gives none)
    reason : str
    """

    verdict: str
    phase_index: float
    reason: str


class Screen(NamedTuple):
    """The screening of one loop.

    Attributes
    ----------
    oscillation : Oscillation, of the control error (PV units)
    amplitude_op : float, amplitude of the controller output at the same period [fraction of stroke]
    horch : HorchEvidence
    """

    oscillation: Oscillation
    amplitude_op: float
    horch: HorchEvidence


def _autocov(x: np.ndarray) -> np.ndarray:
    """Biased autocovariance of ``x`` (mean removed) at lags 0..n-1."""
    n = len(x)
    x = x - x.mean()
    f = np.fft.rfft(x, 2 * n)
    return np.fft.irfft(f * np.conj(f), 2 * n)[:n] / n


def oscillation_index(e, dt: float = 1.0) -> Oscillation:
    """Thornhill's regularity of the ACF zero crossings of one signal.

    Parameters
    ----------
    e : (T,) array, the control error (or PV), any units, T >= 20
    dt : float, sample time [s]

    Returns
    -------
    Oscillation
    """
    x = detrend(e)
    nan = float("nan")
    c = _autocov(x)
    if len(x) < 20 or c[0] <= 0:
        return Oscillation(False, nan, nan, 0.0, nan, "too short or constant")
    acf = c[: 2 * len(x) // 3] / c[0]
    z = acf_zero_crossings(acf, _MAX_CROSSINGS)
    if len(z) < 5:
        return Oscillation(False, nan, nan, 0.0, nan, "the ACF crosses zero fewer than 5 times: no regular "
                                                      "oscillation within two thirds of the record")
    periods = z[2:] - z[:-2]
    tm = float(periods.mean())
    sd = float(periods.std())
    r = tm / (3 * sd) if sd > 0 else math.inf
    lag = int(round(tm))
    a_p = float(acf[lag]) if lag < len(acf) else nan
    amp = math.sqrt(2 * max(float(c[lag]), 0.0)) if lag < len(c) else 0.0
    osc = bool(r > R_MIN and tm >= 4 and a_p >= ACF_MIN)
    if osc:
        why = f"regular oscillation: period {tm * dt:.4g} s, r = {r:.2f}, ACF at one period {a_p:.2f}"
    elif r <= R_MIN:
        why = f"irregular ACF zero crossings (r = {r:.2f} <= {R_MIN})"
    elif tm < 4:
        why = "zero crossings every few samples: noise, not an oscillation"
    else:
        why = f"weak: ACF at one period {a_p:.2f} < {ACF_MIN}"
    return Oscillation(osc, float(min(r, 99.0)), tm * dt, amp if osc else 0.0, a_p, why)


def screen_recording(rec: Recording, plant: str = "tank") -> Screen:
    """Screen one loop: oscillation index of the control error, OP amplitude, Horch's test.

    Parameters
    ----------
    rec : Recording
    plant : str, the process model (Horch's test does not apply to an ``'integrating'`` one)

    Returns
    -------
    Screen
    """
    from ..diagnosis.indices import horch_ccf

    dt = float(rec.dt or 1.0)
    e = rec.pv if rec.sp is None else rec.sp - rec.pv
    osc = oscillation_index(e, dt)
    amp_op = 0.0
    if osc.oscillating:
        c = _autocov(detrend(rec.op))
        lag = int(round(osc.period_s / dt))
        amp_op = math.sqrt(2 * max(float(c[lag]), 0.0)) if lag < len(c) else 0.0
    h = horch_ccf(rec.op, rec.pv, dt, plant)
    pi = h.get("phase_index")
    horch = HorchEvidence(str(h.get("verdict")), float("nan") if pi is None else float(pi),
                          str(h.get("reason", "")))
    return Screen(osc, amp_op, horch)
