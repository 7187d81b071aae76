"""``dead_time``: a transport delay between the valve and the process.

Block: :class:`valve_gym.params.DeadTime`, ``q_in(t) = q_max f(h(t - theta))``.
"""
from __future__ import annotations

from typing import Any

from ..params import DeadTime
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import num, rate_evidence

__all__ = ["SPEC"]


def _free(ctx: FitContext) -> list[FreeParam]:
    sc = ctx.scales
    return [FreeParam("theta", 0.0, float(min(30 * sc.dt, sc.duration / 5)), "lin", "s", "dead time")]


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    return {} if mp.dead_time is None else {"dead_time.theta": mp.dead_time.theta}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    dt = after.structure.scales.dt
    th = after.physical.get("dead_time.theta", float("nan"))
    t = mm.tests
    return (f"Dead time. Evidence: {rate_evidence(before, ': the model responds too early')} "
            f"and correlates with the "
            f"controller output up to lag {t.ccf_peak_lag} (peak {t.ccf_peak:+.2f}, 95 % band "
            f"+-{t.ccf_bound:.2f}). A transport delay theta = {num(th, 's')} "
            f"({th / dt:.1f} samples) between the valve and the process fits. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="dead_time", title="Dead time",
    params=(ParamSpec("theta", "s", 0.0, 1e6, 2.0, "lin", "transport delay"),),
    kernel="a ring buffer delays the flow fraction by theta (rounded to the Euler step)",
    signature="the residual follows minus the model's own rate of change (the model responds too early) "
              "and correlates with past controller outputs",
    citation="D.E. Seborg, T.F. Edgar, D.A. Mellichamp, Process dynamics and control, Wiley, ch. 6.",
    free=_free, neutral={"theta": 0.0}, build=lambda ctx, v, dte, part: DeadTime(theta=v["theta"]),
    physical=_physical, units=lambda plant: {"dead_time.theta": "s"}, explain=_explain,
    rivals_friction=True))
