"""Plain-language explanations of a diagnosis, tied to the located evidence.

Every sentence names the evidence (which condition or test of the residual
points at the effect, with its numbers), the physics, and the fitted
parameters in the recording's units.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..effects import candidate_effects, effect_spec
from ..effects.text import condition_text, derivative_correlation
from ..effects.text import num as _num
from ..effects.text import pct as _pct
from .causes import CAUSE_WORDS
from .fit import FitResult
from .locate import MismatchReport
from .stiction.hammerstein import SEIZED_TRAVEL

if TYPE_CHECKING:
    from .verdict import FreeRunTest, FrictionVerdict, KStepTest

__all__ = ["explain_effect", "explain_none", "explain_free_run", "explain_friction", "explain_combined",
           "explain_naming_conflict", "derivative_correlation"]


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


def explain_free_run(t: FreeRunTest) -> str:
    """One paragraph on the free-run friction test (:class:`~.verdict.FreeRunTest`)."""
    p = t.parameters
    if t.model == "slip_jump":
        fr = f"slip-jump friction S = {_pct(p['S'])}, J = {_pct(p['J'])} of the stroke"
    else:
        z_max = p.get("z_max")
        fr = (f"dead band 2 e_dead = {_pct(p['dead_band'])} of the stroke, "
              f"friction band z_max = {_num(0.0 if z_max is None else z_max, 's')}")
    if t.significant and t.big and not t.moves:
        return _still_valve(t)
    r = t.rule
    d_ic, band, need, op_range = t.delta_ic, t.band, t.band_needed, t.op_working_range
    alt = f"a frictionless valve ({t.frictionless_model})"
    if t.lag_alt:
        alt += " -- a frictionless valve with a " + " / ".join(e.replace("_", " ") for e in t.lag_alt)
        alt += " explains the delays as well as friction could"
    ev = condition_text(t.reversal)
    if t.present:
        return (f"The valve sticks: the model with friction ({fr}) beats the best frictionless "
                f"alternative, {t.frictionless_model} (criterion {d_ic:+.1f}; RMSE "
                f"{_num(t.frictionless_rmse)} -> {_num(t.friction_rmse)}), and the band, "
                f"{_pct(band)} of the stroke, reaches the {_pct(need)} that matters in this "
                f"loop (the smaller of {_pct(r.abs_band)} of the stroke, more dead band than a "
                f"healthy valve is allowed, and {r.rel_band:g} x the controller output's working "
                f"range of {_pct(op_range or 0.0)}; at least {_pct(r.min_band)}, a positioner's "
                f"resolution): the controller keeps pushing a valve that "
                f"does not follow. " + (f"At reversals of the output: {ev}." if ev else ""))
    if t.significant and band < need:
        return (f"No sticking valve that matters: friction improves the fit (criterion "
                f"{d_ic:+.1f} against {t.frictionless_model}) but its band, {_pct(band)} of the stroke, "
                f"is below the {_pct(need)} that matters in this loop (the smaller of "
                f"{_pct(r.abs_band)} of the stroke and {r.rel_band:g} x the controller output's "
                f"working range of {_pct(op_range or 0.0)}; at least {_pct(r.min_band)}): fitted {fr}.")
    return (f"No significant valve friction: {alt} explains the record as well "
            f"(criterion {d_ic:+.1f}); fitted {fr}.")


def _still_valve(t: FreeRunTest) -> str:
    """Why a friction fit that lowers the criterion with a band that matters is no sticking valve."""
    moved = "never moves" if t.slips == 0 else "moves only once"
    return (f"No sticking valve shown: friction lowers the criterion ({t.delta_ic:+.1f}) with a band of "
            f"{100 * t.band:.2g} % of the stroke, but the fitted valve {moved} over the record (the controller "
            f"output's working range is {100 * t.op_working_range:.2g} %): the model explains the process without "
            f"the output's moves, as it does a quiet healthy loop whose output moves answer the measurement noise. "
            f"A sticking valve slips; a seized one would be told only over an output travel of "
            f"{100 * SEIZED_TRAVEL:.0f} % or more.")


def _kstep_decides(t: FreeRunTest, k: KStepTest) -> str:
    """Why the k-step test alone calls the valve sticky."""
    return (f" Yet on {k.horizon}-sample-ahead predictions, where a slow unmeasured load cannot "
            f"accumulate, friction pays (criterion change {k.delta_ic:.1f}) with a band of "
            f"{100 * max(t.band, k.band):.2g} % of the stroke (free-run fit "
            f"{100 * t.band:.2g} %, k-step fit {100 * k.band:.2g} %): the free run, which "
            f"must reproduce every slow load and drift from the controller output alone, missed it, and the "
            f"verdict is that the valve sticks.")


def _frozen_position(code: str, t: FreeRunTest) -> str:
    """What a recorded position that never moved says (:func:`~.verdict.frozen_position`)."""
    travel, band = 100 * float(t.op_working_range), 100 * float(t.band)
    if code == "seized":
        return (f"it stays put while the output travels {travel:.2g} %, and the process model needs a "
                f"friction band of {band:.2g} % of the stroke to explain a process that does not follow "
                f"the output: the valve is seized; free it or replace it.")
    if code == "short_travel":
        return (f"it stays put while the output travels only {travel:.2g} % of the stroke: too little to "
                f"tell a seized valve from a frozen position signal; the verdict rests on the other methods.")
    return (f"it stays put while the output travels {travel:.2g} %, yet the process follows the output "
            f"(the process model needs a friction band of only {band:.2g} %): the position signal is "
            f"frozen, not the valve; check the position transmitter. The verdict rests on the other methods.")


#: Why there is no friction verdict (a pump has no valve).
UNTESTED = "the actuator is a pump: there is no valve to stick"


def explain_friction(v: FrictionVerdict) -> str:
    """The friction verdict (:class:`~.verdict.FrictionVerdict`) in words: one paragraph.

    The free-run friction test (:func:`explain_free_run`), the k-step test where it alone calls the
    valve sticky, the methods combined (:func:`explain_combined`), what the recorded valve position
    says and, where a cause of the oscillation overrules the verdict, that cause.  Where no valve was
    tested, why not.
    """
    t = v.free_run
    if not v.tested or t is None:
        return UNTESTED
    txt = explain_free_run(t)
    if v.kstep_decides and v.kstep is not None:
        txt += _kstep_decides(t, v.kstep)
    if v.combined is None:
        return txt
    txt = (txt + " " + explain_combined(v.combined)).strip()
    stem = v.evidence_of("stem")
    if stem is not None and v.frozen is not None:
        txt += f" Recorded valve position: {_frozen_position(v.frozen, t)}"
    elif stem is not None:
        txt += (f" Recorded valve position: {stem.reason}" + (
            "; the verdict reads the stem." if stem.applicable else "; the verdict rests on the other methods."))
    c = v.overruled_by
    if c is not None:
        txt = (txt + " " + (
            f"The oscillation is better explained as {CAUSE_WORDS[c.cause]} (p = {c.probabilities[c.cause]:.2f}, "
            f"stiction {c.p_stiction:.2f}): the verdict is no stiction.")).strip()
    return txt


def explain_naming_conflict(v: FrictionVerdict) -> str:
    """The caution added to the slip-jump paragraph where the effect is named but the verdict is no ('' otherwise).

    The two answer different questions: naming asks whether a slip-jump term improves the fit
    enough (criterion and held-out test); the verdict whether the valve sticks, from every method
    combined, and it is the one validated on labelled plant loops.  A record without a limit cycle
    or stick episodes can pay for the term and still give those methods nothing to confirm it.
    """
    if not v.tested or v.naming_agrees is not False:
        return ""
    p = v.probability
    pr = f" (probability of stiction {p:.2f})" if np.isfinite(p) else ""
    if v.verdict_source == "stem":
        return (" Caution: the recorded valve position follows the output (the stem test finds no "
                "stiction that matters): the slip-jump term is a model correction, not a finding "
                "against the valve.")
    return (f" Caution: the stiction verdict is no{pr}. The slip-jump term pays in the fit, but "
            f"the methods that judge whether the valve sticks (the limit cycle's shape, stick "
            f"episodes, friction against frictionless models on the whole record) do not "
            f"confirm it: treat it as a model correction, not as a finding against the valve, "
            f"until a valve test (a slow output ramp or small steps with the loop in manual) "
            f"shows the stem sticking.")


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
