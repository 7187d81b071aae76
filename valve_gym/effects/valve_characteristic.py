"""``valve_characteristic``: the installed flow characteristic is not linear in the opening.

Two forms are tried as candidates: equal percentage ``f = R**(h - 1)`` (free
rangeability ``R``) and quick opening ``f = sqrt(h)`` (no free parameter; the
choice of form counts as one). Block: :class:`valve_gym.params.ValveCharacteristic`.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..params import ValveCharacteristic
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import num

__all__ = ["SPEC"]

_DEFAULT = "equal_percentage"


def _applies(plant: str, actuator: str) -> str:
    return "" if actuator == "valve" else f"valve_characteristic acts on a valve; the actuator is a {actuator}"


def _free(ctx: FitContext) -> list[FreeParam]:
    if ctx.variants.get("valve_characteristic", _DEFAULT) == "equal_percentage":
        return [FreeParam("R", 1.5, 100.0, "log", "-", "rangeability (equal percentage)")]
    return []


def _build(ctx: FitContext, v: dict, dte: float, part: Any) -> ValveCharacteristic:
    kind = ctx.variants.get("valve_characteristic", _DEFAULT)
    return ValveCharacteristic(kind=kind, R=v["R"] if "R" in v else 30.0, h0=0.0)


def _flow_fraction(ctx: FitContext, v: dict, u: np.ndarray) -> np.ndarray:
    if ctx.variants.get("valve_characteristic", _DEFAULT) == "equal_percentage":
        return v["R"] ** (u - 1.0)
    return np.sqrt(u)


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    vc = mp.valve_characteristic
    return {"valve_characteristic.R": vc.R} if vc is not None and vc.kind == "equal_percentage" else {}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    p = after.physical
    kind = after.structure.variants.get("valve_characteristic", _DEFAULT)
    R = p.get("valve_characteristic.R")
    lo, hi = mm.condition("op_low"), mm.condition("op_high")
    ev = ""
    if lo is not None and hi is not None:
        ev = (f"mean residual {num(lo.mean_in)} with the valve in its lowest third and "
              f"{num(hi.mean_in)} in its highest third: the process gain changes with the "
              f"opening")
    desc = (f"an equal-percentage installed characteristic with rangeability R = {num(R)}"
            if kind == "equal_percentage" else "a quick-opening (square-root) characteristic")
    return (f"Valve characteristic. Evidence: {ev or 'opening-dependent residual'}. The flow is "
            f"not proportional to the opening: {desc} fits. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="valve_characteristic", title="Installed valve characteristic",
    params=(ParamSpec("R", "-", 1.0, 1000.0, 30.0, "log", "rangeability of the equal-percentage form"),
            ParamSpec("h0", "-", 0.0, 0.99, 0.0, "fixed", "opening below which no flow passes")),
    kernel="maps the stem position to the flow fraction before the process, every Euler step",
    signature="the mean residual has opposite signs with the valve nearly closed and nearly open "
              "(the process gain changes with the opening)",
    conditions=("op_low", "op_high"),
    citation="ISA-75.11.01, Flow characteristic and rangeability of control valves.",
    applies=_applies, free=_free, neutral={"R": 0.5}, build=_build, physical=_physical,
    units=lambda plant: {"valve_characteristic.R": "-"}, explain=_explain,
    variants=("equal_percentage", "quick_opening"), variant_k={"quick_opening": 1},
    flow_fraction=_flow_fraction))
