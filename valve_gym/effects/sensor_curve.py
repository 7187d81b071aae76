"""``sensor_curve``: the level transmitter reads the level through a power curve.

A measurement effect (no block of the core): the simulated level ``H`` of the
measured vessel, the head above its outlet that drives Torricelli's outflow
(``H = PV - c`` of the model without the effect), is read as

    PV = c + X (max(H - z, 0) / X)**gamma,

``X`` the PV range of the recording (the curve's scale; the level's own scale
is free, so ``X`` only fixes the units of ``H``) and ``z >= 0`` the zero of the
transmitter's curve above the outlet (PV units): the head that drives the
outflow is counted from the outlet's exit, the reading from the transmitter's
own zero, and nothing makes the two the same point (an outlet pipe below the
vessel's floor, a probe that ends above it). ``gamma = 1`` and ``z = 0`` are the
linear transmitter of the base model. With ``gamma = 1`` the zero cannot be told
from the offset ``c`` (both shift the reading); with a curved
reading it sets where on the level the curve bends. An uncalibrated capacitive level sensor
(the cascaded-tanks benchmark of Schoukens et al. 2016 reads the lower tank's
level with one) need not be linear in the level; the same ``gamma`` also
stands for a vessel whose cross-section changes with the height, or an outflow
law steeper or flatter than Torricelli's at the measured vessel: the recorded
PV cannot tell these apart, each bends the map from the stored volume to the
reading.

Only for the ``cascade``: its measurement offset ``c`` is fitted, so the zero
of the level on the PV is known; for the other plants the PV's zero is not a
level and a curved reading is the process gain's nonlinearity.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import num

__all__ = ["SPEC"]

_LO, _HI = 0.4, 4.0


def _applies(plant: str, actuator: str) -> str:
    if plant != "cascade":
        return ("the zero of the level on the PV is fitted only for the cascade (offset c); for "
                "this plant a curved reading cannot be told apart from the process gain")
    return ""


#: Highest zero of the curve above the outlet, as a fraction of the record's PV range.
_ZERO_HI = 0.8


def _free(ctx: FitContext) -> list[FreeParam]:
    return [FreeParam("gamma", _LO, _HI, "log", "-", "exponent of the reading, PV - c ~ level**gamma"),
            FreeParam("curve_zero", 0.0, _ZERO_HI * _scale(ctx), "lin", "PV",
                      "zero of the transmitter's curve above the outlet (the outflow's head at PV = c)")]


def _scale(ctx: Any) -> float:
    return float(max(ctx.scales.y_range, 1e-9))


def _measure(ctx: Any, v: dict, t: np.ndarray, Y: np.ndarray) -> np.ndarray:
    c = v["c"][None, :]
    X = _scale(ctx)
    L = np.maximum(Y - c, 0.0) / X          # Y - c = H - z: the plant's map offset is c - z
    return c + X * L ** v["gamma"][None, :]


def _physical(ctx: Any, v: dict, mp: Any, sign, offset) -> dict:
    g = float(np.asarray(v["gamma"]).reshape(-1)[0])
    z = float(np.asarray(v["curve_zero"]).reshape(-1)[0])
    return {"sensor_curve.gamma": g, "sensor_curve.scale": _scale(ctx), "sensor_curve.zero": z}


#: Extra starts of a candidate fit: the curve's zero at these fractions of its range (the zero at the
#: outlet, the first start, is the neutral reading).
_ZERO_STARTS = (0.35, 0.7)


def _seed(prev: dict, structure: Any, seeds: np.ndarray) -> np.ndarray:
    """Also start the fit with the curve's zero well above the outlet.

    From the neutral start alone the search can settle on a zero near the outlet, a local optimum
    of a curve that bends too late.
    """
    i = structure.index("curve_zero")
    extra = np.repeat(seeds[:1], len(_ZERO_STARTS), axis=0)
    extra[:, i] = _ZERO_STARTS
    return np.vstack([seeds, extra])


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    g = after.physical.get("sensor_curve.gamma", float("nan"))
    X = after.physical.get("sensor_curve.scale", float("nan"))
    z = after.physical.get("sensor_curve.zero", 0.0)
    shape = "steeper" if g > 1 else "flatter"
    zero = (f"; the curve starts {num(z, pv_unit)} above the outlet, so the outflow's head at the lowest "
            f"reading is not zero" if z > 1e-3 * X else "")
    return (f"Sensor curve. Evidence: the model with a linear reading misses the level's response by a "
            f"different factor at low and at high PV. The reading fits as PV = c + X ((H - z)/X)^gamma with "
            f"gamma = {num(g)} (X = {num(X, pv_unit)}, z = {num(z, pv_unit)}, H the head above the outlet): "
            f"the PV rises {shape} than the stored level{zero}; an uncalibrated transmitter, or equally a "
            f"vessel whose cross-section changes with the height. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="sensor_curve", title="Sensor curve",
    params=(ParamSpec("gamma", "-", _LO, _HI, 1.0, "log", "exponent of the reading, PV - c ~ level**gamma"),
            ParamSpec("scale", "PV", 1e-9, 1e9, 1.0, "lin", "scale X of the curve (the record's PV range)"),
            ParamSpec("zero", "PV", 0.0, 1e9, 0.0, "lin",
                      "zero z of the transmitter's curve above the outlet (the outflow's head at PV = c)")),
    kernel="none: the core's head H is read through PV = c + X (max(H - z, 0)/X)**gamma after the core "
           "(measurement effect; the plant's linear map is PV_lin = H + c - z)",
    signature="the residual's sign and size follow the PV level: the model's gain from the stored level "
              "to the reading is too small at one end of the range and too large at the other",
    conditions=("pv_low", "pv_high"),
    citation="M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noel, Cascaded tanks benchmark combining soft and "
             "hard nonlinearities, 2016, DOI 10.4121/12960104 (uncalibrated capacitive level sensor).",
    applies=_applies, free=_free, neutral={"gamma": float(np.log(1.0 / _LO) / np.log(_HI / _LO)), "curve_zero": 0.0},
    measure=_measure, physical=_physical, seed=_seed, map_offset=lambda ctx, v: v["curve_zero"],
    units=lambda plant: {"sensor_curve.gamma": "-", "sensor_curve.scale": "PV", "sensor_curve.zero": "PV"},
    explain=_explain))
