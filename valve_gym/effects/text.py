"""Sentence pieces shared by the effects' report paragraphs and :mod:`valve_gym.diagnosis.explain`.

They read fit results and mismatch reports by attribute only (``y``, ``y_sim``,
``residual``, ``structure``; ``condition(name)``, ``tests``), so the effect
modules need not import the diagnosis pipeline.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["pct", "num", "derivative_correlation", "cond", "condition_text", "plateau_evidence", "rate_evidence"]


def pct(x):
    """``x`` (a fraction) as a percentage with two significant digits (whole numbers from 100 % up).

    >>> pct(0.0123), pct(1.0), pct(2.5)
    ('1.2 %', '100 %', '250 %')
    """
    v = 100 * x
    return f"{v:.0f} %" if abs(v) >= 99.5 else f"{v:.2g} %"     # .2g would write 100 as 1e+02


def num(x, unit=""):
    """``x`` with three significant digits and its unit; ``n/a`` when missing or not finite."""
    if x is None or not np.isfinite(x):
        return "n/a"
    a = abs(x)
    s = f"{x:.3g}" if (a >= 1e-3 and a < 1e5) or a == 0 else f"{x:.3e}"
    return f"{s} {unit}".strip()


def derivative_correlation(residual, y_sim) -> float:
    """Correlation of the residual with the simulated PV's rate of change.

    Strongly negative when the model leads the measurement (a delay or lag
    is missing): ``r ~ -tau * dy/dt``.
    """
    d = np.gradient(np.asarray(y_sim, float))
    r = np.asarray(residual, float)
    if np.std(d) == 0 or np.std(r) == 0:
        return 0.0
    return float(np.corrcoef(r, d)[0, 1])


def cond(mm: Any, name: str) -> str:
    """The located condition ``name`` of ``mm`` as evidence: residual RMS inside against outside."""
    return condition_text(mm.condition(name))


def condition_text(c: Any) -> str:
    """A located condition (a ``ConditionStat``, or None) as evidence: residual RMS inside against outside."""
    if c is None:
        return ""
    sig = "significant" if c.significant else "not significant alone"
    return (f"residual RMS {num(c.rms_in)} {c.description} against {num(c.rms_out)} elsewhere "
            f"({c.ratio:.2f} x, z = {c.z:.1f}, {sig})")


def plateau_evidence(before: Any, mm: Any) -> str:
    """Flat top of the measured PV that the model without overflow overshoots."""
    y, ys = before.y, before.y_sim
    sig = max(mm.tests.noise_std, 1e-12)
    top = float(np.max(y))
    flat = y >= top - 2.5 * sig
    sat = before.structure.scales.sat_hi
    s = (f"the measured PV sits flat at its top ({num(top)}) for {int(flat.sum())} samples "
         f"({pct(flat.mean())} of the record)")
    if sat is not None:
        # the model is clipped by the sensor range: it stays pinned where the PV has fallen
        pinned = (ys >= sat - 1e-9 * max(abs(sat), 1.0)) & (y < sat - 2.5 * sig)
        s += (f"; the model without overflow stays pinned at the sensor's {num(sat)} on "
              f"{int(pinned.sum())} samples where the measured level has already fallen")
    else:
        over = ys - top
        s += (f" while the model without overflow goes above that level on "
              f"{int(np.sum(over > 2.5 * sig))} samples, by up to "
              f"{num(max(float(over.max()), 0.0))}")
    hi = mm.condition("pv_high")
    if hi is not None and hi.mean_in < 0:
        s += (f"; in the top 10 % of the PV the model is too high by {num(-hi.mean_in)} on "
              f"average (water it predicts is lost)")
    return s


def rate_evidence(before: Any, note: str = "") -> str:
    """The residual against the model's own rate of change, the sign of a delay or a lag."""
    dc = derivative_correlation(before.residual, before.y_sim)
    weak = "" if np.isfinite(dc) and abs(dc) >= 0.3 else \
        ", weak on its own: the choice rests on the information criterion and the held-out error"
    return f"the residual follows the model's own rate of change (correlation {dc:+.2f}{weak}{note})"


