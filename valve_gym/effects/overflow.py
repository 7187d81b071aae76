"""``overflow``: the vessel has a top; above it the inflow spills.

Block: :class:`valve_gym.params.Overflow`. For the two-tank ``cascade`` the upper
tank's spill partly falls into the lower tank (Schoukens et al. 2016), and the
lower tank has its own top.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..params import Overflow
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import cond, num, pct, plateau_evidence

__all__ = ["SPEC"]


def _free(ctx: FitContext) -> list[FreeParam]:
    if ctx.plant == "cascade":
        return [FreeParam("L_max", 0.3, 6.0, "log", "-", "upper-tank top / upper level at the mean input"),
                FreeParam("spill", 0.0, 1.0, "lin", "-",
                          "fraction of the upper tank's spill that falls into the lower tank"),
                FreeParam("L2_frac", 0.0, 1.0, "lin", "-",
                          "lower-tank top between median and max PV (+30 % of range)")]
    return [FreeParam("L_frac", 0.0, 1.0, "lin", "-", "top between median and max PV (+30 % of range)")]


def _build(ctx: FitContext, v: dict, dte: float, part: Any) -> Overflow:
    """The block, its limits placed within the range of the recorded PV."""
    sc = ctx.scales
    sign, offset = part.sign, part.offset
    if ctx.plant == "cascade":
        X1 = max(sc.y_mean, 1e-9)
        lo2 = sc.y_q50 - offset
        hi2 = sc.y_max + 0.3 * sc.y_range - offset
        L2 = np.maximum(lo2 + v["L2_frac"] * (hi2 - lo2), 1e-9)
        return Overflow(L_max=v["L_max"] * X1, L2_max=L2, spill_to_lower=v["spill"])
    # top in model units (level = sign * (PV - offset))
    ym = sign * (np.array([sc.y_q50, sc.y_max, sc.y_min])[:, None] - offset)
    lo = ym[0]
    hi = np.maximum(ym[1], ym[2]) + 0.3 * sc.y_range
    return Overflow(L_max=np.maximum(lo + v["L_frac"] * (hi - lo), 1e-9))


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    o = mp.overflow
    if o is None:
        return {}
    out = {"overflow.L_max": o.L_max}
    if ctx.plant == "cascade":
        out.update({"overflow.L2_max": o.L2_max, "overflow.spill_to_lower": o.spill_to_lower,
                    "overflow.L2_max_pv": o.L2_max + offset[0]})
    else:
        out["overflow.L_max_pv"] = sign[0] * o.L_max + offset[0]
    return out


def _units(plant: str) -> dict:
    return {"overflow.L_max": "upper-tank level units (scaled to PV)" if plant == "cascade" else "PV",
            "overflow.L2_max": "PV", "overflow.spill_to_lower": "-",
            "overflow.L_max_pv": "PV (limit as read on the PV)",
            "overflow.L2_max_pv": "PV (limit as read on the PV)"}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    p = after.physical
    ev = cond(mm, "pv_high")
    if after.structure.plant == "cascade":
        L1 = p.get("overflow.L_max", float("nan"))
        L2 = p.get("overflow.L2_max_pv", float("nan"))
        sp = p.get("overflow.spill_to_lower", float("nan"))
        ev2 = cond(mm, "pv_at_upper_range")
        return (f"Overflow. Evidence: {plateau_evidence(before, mm)}; {ev}"
                + (f"; {ev2}" if ev2 else "") +
                f". The mismatch sits at the high-level episodes: the upper tank spills, so "
                f"the lower tank gets less water than the model predicts and its level falls "
                f"back sooner. Fitted upper-tank top at {num(L1)} (upper-level units, the "
                f"mean-input level is {num(after.structure.scales.y_mean)}), "
                f"{pct(sp)} of the spill reaches the lower tank, lower-tank top at "
                f"{num(L2, pv_unit)}. {imp}.{where}")
    L = p.get("overflow.L_max_pv", float("nan"))
    return (f"Overflow. Evidence: {plateau_evidence(before, mm)}; {ev}. The vessel "
            f"overflows at L_max = {num(L, pv_unit)}. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="overflow", title="Overflow",
    params=(ParamSpec("L_max", "m", 1e-9, 1e6, 2.0, "lin", "top of the (upper) tank"),
            ParamSpec("L2_max", "m", 1e-9, 1e6, 1e6, "lin", "top of the lower tank (cascade)"),
            ParamSpec("spill_to_lower", "-", 0.0, 1.0, 0.5, "lin",
                      "share of the upper tank's spill that falls into the lower tank (cascade)")),
    kernel="the level is held at its top after each Euler step; the excess spills",
    signature="the measured PV sits flat at its top while the model without it goes higher "
              "(mean residual negative at high PV)",
    conditions=("pv_high", "pv_at_upper_range"),
    citation="M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noel, Cascaded tanks benchmark combining soft and "
             "hard nonlinearities, 2016, DOI 10.4121/12960104.",
    free=_free, neutral={"L_frac": 1.0, "L_max": 1.0, "spill": 0.5, "L2_frac": 1.0}, build=_build,
    physical=_physical, units=_units, explain=_explain))
