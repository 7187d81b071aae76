"""One call for the combined stiction assessment of a record.

:func:`assess_stiction` runs the model-free methods on OP and PV, takes the
model-based evidence of a friction fit when one is given (the diagnosis
passes its friction verdict and slip-jump fit), combines them with the
fitted logistic model of :mod:`.combine` and estimates S and J with the two
size methods (ellipse, fitted slip-jump block), combined by
:func:`combine_size_estimates`.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..fit import FitResult
from ._base import check_signals
from .bicoherence import bicoherence_evidence
from .combine import FEATURES, LogisticModel, StictionAssessment, combine_sizes, features, verdict_of
from .ellipse import ellipse_evidence
from .episodes import episodes_evidence
from .hammerstein import NAN_SIZE, SizeEstimate, hammerstein_evidence, slip_jump_profile
from .horch import horch_evidence
from .kstep import kstep_evidence
from .stem import stem_evidence, stem_size
from .waveform import waveform_evidence

__all__ = ["assess_stiction", "combine_size_estimates", "default_model", "model_free_evidence"]


def default_model() -> LogisticModel:
    """The shipped logistic model (fitted by ``benchmarks/validate_stiction.py --write-model``)."""
    from ._weights import MODEL
    return LogisticModel.from_dict(MODEL)


def model_free_evidence(op, pv, dt: float, plant: str, sp=None) -> list:
    """Evidence of the model-free methods (Horch, bicoherence, ellipse, waveform, stick episodes)."""
    op, pv = check_signals(op, pv, dt)
    return [horch_evidence(op, pv, dt, plant), bicoherence_evidence(op, pv, dt, sp),
            ellipse_evidence(op, pv, dt), waveform_evidence(op, pv, dt, plant),
            episodes_evidence(op, pv, dt, plant, sp)]


def _ellipse_size(ev) -> SizeEstimate:
    e = next((x for x in ev if x.method == "ellipse"), None)
    if e is None or not e.applicable:
        return NAN_SIZE
    d = e.details
    nan = float("nan")
    return SizeEstimate("ellipse", d["S_est"], d["S_est_lo"], d["S_est_hi"], nan, nan, nan)


def _log_half_width(s: SizeEstimate) -> float:
    return float(np.log(max(s.S_hi, 1e-12) / max(s.S_lo, 1e-12))) / 2.0


def combine_size_estimates(sizes) -> tuple[SizeEstimate, bool | None]:
    """One S, J estimate from the size methods, and whether their S intervals overlap.

    With two estimates of S (fitted slip-jump block first, ellipse second), each
    with a calibrated 90 % interval, ``S`` is their precision-weighted mean on the
    log scale (weights ``1 / w^2``, ``w`` half the log-width of each interval) and
    the interval is the union (hull) of the two: it holds the truth at least as
    often as either.  ``sizes_agree`` is True when the intervals overlap (:func:`.combine.combine_sizes`).
    ``J`` and its interval are the slip-jump block's.  One method: its own estimate.
    """
    main, agree = combine_sizes(sizes)
    ok = [s for s in sizes if np.isfinite(s.S)]
    if len(ok) < 2 or any(s.S <= 0 for s in ok):
        return main, agree
    w = np.array([1.0 / max(_log_half_width(s), 1e-6) ** 2 for s in ok])
    s_hat = float(np.exp(np.sum(w * np.log([s.S for s in ok])) / np.sum(w)))
    return main._replace(S=s_hat, S_lo=min(s.S_lo for s in ok), S_hi=max(s.S_hi for s in ok)), agree


def _fitted_band(fit: FitResult | None) -> float:
    """Stick band ``S`` of a fitted slip-jump model (NaN without one)."""
    return float("nan") if fit is None else float(fit.physical.get("slip_jump.S", float("nan")))


def assess_stiction(op, pv, dt: float = 1.0, plant: str = "first_order", *, sp=None,
                    verdict: Mapping | None = None, slip_fit: FitResult | None = None,
                    model: LogisticModel | None = None, map_fn=None, fit_data=None,
                    mv=None) -> StictionAssessment:
    """Combined stiction probability, verdict and size of one record.

    Parameters
    ----------
    op : (T,) controller output, fraction of stroke (0..1)
    pv : (T,) process variable (any units)
    dt : float, sample time [s]
    plant : str, ``'integrating'`` for levels without self-regulation, else self-regulating
    sp : (T,) set point, optional
    verdict : mapping, optional, the model-based friction verdict of
        :func:`valve_gym.diagnosis.diagnose` (``delta_ic``, ``band``, ``band_needed``, ...)
    slip_fit : FitResult, optional, fitted slip-jump model (for S, J with intervals)
    model : LogisticModel, optional (default :func:`default_model`)
    map_fn : map-like callable, optional (e.g. an executor's ``map``): the S profile of
        ``slip_fit`` runs its two sides side by side (same result)
    fit_data : (op, pv), optional, the signals ``slip_fit`` was fitted on when they are not
        ``op``, ``pv`` (the record re-paired for the model, e.g. each OP with the next PV); the
        data-driven methods read ``op``, ``pv`` as logged, the S profile reads ``fit_data``
    mv : (T,) recorded valve position (0..1), optional: the stem test (:mod:`.stem`) reads it
        against ``op``; its evidence is added (not a feature of the logistic model) and, where it
        finds stiction, its S and J are the ones reported (a measured stem is the direct reading)

    Returns
    -------
    StictionAssessment
    """
    op, pv = check_signals(op, pv, dt)
    ev = model_free_evidence(op, pv, dt, plant, sp)
    if slip_fit is None:
        slip = NAN_SIZE
    else:
        fop, fpv = (op, pv) if fit_data is None else check_signals(fit_data[0], fit_data[1], dt)
        slip = slip_jump_profile(slip_fit, fop, fpv, map_fn=map_fn)
    if verdict is not None:
        # the band feature reads the slip-jump fit's own S (what the combination was fitted and
        # validated on), not the profile's re-optimised estimate
        ev.append(hammerstein_evidence(verdict, _fitted_band(slip_fit)))
        ev.append(kstep_evidence(verdict))
    stem = None
    if mv is not None:
        need = float(verdict["band_needed"]) if verdict is not None and "band_needed" in verdict else 0.01
        stem = stem_evidence(op, mv, dt, band_needed=need)
        ev.append(stem)
    model = model or default_model()
    x = features(ev, plant)
    p = float(model.probability(x)[0])
    z = x / np.asarray(model.scale) * np.asarray(model.coef)     # pull away from a silent method (0)
    sizes = [s for s in (slip, _ellipse_size(ev)) if np.isfinite(s.S)]
    size, agree = combine_size_estimates(sizes)
    if stem is not None and stem.verdict == "stiction":
        # the measured stem comes first: its own S and J are reported, the other methods check it
        sizes = [stem_size(stem)] + sizes
        size, agree = combine_sizes(sizes)
    return StictionAssessment(p, verdict_of(p), size.S, size.J, (size.S_lo, size.S_hi),
                              (size.J_lo, size.J_hi), agree, sizes, ev,
                              dict(zip(FEATURES, map(float, x))),
                              dict(zip(FEATURES, map(float, z))))
