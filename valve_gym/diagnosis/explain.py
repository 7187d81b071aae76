"""Plain-language explanations of a diagnosis, tied to the located evidence.

Every sentence names the evidence (which condition or test of the residual
points at the effect, with its numbers), the physics, and the fitted
parameters in the recording's units.
"""
from __future__ import annotations

import numpy as np

from ..effects import candidate_effects, effect_spec
from ..effects.text import cond as _cond
from ..effects.text import derivative_correlation
from ..effects.text import num as _num
from ..effects.text import pct as _pct
from .fit import FitResult
from .locate import MismatchReport

__all__ = ["explain_effect", "explain_none", "explain_stiction", "derivative_correlation"]


def _improvement(before: FitResult, after: FitResult) -> str:
    s = f"RMSE {_num(before.rmse_all)} -> {_num(after.rmse_all)} PV units"
    if np.isfinite(before.holdout_rmse) and np.isfinite(after.holdout_rmse):
        s += f", on the held-out end {_num(before.holdout_rmse)} -> {_num(after.holdout_rmse)}"
    return s


def _where_gained(before: FitResult, after: FitResult, masks) -> str:
    """The operating condition where the residual fell most (relative), as a clause."""
    if not masks:
        return ""
    rb, ra = before.residual, after.residual
    best = None
    for name, (m, desc) in masks.items():
        if m.sum() < 5:
            continue
        a = float(np.sqrt(np.mean(rb[m] ** 2)))
        b = float(np.sqrt(np.mean(ra[m] ** 2)))
        if a > 0 and (best is None or b / a < best[0]):
            best = (b / a, desc, a, b)
    if best is None:
        return ""
    return (f" The residual fell most {best[1]} (RMS {_num(best[2])} -> {_num(best[3])}).")


def explain_effect(effect: str, before: FitResult, after: FitResult, mm: MismatchReport,
                   pv_unit: str = "PV units", masks=None) -> str:
    """One paragraph on why ``effect`` was added.

    Parameters
    ----------
    effect : str, the effect added
    before : FitResult, the model without it (whole record)
    after : FitResult, the model with it (whole record)
    mm : MismatchReport of ``before``
    pv_unit : str, how to call the PV's unit
    masks : dict, optional, operating-condition masks
        (:func:`~valve_gym.diagnosis.locate.condition_masks`); the condition
        where the residual fell most is named
    """
    imp = _improvement(before, after) + "." + _where_gained(before, after, masks).rstrip(".")
    regions = mm.regions
    where = ""
    if regions:
        top = regions[0]
        where = (f" The largest mismatch region is {top.t_start:g}-{top.t_end:g} s "
                 f"({_pct(top.share_sse)} of the squared error).")
    if effect in candidate_effects():
        return effect_spec(effect).explain(before, after, mm, pv_unit, imp, where)
    return f"{effect}: {imp}."


def explain_none(base: FitResult, mm: MismatchReport, best_candidate: str | None = None) -> str:
    """Why no effect was added."""
    t = mm.tests
    s = (f"No candidate effect pays: the base model ({base.label}) explains the record, "
         f"residual RMS {_num(mm.rms)} against a measurement-noise level of "
         f"{_num(t.noise_std)}")
    if t.white:
        s += f"; the residual is white (Ljung-Box p = {t.ljung_box_p:.2g})."
    else:
        s += (f"; the residual is not white (Ljung-Box p = {t.ljung_box_p:.2g}, "
              f"{_pct(t.acf_outside)} of the autocorrelations outside the 95 % band), but none of "
              f"the candidate effects explains that structure"
              + (f" (the closest was {best_candidate})" if best_candidate else "") + ".")
    return s


