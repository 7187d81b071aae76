"""``sensor_curve``: the level transmitter reads the level through a power curve.

A measurement effect (no block of the core): the simulated level ``L`` of the
measured vessel, counted from the zero of the measurement map (``L = PV - c``
of the model without the effect), is read as

    PV = c + X (L / X)**gamma,

``X`` the PV range of the recording (the curve's scale; the level's own scale
is free, so ``X`` only fixes the units of ``L``). ``gamma = 1`` is the linear
transmitter of the base model. An uncalibrated capacitive level sensor
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


def _free(ctx: FitContext) -> list[FreeParam]:
    return [FreeParam("gamma", _LO, _HI, "log", "-", "exponent of the reading, PV - c ~ level**gamma")]


def _scale(ctx: Any) -> float:
    return float(max(ctx.scales.y_range, 1e-9))


def _measure(ctx: Any, v: dict, t: np.ndarray, Y: np.ndarray) -> np.ndarray:
    c = v["c"][None, :]
    X = _scale(ctx)
    L = np.maximum(Y - c, 0.0) / X
    return c + X * L ** v["gamma"][None, :]


def _physical(ctx: Any, v: dict, mp: Any, sign, offset) -> dict:
    g = float(np.asarray(v["gamma"]).reshape(-1)[0])
    return {"sensor_curve.gamma": g, "sensor_curve.scale": _scale(ctx)}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    g = after.physical.get("sensor_curve.gamma", float("nan"))
    X = after.physical.get("sensor_curve.scale", float("nan"))
    shape = "steeper" if g > 1 else "flatter"
    return (f"Sensor curve. Evidence: the model with a linear reading misses the level's response by a "
            f"different factor at low and at high PV. The reading fits as PV = c + X (L/X)^gamma with "
            f"gamma = {num(g)} (X = {num(X, pv_unit)}): the PV rises {shape} than the stored level, "
            f"an uncalibrated transmitter, or equally a vessel whose cross-section changes with the "
            f"height. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="sensor_curve", title="Sensor curve",
    params=(ParamSpec("gamma", "-", _LO, _HI, 1.0, "log", "exponent of the reading, PV - c ~ level**gamma"),
            ParamSpec("scale", "PV", 1e-9, 1e9, 1.0, "lin", "scale X of the curve (the record's PV range)")),
    kernel="none: the simulated level is read through PV = c + X ((PV_lin - c)/X)**gamma after the core "
           "(measurement effect)",
    signature="the residual's sign and size follow the PV level: the model's gain from the stored level "
              "to the reading is too small at one end of the range and too large at the other",
    conditions=("pv_low", "pv_high"),
    citation="M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noel, Cascaded tanks benchmark combining soft and "
             "hard nonlinearities, 2016, DOI 10.4121/12960104 (uncalibrated capacitive level sensor).",
    applies=_applies, free=_free, neutral={"gamma": float(np.log(1.0 / _LO) / np.log(_HI / _LO))},
    measure=_measure, physical=_physical,
    units=lambda plant: {"sensor_curve.gamma": "-", "sensor_curve.scale": "PV"}, explain=_explain))
