r"""Fast screening of a loop: whether it oscillates, and whether the oscillation looks like a sticky valve.

A full diagnosis (:func:`valve_gym.diagnosis.diagnose`) fits the simulator many
times and costs seconds per loop.  Most loops of a plant do not oscillate; the
screening stage finds the ones that do in milliseconds, with two model-free
tests, and only those go on to the full diagnosis:

* **oscillation** of the control error ``e = SP - PV`` (the PV when there is no
  set point): the ``"screen"`` rule of the one oscillation detector,
  :func:`valve_gym.oscillation.detect_oscillation` (Thornhill, Huang & Zhang 2003
  [1]_): the ACF's zero crossings are regular (``r > 1``), the period is at least
  4 samples and the ACF at one period is at least 0.3 (the oscillation carries a
  real share of the error's variance).  The amplitude is that of the sinusoid
  with the same autocovariance at one period, ``A = sqrt(2 c(T))``; white
  measurement noise does not enter ``c(T)``.
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
>>> from valve_gym.oscillation import detect_oscillation
>>> osc = detect_oscillation(e, dt=1.0, rule="screen")
>>> osc.present, round(osc.period_s), round(osc.amplitude, 2)
(True, 100, 0.05)
"""
from __future__ import annotations

import math
from typing import NamedTuple

from ..diagnosis.recording import Recording
from ..oscillation import Oscillation, detect_oscillation
from ..signals import acf, detrend

__all__ = ["HorchEvidence", "Screen", "screen_recording"]


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
    oscillation : valve_gym.oscillation.Oscillation, of the control error (PV units), ``"screen"`` rule
    amplitude_op : float, amplitude of the controller output at the same period [fraction of stroke]
    horch : HorchEvidence
    """

    oscillation: Oscillation
    amplitude_op: float
    horch: HorchEvidence


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
    osc = detect_oscillation(e, dt, "screen")
    amp_op = 0.0
    lag = int(round(osc.period_s / dt)) if osc.present else len(rec.op)
    if lag < len(rec.op):
        c = acf(detrend(rec.op), lag, normalise=False)
        amp_op = math.sqrt(2 * max(float(c[lag]), 0.0))
    h = horch_ccf(rec.op, rec.pv, dt, plant)
    pi = h.get("phase_index")
    horch = HorchEvidence(str(h.get("verdict")), float("nan") if pi is None else float(pi),
                          str(h.get("reason", "")))
    return Screen(osc, amp_op, horch)
