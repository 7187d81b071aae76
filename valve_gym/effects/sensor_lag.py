"""``sensor_lag``: a first-order lag of the measurement, ``tau_s dy/dt = L - y``.

Block: :class:`valve_gym.params.SensorLag`.
"""
from __future__ import annotations

from typing import Any

from ..params import SensorLag
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import num, rate_evidence

__all__ = ["SPEC"]


def _free(ctx: FitContext) -> list[FreeParam]:
    return [FreeParam("tau_s", ctx.t_min, 30 * ctx.scales.dt, "log", "s", "sensor time constant")]


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    return {} if mp.sensor_lag is None else {"sensor_lag.tau_s": mp.sensor_lag.tau_s}


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    ts = after.physical.get("sensor_lag.tau_s", float("nan"))
    return (f"Sensor lag. Evidence: {rate_evidence(before)}: the measurement lags behind the "
            f"process, smoothly "
            f"rather than by a fixed delay. A first-order measurement lag tau_s = "
            f"{num(ts, 's')} fits. {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="sensor_lag", title="Sensor lag",
    params=(ParamSpec("tau_s", "s", 1e-6, 1e6, 5.0, "log", "sensor time constant"),),
    kernel="a first-order lag between the level and the measured PV, every Euler step",
    signature="the residual follows the model's own rate of change, smoothly rather than by a fixed delay",
    free=_free, neutral={"tau_s": 0.0}, build=lambda ctx, v, dte, part: SensorLag(tau_s=v["tau_s"]),
    physical=_physical, units=lambda plant: {"sensor_lag.tau_s": "s"}, explain=_explain,
    rivals_friction=True))
