"""Stiction detection and quantification from several published methods.

Each method is a small module returning an :class:`Evidence` (its index,
applicability and reliability on the record):

* :mod:`.horch` - cross-correlation test (Horch 1999) / PV-derivative shape for integrating loops;
* :mod:`.bicoherence` - non-Gaussianity and nonlinearity indices (Choudhury, Shah & Thornhill 2004);
* :mod:`.ellipse` - ellipse on the filtered PV-OP plot, apparent stiction (Choudhury et al. 2006);
* :mod:`.waveform` - triangle vs sine curve fitting (He et al. 2007);
* :mod:`.episodes` - stick episodes: the OP ramps, the process does not answer (after Kano et al. 2004);
* :mod:`.hammerstein` - the package's friction block fitted inside the process model, S and J
  with profile intervals;
* :mod:`.kstep` - the same friction test on k-step-ahead predictions (robust to slow unmeasured loads);
* :mod:`.stem` - where the valve position is recorded: stiction laws fitted from the output to it
  (read apart from the combination: it decides the verdict where it applies).

:mod:`.combine` turns them into a calibrated probability (logistic model over
two regimes: regular oscillation or not) and one S, J estimate; :func:`assess_stiction` does it all for one record.
:mod:`.loops` simulates textbook closed loops with Choudhury, Kano or
force-balance friction, independent of :mod:`valve_gym.core`, for validation.
"""
from ._base import Evidence, Oscillation, oscillation
from .assess import assess_stiction, default_model, model_free_evidence
from .combine import FEATURES, LogisticModel, StictionAssessment, fit_logistic
from .hammerstein import SizeEstimate

__all__ = ["Evidence", "Oscillation", "oscillation", "assess_stiction", "default_model",
           "model_free_evidence", "FEATURES", "LogisticModel", "StictionAssessment", "fit_logistic",
           "SizeEstimate"]
