"""Plain-language explanations of a diagnosis, tied to the located evidence.

Every sentence names the evidence (which condition or test of the residual
points at the effect, with its numbers), the physics, and the fitted
parameters in the recording's units.
"""
from __future__ import annotations

import numpy as np

from .fit import FitResult
from .locate import MismatchReport

__all__ = ["explain_effect", "explain_none", "explain_stiction", "derivative_correlation"]


def _pct(x):
    return f"{100 * x:.2g} %"


def _num(x, unit=""):
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


def _cond(mm: MismatchReport, name: str) -> str:
    c = mm.condition(name)
    if c is None:
        return ""
    sig = "significant" if c.significant else "not significant alone"
    return (f"residual RMS {_num(c.rms_in)} {c.description} against {_num(c.rms_out)} elsewhere "
            f"({c.ratio:.2f} x, z = {c.z:.1f}, {sig})")


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


def _plateau_evidence(before: FitResult, mm: MismatchReport) -> str:
    """Flat top of the measured PV that the model without overflow overshoots."""
    y, ys = before.y, before.y_sim
    sig = max(mm.tests.noise_std, 1e-12)
    top = float(np.max(y))
    flat = y >= top - 2.5 * sig
    sat = before.structure.scales.sat_hi
    s = (f"the measured PV sits flat at its top ({_num(top)}) for {int(flat.sum())} samples "
         f"({_pct(flat.mean())} of the record)")
    if sat is not None:
        # the model is clipped by the sensor range: it stays pinned where the PV has fallen
        pinned = (ys >= sat - 1e-9 * max(abs(sat), 1.0)) & (y < sat - 2.5 * sig)
        s += (f"; the model without overflow stays pinned at the sensor's {_num(sat)} on "
              f"{int(pinned.sum())} samples where the measured level has already fallen")
    else:
        over = ys - top
        s += (f" while the model without overflow goes above that level on "
              f"{int(np.sum(over > 2.5 * sig))} samples, by up to "
              f"{_num(max(float(over.max()), 0.0))}")
    hi = mm.condition("pv_high")
    if hi is not None and hi.mean_in < 0:
        s += (f"; in the top 10 % of the PV the model is too high by {_num(-hi.mean_in)} on "
              f"average (water it predicts is lost)")
    return s


def _rate_evidence(before: FitResult, note: str = "") -> str:
    """The residual against the model's own rate of change, the sign of a delay or a lag."""
    dc = derivative_correlation(before.residual, before.y_sim)
    weak = "" if np.isfinite(dc) and abs(dc) >= 0.3 else \
        ", weak on its own: the choice rests on the information criterion and the held-out error"
    return f"the residual follows the model's own rate of change (correlation {dc:+.2f}{weak}{note})"


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
    explain = _EXPLAIN.get(effect)
    if explain is not None:
        return explain(before, after, mm, pv_unit, imp, where)
    return f"{effect}: {imp}."


