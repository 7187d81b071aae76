"""Load-robust model-based evidence: the friction test on k-step-ahead predictions.

The free-run friction test (:mod:`.hammerstein`) asks a model driven by the
controller output alone to reproduce the whole record, slow unmeasured loads
included.  Under a drifting load that error can outweigh what friction explains:
on the compensator benchmark's regulation loops (an Ornstein-Uhlenbeck load
inflow) a valve with a 9 % stick band gave the same free-run error with and
without friction.  Here the same models (frictionless valve, with a dead time
where that is an alternative, and the paper's friction) are fitted to the
``N``-step-ahead prediction instead: every ``N`` samples the measured level
restarts from the recorded PV (:meth:`valve_gym.diagnosis.model.ModelStructure.simulate`,
``reset``), while the valve runs on from the controller output.  The load then
matters only within a block of ``N`` samples, and what the valve's stick-slip
does to the level after each controller move stays in the error.

Notes
-----
``value = asinh(-delta_ic / 2)`` with ``delta_ic`` the change of the information
criterion (BIC over the effective number of independent residual samples) from
the best frictionless k-step fit to the friction fit; ``delta_ic < -2`` (value
above 0.88) is the usual threshold of a friction that pays.

References
----------
.. [1] L. Ljung, System Identification: Theory for the User, 2nd ed., Prentice
   Hall, 1999, ch. 7 (prediction-error methods, k-step-ahead predictors).
.. [2] M. Jelali, "Estimation of valve stiction in control loops using
   separable least-squares and global search algorithms", Journal of Process
   Control 18 (2008) 632-642.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ._base import Evidence, not_applicable

__all__ = ["kstep_evidence"]

CITE = "Ljung 1999, System Identification, ch. 7 (k-step prediction error); Jelali 2008"
DOC = ("asinh(-delta IC / 2) of the paper's friction against the best frictionless model, both fitted to "
       "the k-step-ahead prediction (> 0.9: friction pays, delta IC < -2)")


def kstep_evidence(verdict: Mapping) -> Evidence:
    """Evidence from the k-step friction test of :func:`valve_gym.diagnosis.diagnose`.

    Parameters
    ----------
    verdict : mapping, the friction verdict; reads ``kstep_delta_ic`` and ``kstep_horizon``
        (samples), absent when the test was not run (a pump, a measurement effect in the model)

    Returns
    -------
    Evidence, ``value = asinh(-delta_ic / 2)``; ``details``: ``delta_ic``, ``horizon_samples``

    Examples
    --------
    >>> e = kstep_evidence({"kstep_delta_ic": -16.5, "kstep_horizon": 60})
    >>> e.verdict, round(e.value, 2)
    ('stiction', 2.81)
    >>> kstep_evidence({}).applicable
    False
    """
    d_ic = verdict.get("kstep_delta_ic")
    if d_ic is None or not np.isfinite(float(d_ic)):
        return not_applicable("kstep", CITE, "no k-step friction test on this record", DOC)
    d_ic = float(d_ic)
    v = float(np.arcsinh(-d_ic / 2.0))
    horizon = float(verdict.get("kstep_horizon", float("nan")))
    return Evidence("kstep", CITE, True, v, 1.0, "stiction" if d_ic < -2.0 else "no stiction",
                    f"on {horizon:g}-sample-ahead predictions friction changes the information criterion "
                    f"by {d_ic:.1f}", DOC, {"delta_ic": d_ic, "horizon_samples": horizon})
