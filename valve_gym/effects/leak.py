"""``leak``: a constant extra outflow (offtake) that does not depend on the level.

Block: :class:`valve_gym.params.Leak`, ``A dL/dt = q_in - q_out - q_leak``.
"""
from __future__ import annotations

from typing import Any

from ..params import Leak
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, register_effect
from .text import num

__all__ = ["SPEC"]

_FLOW = {"first_order": "PV", "integrating": "PV/s", "tank": "PV/s", "cascade": "PV/s"}


def _applies(plant: str, actuator: str) -> str:
    if plant == "integrating":
        return ("a constant leak cannot be told apart from the integrating plant's "
                "constant outflow q_out (same equation); it is already in the base model")
    if plant == "first_order":
        return ("a constant leak cannot be told apart from the first-order plant's bias b "
                "(same equation); it is already in the base model")
    return ""


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    q = after.physical.get("leak.q_leak", float("nan"))
    lo, hi = mm.condition("pv_low"), mm.condition("pv_high")
    ev = ""
    if lo is not None and hi is not None:
        ev = (f"mean residual {num(lo.mean_in)} at low PV and {num(hi.mean_in)} at high PV: "
              f"the base model's outflow has the wrong dependence on the level")
    return (f"Leak. Evidence: {ev or 'level-dependent residual'}; part of the outflow does not "
            f"depend on the level. A constant extra outflow q_leak = {num(q)} "
            f"({after.units.get('leak.q_leak', '')}) fits. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="leak", title="Leak",
    params=(ParamSpec("q_leak", "m^3/s", 0.0, 1e6, 0.0005, "sq", "constant extra outflow"),),
    kernel="a constant outflow subtracted in the level balance, every Euler step",
    signature="the mean residual changes sign between low and high PV: the outflow's dependence on the "
              "level is wrong",
    conditions=("pv_low", "pv_high"),
    applies=_applies,
    free=lambda ctx: [FreeParam("leak_frac", 0.0, 0.8, "sq", "-", "leak / mean inflow")],
    neutral={"leak_frac": 0.0},
    build=lambda ctx, v, dte, part: Leak(q_leak=v["leak_frac"] * part.flow_scale),
    physical=lambda ctx, v, mp, sign, offset: {} if mp.leak is None else {"leak.q_leak": mp.leak.q_leak},
    units=lambda plant: {"leak.q_leak": _FLOW[plant]}, explain=_explain))