def _explain_slip_jump(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                       imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``slip_jump``."""
    p = after.physical
    S, J = p.get("slip_jump.S", float("nan")), p.get("slip_jump.J", float("nan"))
    if J > 1.1 * S:
        kind = "J > S: the stem overshoots the controller output after it breaks free"
    elif J < 0.9 * S:
        kind = "J < S: the stem stops short of the controller output (undershoot)"
    else:
        kind = "J ~ S: the stem jumps to the controller output"
    ev = _cond(mm, "near_op_reversal")
    return (f"Slip-jump valve friction. Evidence: {ev or 'the base model misses after reversals'}; "
            f"the stem sticks when the controller output reverses and then jumps, which the "
            f"paper's integral friction model cannot reproduce. Fitted stick band S = "
            f"{_pct(S)} and slip jump J = {_pct(J)} of the stroke ({kind}). {imp}.{where}")


def _explain_overflow(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                      imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``overflow``."""
    p = after.physical
    ev = _cond(mm, "pv_high")
    if after.structure.plant == "cascade":
        L1 = p.get("overflow.L_max", float("nan"))
        L2 = p.get("overflow.L2_max_pv", float("nan"))
        sp = p.get("overflow.spill_to_lower", float("nan"))
        ev2 = _cond(mm, "pv_at_upper_range")
        return (f"Overflow. Evidence: {_plateau_evidence(before, mm)}; {ev}"
                + (f"; {ev2}" if ev2 else "") +
                f". The mismatch sits at the high-level episodes: the upper tank spills, so "
                f"the lower tank gets less water than the model predicts and its level falls "
                f"back sooner. Fitted upper-tank top at {_num(L1)} (upper-level units, the "
                f"mean-input level is {_num(after.structure.scales.y_mean)}), "
                f"{_pct(sp)} of the spill reaches the lower tank, lower-tank top at "
                f"{_num(L2, pv_unit)}. {imp}.{where}")
    L = p.get("overflow.L_max_pv", float("nan"))
    return (f"Overflow. Evidence: {_plateau_evidence(before, mm)}; {ev}. The vessel "
            f"overflows at L_max = {_num(L, pv_unit)}. {imp}.{where}")


def _explain_dead_time(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                       imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``dead_time``."""
    p = after.physical
    dt = after.structure.scales.dt
    th = p.get("dead_time.theta", float("nan"))
    t = mm.tests
    return (f"Dead time. Evidence: {_rate_evidence(before, ': the model responds too early')} "
            f"and correlates with the "
            f"controller output up to lag {t.ccf_peak_lag} (peak {t.ccf_peak:+.2f}, 95 % band "
            f"+-{t.ccf_bound:.2f}). A transport delay theta = {_num(th, 's')} "
            f"({th / dt:.1f} samples) between the valve and the process fits. {imp}.{where}")


def _explain_sensor_lag(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                        imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``sensor_lag``."""
    p = after.physical
    ts = p.get("sensor_lag.tau_s", float("nan"))
    return (f"Sensor lag. Evidence: {_rate_evidence(before)}: the measurement lags behind the "
            f"process, smoothly "
            f"rather than by a fixed delay. A first-order measurement lag tau_s = "
            f"{_num(ts, 's')} fits. {imp}.{where}")


def _explain_oscillating_disturbance(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                                     imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``oscillating_disturbance``."""
    p = after.physical
    a = p.get("oscillating_disturbance.amplitude", float("nan"))
    per = p.get("oscillating_disturbance.period", float("nan"))
    t = mm.tests
    pr = f"{t.period:.3g} s" if t.period else "n/a"
    return (f"Oscillating disturbance. Evidence: the base residual oscillates (dominant "
            f"period {pr}, Ljung-Box p = {t.ljung_box_p:.2g}) in a way the controller output "
            f"does not explain: a periodic load enters the process. Fitted amplitude "
            f"{_num(a)} ({after.units.get('oscillating_disturbance.amplitude', '')}), period "
            f"{_num(per, 's')}. {imp}.{where}")


def _explain_leak(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                  imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``leak``."""
    p = after.physical
    q = p.get("leak.q_leak", float("nan"))
    lo, hi = mm.condition("pv_low"), mm.condition("pv_high")
    ev = ""
    if lo is not None and hi is not None:
        ev = (f"mean residual {_num(lo.mean_in)} at low PV and {_num(hi.mean_in)} at high PV: "
              f"the base model's outflow has the wrong dependence on the level")
    return (f"Leak. Evidence: {ev or 'level-dependent residual'}; part of the outflow does not "
            f"depend on the level. A constant extra outflow q_leak = {_num(q)} "
            f"({after.units.get('leak.q_leak', '')}) fits. {imp}.{where}")


def _explain_valve_characteristic(before: FitResult, after: FitResult, mm: MismatchReport, pv_unit: str,
                                  imp: str, where: str) -> str:
    """Paragraph of :func:`explain_effect` for ``valve_characteristic``."""
    p = after.physical
    kind = after.structure.variants.get("valve_characteristic", "equal_percentage")
    R = p.get("valve_characteristic.R")
    lo, hi = mm.condition("op_low"), mm.condition("op_high")
    ev = ""
    if lo is not None and hi is not None:
        ev = (f"mean residual {_num(lo.mean_in)} with the valve in its lowest third and "
              f"{_num(hi.mean_in)} in its highest third: the process gain changes with the "
              f"opening")
    desc = (f"an equal-percentage installed characteristic with rangeability R = {_num(R)}"
            if kind == "equal_percentage" else "a quick-opening (square-root) characteristic")
    return (f"Valve characteristic. Evidence: {ev or 'opening-dependent residual'}. The flow is "
            f"not proportional to the opening: {desc} fits. {imp}.{where}")


#: Paragraph writer per effect, for :func:`explain_effect`.
_EXPLAIN = {
    "slip_jump": _explain_slip_jump,
    "overflow": _explain_overflow,
    "dead_time": _explain_dead_time,
    "sensor_lag": _explain_sensor_lag,
    "oscillating_disturbance": _explain_oscillating_disturbance,
    "leak": _explain_leak,
    "valve_characteristic": _explain_valve_characteristic,
}


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
    txt = (f"Second opinion, {len(a.evidence)} methods combined: {words[a.verdict]} "
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