def explain_stiction(present: bool, with_fr: FitResult, without: FitResult, d_ic: float,
                     h_change: float, mm: MismatchReport, significant: bool | None = None,
                     band: float | None = None, min_band: float | None = None, lag_alt=(),
                     op_range: float | None = None, abs_band: float = 0.01, rel_band: float = 0.5,
                     floor: float = 0.001) -> str:
    """One paragraph on the friction verdict (``min_band``: the band needed, see ``SelectionRule``)."""
    p = with_fr.physical
    if "slip_jump.S" in p:
        fr = (f"slip-jump friction S = {_pct(p['slip_jump.S'])}, J = {_pct(p['slip_jump.J'])} "
              f"of the stroke")
    else:
        fr = (f"dead band 2 e_dead = {_pct(2 * p.get('valve.e_dead', 0.0))} of the stroke, "
              f"friction band z_max = {_num(p.get('valve.z_max', 0.0), 's')}")
    alt = f"a frictionless valve ({without.label})"
    if lag_alt:
        alt += " -- a frictionless valve with a " + " / ".join(e.replace("_", " ") for e in lag_alt)
        alt += " explains the delays as well as friction could"
    ev = _cond(mm, "near_op_reversal")
    if present:
        return (f"The valve sticks: the model with friction ({fr}) beats the best frictionless "
                f"alternative, {without.label} (criterion {d_ic:+.1f}; RMSE "
                f"{_num(without.rmse_all)} -> {_num(with_fr.rmse_all)}), and the band, "
                f"{_pct(band)} of the stroke, reaches the {_pct(min_band)} that matters in this "
                f"loop (the smaller of {_pct(abs_band)} of the stroke, more dead band than a "
                f"healthy valve is allowed, and {rel_band:g} x the controller output's working "
                f"range of {_pct(op_range or 0.0)}; at least {_pct(floor)}, a positioner's "
                f"resolution): the controller keeps pushing a valve that "
                f"does not follow. " + (f"At reversals of the output: {ev}." if ev else ""))
    if significant and band is not None and min_band is not None and band < min_band:
        return (f"No sticking valve that matters: friction improves the fit (criterion "
                f"{d_ic:+.1f} against {without.label}) but its band, {_pct(band)} of the stroke, "
                f"is below the {_pct(min_band)} that matters in this loop (the smaller of "
                f"{_pct(abs_band)} of the stroke and {rel_band:g} x the controller output's "
                f"working range of {_pct(op_range or 0.0)}; at least {_pct(floor)}): fitted {fr}.")
    return (f"No significant valve friction: {alt} explains the record as well "
            f"(criterion {d_ic:+.1f}); fitted {fr}.")


def explain_combined(a) -> str:
    """One paragraph on the combined stiction verdict of a :class:`~.stiction.StictionAssessment`.

    Names the probability, the two methods with the largest pull on it and the
    stiction size with its 90 % interval (when the verdict is stiction).
    """
    words = {"stiction": "stiction", "no stiction": "no stiction", "undecided": "undecided"}
    n = sum(e.method != "stem" for e in a.evidence)      # the stem test is read apart, not combined
    txt = (f"{n} methods combined: {words[a.verdict]} "
           f"(probability of stiction {a.probability:.2f}")
    pulls = sorted(a.contributions.items(), key=lambda kv: -abs(kv[1]))[:2]
    pulls = [(k, v) for k, v in pulls if abs(v) > 0.1]
    if pulls:
        txt += "; strongest: " + ", ".join(f"{k} {'for' if v > 0 else 'against'}" for k, v in pulls)
    txt += ")."
    if a.verdict == "stiction" and np.isfinite(a.S):
        txt += (f" Fitted stiction band S = {_pct(a.S)} of the stroke "
                f"(90 % interval {_pct(a.S_interval[0])} to {_pct(a.S_interval[1])}")
        if a.sizes_agree is not None:
            txt += "; the size methods " + ("agree" if a.sizes_agree else "disagree")
        txt += ")"
        if np.isfinite(a.J):
            txt += f", slip jump J = {_pct(a.J)} ({_pct(a.J_interval[0])} to {_pct(a.J_interval[1])})"
        txt += "."
    return txt
