"""``oscillating_disturbance``: a sinusoidal load that enters the process.

Block: :class:`valve_gym.params.OscillatingDisturbance`,
``q_d(t) = amplitude sin(2 pi t / period + phase)`` added to the inflow.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..params import OscillatingDisturbance
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import num

__all__ = ["SPEC"]

_FLOW = {"first_order": "PV", "integrating": "PV/s", "tank": "PV/s", "cascade": "PV/s"}


def _free(ctx: FitContext) -> list[FreeParam]:
    sc = ctx.scales
    dt, D = sc.dt, sc.duration
    if ctx.period_hint:
        plo, phi = ctx.period_hint / 1.5, ctx.period_hint * 1.5
    else:
        plo, phi = 4 * dt, D / 2
    plo, phi = max(plo, 3 * dt), max(min(phi, D), 3.1 * dt)
    return [FreeParam("dist_amp", 0.0, 1.0, "sq", "-", "amplitude / flow scale"),
            FreeParam("period", plo, phi, "log", "s", "period"),
            FreeParam("phase", 0.0, 2 * np.pi, "lin", "rad", "phase at t = 0")]


def _build(ctx: FitContext, v: dict, dte: float, part: Any) -> OscillatingDisturbance:
    sc = ctx.scales
    flow_scale = part.flow_scale
    if ctx.plant == "first_order":
        amp_scale = np.full_like(flow_scale, 2.0 * sc.y_range)
    elif ctx.plant == "integrating":
        amp_scale = flow_scale * 3.0 * sc.u_std
    else:
        amp_scale = 0.5 * flow_scale
    return OscillatingDisturbance(amplitude=v["dist_amp"] * amp_scale, period=v["period"], phase=v["phase"])


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    d = mp.oscillating_disturbance
    if d is None:
        return {}
    return {"oscillating_disturbance.amplitude": d.amplitude, "oscillating_disturbance.period": d.period,
            "oscillating_disturbance.phase": float(np.mod(d.phase, 2 * np.pi))}


def _units(plant: str) -> dict:
    return {"oscillating_disturbance.amplitude": _FLOW[plant], "oscillating_disturbance.period": "s",
            "oscillating_disturbance.phase": "rad"}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    p = after.physical
    a = p.get("oscillating_disturbance.amplitude", float("nan"))
    per = p.get("oscillating_disturbance.period", float("nan"))
    t = mm.tests
    pr = f"{t.period:.3g} s" if t.period else "n/a"
    return (f"Oscillating disturbance. Evidence: the base residual oscillates (dominant "
            f"period {pr}, Ljung-Box p = {t.ljung_box_p:.2g}) in a way the controller output "
            f"does not explain: a periodic load enters the process. Fitted amplitude "
            f"{num(a)} ({after.units.get('oscillating_disturbance.amplitude', '')}), period "
            f"{num(per, 's')}. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="oscillating_disturbance", title="Oscillating disturbance",
    params=(ParamSpec("amplitude", "m^3/s", 0.0, 1e6, 0.0005, "sq", "amplitude of the load"),
            ParamSpec("period", "s", 1e-6, 1e9, 60.0, "log", "period"),
            ParamSpec("phase", "rad", 0.0, 2 * np.pi, 0.0, "lin", "phase at t = 0")),
    kernel="a sinusoid added to the inflow, every Euler step",
    signature="the base residual oscillates regularly (Ljung-Box rejects whiteness, one dominant period) "
              "in a way the controller output does not explain",
    free=_free, neutral={"dist_amp": 0.0, "period": 0.5, "phase": 0.0}, build=_build, physical=_physical,
    units=_units, explain=_explain))
