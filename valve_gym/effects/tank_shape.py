"""``tank_shape``: the tank's cross-section changes with the level (cone, sphere, trough, ...).

Block: :class:`valve_gym.params.TankShape`, ``A(L) = area max(1 + taper x + curvature x^2, 0.1)``
with ``x = L / L_ref - 1`` and ``L_ref`` the level at the record's mean PV. The base model's
vertical cylinder is the block at ``taper = curvature = 0``. A level loop on a cone or a sphere
speeds up where the cross-section narrows and slows where it widens; the steady state (inflow =
outflow) does not change, which is what tells the shape apart from a leak.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..core import tank_shape_factor
from ..params import TankShape
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import cond, num

__all__ = ["SPEC"]


def _applies(plant: str, actuator: str) -> str:
    if plant != "tank":
        return ("the tank's shape is fitted for the 'tank' plant only (the level of an integrating or "
                "first-order plant has no known zero, and the cascade's measured tank is the lower one)")
    return ""


def _free(ctx: FitContext) -> list[FreeParam]:
    return [FreeParam("taper", -3.0, 3.0, "lin", "-", "d ln A / d ln L at the mean level (cone: 2)"),
            FreeParam("curvature", -2.0, 2.0, "lin", "-", "second-order term of A(L)/A (sphere half full: -1)")]


def _l_ref(ctx: FitContext, part: Any) -> np.ndarray:
    """The level at the record's mean PV in the core's units (PV minus the measurement offset), per row."""
    return np.maximum(ctx.scales.y_mean - np.asarray(part.offset, float), 1e-9)


def _build(ctx: FitContext, v: dict, dte: float, part: Any) -> TankShape:
    return TankShape(taper=v["taper"], curvature=v["curvature"], L_ref=_l_ref(ctx, part))


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    sh = mp.tank_shape
    if sh is None:
        return {}
    c = float(np.asarray(offset, float).reshape(-1)[0])
    lo, hi = np.broadcast_to(tank_shape_factor(sh, np.array([ctx.scales.y_min - c, ctx.scales.y_max - c])), (2,))
    return {"tank_shape.taper": sh.taper, "tank_shape.curvature": sh.curvature, "tank_shape.L_ref": sh.L_ref,
            "tank_shape.area_at_min_pv": lo, "tank_shape.area_at_max_pv": hi}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    ph = after.physical
    ev = "; ".join(e for e in (cond(mm, "pv_low"), cond(mm, "pv_high")) if e)
    return (f"Tank shape. Evidence: {ev or 'the response is faster at one end of the level range than at the other'}; "
            f"the loop's speed changes with the level, not its steady state. A cross-section that changes with "
            f"the level fits: taper {num(ph.get('tank_shape.taper'))}, curvature "
            f"{num(ph.get('tank_shape.curvature'))} (a cone, apex down, reads 2 and 1; a sphere half full 0 and "
            f"-1); the area at the lowest PV is {num(ph.get('tank_shape.area_at_min_pv'))} and at the highest "
            f"{num(ph.get('tank_shape.area_at_max_pv'))} times that at the mean PV. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="tank_shape", title="Tank shape",
    params=(ParamSpec("taper", "-", -10.0, 10.0, 0.0, "lin", "relative change of the area per relative level"),
            ParamSpec("curvature", "-", -10.0, 10.0, 0.0, "lin", "second-order term of the area"),
            ParamSpec("L_ref", "m", 1e-9, 1e9, 1.0, "log", "level at which the area is process.area")),
    kernel="the level balance divides by the cross-section at the level at the start of each controller sample",
    signature="the model is too slow where the tank narrows and too fast where it widens; the steady "
              "level for a given inflow is right",
    conditions=("pv_low", "pv_high"),
    citation="vessel geometry: A(L) of a cone ~ L^2, of a sphere ~ L (D - L)",
    applies=_applies, free=_free, neutral={"taper": 0.5, "curvature": 0.5}, build=_build,
    physical=_physical,
    units=lambda plant: {"tank_shape.taper": "-", "tank_shape.curvature": "-", "tank_shape.L_ref": "PV",
                         "tank_shape.area_at_min_pv": "-", "tank_shape.area_at_max_pv": "-"},
    explain=_explain))
