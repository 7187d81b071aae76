"""A toy effect in one file: a level transmitter whose reading drifts linearly in time.

``PV_measured(t) = PV(t) + rate * t``. The effect acts on the measurement only, so
it needs no change to the physics core: this file is the whole effect. Importing
it registers ``sensor_drift``; from then on ``diagnose(...)`` tries it with the
other candidates, fits ``rate`` and explains it in the report.
"""
from __future__ import annotations

from valve_gym.effects.spec import EffectSpec, register_effect
from valve_gym.effects.text import num
from valve_gym.paramspec import FreeParam, ParamSpec


def free(ctx):
    """One free coordinate: the drift rate, at most one PV range over the record either way."""
    sc = ctx.scales
    r = sc.y_range / sc.duration
    return [FreeParam("drift_rate", -r, r, "lin", "PV/s", "transmitter drift rate")]


def measure(ctx, v, t, Y):
    """The drifting reading: ``Y`` (T, n) simulated PV, ``t`` (T,) seconds, ``v['drift_rate']`` (n,)."""
    return Y + t[:, None] * v["drift_rate"][None, :]


def explain(before, after, mm, pv_unit, imp, where):
    """The report paragraph: fitted drift per hour, and what it does over the record."""
    rate = after.physical.get("sensor_drift.rate", float("nan"))
    total = rate * after.structure.scales.duration
    return (f"Sensor drift. Evidence: the residual grows steadily with time, independent of the "
            f"operating point. The transmitter drifts by {num(rate * 3600, pv_unit + '/h')} "
            f"({num(total, pv_unit)} over the record). {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="sensor_drift", title="Sensor drift",
    params=(ParamSpec("rate", "PV/s", -1e3, 1e3, 0.0, "lin", "drift of the reading per second"),),
    kernel="none: added to the simulated PV after the core (measurement effect)",
    signature="a residual that grows linearly with time, at every operating point",
    free=free, neutral={"drift_rate": 0.5}, measure=measure,
    physical=lambda ctx, v, mp, sign, offset: {"sensor_drift.rate": float(v["drift_rate"][0])},
    units=lambda plant: {"sensor_drift.rate": "PV/s"}, explain=explain))
