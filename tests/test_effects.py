"""The effect registry: every effect is one spec, and a new one is one file (docs/examples/sensor_drift.py)."""
from __future__ import annotations

import pathlib
from dataclasses import replace

import numpy as np
import pytest

from valve_gym.diagnosis import data_path, diagnose, load_recording
from valve_gym.diagnosis.fit import fit_structure
from valve_gym.diagnosis.model import DataScales, ModelStructure, effect_applicability
from valve_gym.diagnosis.recording import Recording
from valve_gym.diagnosis.synthetic import make_case
from valve_gym.effects import CANDIDATE_EFFECTS, candidate_effects, effect_spec
from valve_gym.effects.spec import EffectSpec, register_effect, unregister_effect
from valve_gym.params import EFFECTS

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_builtin_effects_are_the_core_blocks_in_the_order_tried():
    assert CANDIDATE_EFFECTS == ("slip_jump", "valve_characteristic", "dead_time", "overflow", "leak",
                                 "sensor_lag", "sensor_curve", "oscillating_disturbance", "tank_shape")
    measurement = {"sensor_curve"}                  # acts on the PV after the core, no core block
    assert set(EFFECTS) - set(CANDIDATE_EFFECTS) == {"cascade", "actuator"}   # plant structure, not effects
    assert set(CANDIDATE_EFFECTS) - set(EFFECTS) == measurement
    for e in CANDIDATE_EFFECTS:
        spec = effect_spec(e)
        if e in measurement:
            assert spec.build is None and spec.measure is not None
        else:
            assert spec.build is not None and spec.measure is None
        assert spec.params and spec.kernel and spec.signature
        # each spec's module is one file named after the effect
        assert (ROOT / "valve_gym" / "effects" / f"{e}.py").is_file()


def test_specs_declare_free_parameters_their_blocks_use():
    u = np.linspace(0.3, 0.6, 400)
    y = 1.0 + 0.5 * np.sin(np.linspace(0, 12, 400))
    sc = DataScales.from_signals(u, y, 1.0)
    for e in CANDIDATE_EFFECTS:
        plant = "tank" if effect_spec(e).applicable("tank", "valve")[0] else "cascade"
        ms = ModelStructure(plant, "valve", (e,), sc, n_sub=2)
        free = [p.name for p in effect_spec(e).free(ms)]
        assert set(free) <= set(ms.names)
        for name in free:                           # a neutral start inside the unit interval
            assert 0.0 <= ms.neutral_coord(ms.params[ms.index(name)]) <= 1.0
        W = np.full((2, len(ms.params)), 0.4)
        Y = ms.simulate(W, u)
        assert Y.shape == (400, 2) and np.isfinite(Y).all()
        phys = ms.physical(W[0])
        units = ms.units()
        for key in phys:
            assert key in units, f"{e}: {key} has no unit"


def test_applicability_is_the_effects_own_rule():
    ok, why = effect_applicability("leak", "integrating", "valve")
    assert not ok and "q_out" in why
    ok, why = effect_applicability("slip_jump", "tank", "pump")
    assert not ok and "valve" in why
    assert effect_applicability("dead_time", "first_order", "pump") == (True, "")
    ok, why = effect_applicability("no_such_effect", "tank", "valve")
    assert not ok and "unknown" in why


def test_a_spec_must_say_how_it_enters():
    with pytest.raises(ValueError, match="exactly one of build"):
        EffectSpec(name="x", title="x", params=(), kernel="", signature="", explain=lambda *a: "")
    with pytest.raises(ValueError, match="identifier"):
        EffectSpec(name="a b", title="x", params=(), kernel="", signature="", explain=lambda *a: "",
                   measure=lambda ctx, v, t, Y: Y)
    spec = EffectSpec(name="not_a_block", title="x", params=(), kernel="", signature="",
                      explain=lambda *a: "", build=lambda *a: None)
    with pytest.raises(ValueError, match="no block"):
        register_effect(spec)
    with pytest.raises(ValueError, match="unknown effect"):
        effect_spec("not_registered")


@pytest.fixture
def sensor_drift(repo_module):
    """The one-file toy effect of docs/extending.md, registered for the test only."""
    yield repo_module("docs/examples/sensor_drift.py", "sensor_drift_example")
    unregister_effect("sensor_drift")


@pytest.mark.slow
def test_one_file_effect_is_found_fitted_and_explained(sensor_drift):
    assert "sensor_drift" in candidate_effects() and "sensor_drift" not in CANDIDATE_EFFECTS
    rec = make_case("none", seed=1, n=1200).recording
    t = np.arange(len(rec.pv)) * rec.dt
    rate = 0.15 / t[-1]                                  # 0.15 m over the record
    drifting = replace(rec, pv=rec.pv + rate * t)
    cands = ("sensor_drift", "leak", "overflow")
    res = diagnose(drifting, plant="tank", candidates=cands, effort="fast")
    assert res.effects == ["sensor_drift"]
    assert res.final.physical["sensor_drift.rate"] == pytest.approx(rate, rel=0.1)
    assert any(p.startswith("Sensor drift.") for p in res.explanation)
    assert res.to_dict()["effects"] == ["sensor_drift"]
    clean = diagnose(rec, plant="tank", candidates=cands, effort="fast")
    assert "sensor_drift" not in clean.effects


def _cascade_with_curve():
    """A pump-fed cascade without and with ``sensor_curve``, its input, scales and one base parameter set."""
    u = 0.3 + 0.2 * (np.arange(300) // 50 % 2)
    y = 4.0 + 2.0 * np.sin(np.linspace(0, 6, 300))
    sc = DataScales.from_signals(u, y, 4.0)
    base = ModelStructure("cascade", "pump", (), sc, n_sub=2)
    ms = ModelStructure("cascade", "pump", ("sensor_curve",), sc, n_sub=2)
    return u, sc, base, ms, base.decode(np.full((1, len(base.params)), 0.4))


def test_sensor_curve_reads_the_cascade_level_through_a_power_curve():
    ok, why = effect_applicability("sensor_curve", "tank", "pump")
    assert not ok and "cascade" in why
    u, sc, base, ms, v = _cascade_with_curve()
    lin = base.simulate(v, u, coords=False)[:, 0]
    neutral = ms.decode(ms.encode({k: float(a[0]) for k, a in v.items()}))
    assert np.allclose(ms.simulate(neutral, u, coords=False)[:, 0], lin)      # gamma = 1: linear reading
    curved = dict(neutral, gamma=np.array([2.0]))
    c, X = float(v["c"][0]), sc.y_range
    assert np.allclose(ms.simulate(curved, u, coords=False)[:, 0], c + X * ((lin - c) / X) ** 2)
    phys = ms.physical(ms.encode({k: float(a[0]) for k, a in curved.items()}))
    assert np.isclose(phys["sensor_curve.gamma"], 2.0) and np.isclose(phys["sensor_curve.scale"], X)


def test_sensor_curve_zero_reads_the_curve_from_a_point_above_the_outlet():
    """The curve's zero ``z``: the core's head ``H`` drives the outflow, the PV reads ``c + X ((H - z)/X)**g``."""
    u, sc, base, ms, v = _cascade_with_curve()
    c, z, g, X = float(v["c"][0]), 1.5, 1.7, sc.y_range
    # the same core (head, outflow, initial head) is the linear model with offset c - z
    head_pv = base.simulate(dict(v, c=np.array([c - z])), u, coords=False)[:, 0]
    w = ms.encode({**{k: float(a[0]) for k, a in v.items()}, "gamma": g, "curve_zero": z})
    curved = ms.simulate(w[None, :], u)[:, 0]
    assert np.allclose(curved, c + X * (np.maximum(head_pv - c, 0.0) / X) ** g)
    assert np.ptp(head_pv) > 0.5 and np.any(head_pv < c + 0.5)      # the curve's low end is exercised
    phys = ms.physical(w)
    assert phys["sensor_curve.zero"] == pytest.approx(z)
    assert phys["measurement.offset"] == pytest.approx(c - z)        # the linear map of the head


def test_cascaded_tanks_held_out_with_overflow_and_the_curve_zero():
    """README proof 1 on the real lab record: overflow, then the sensor curve with its zero above the outlet."""
    rec = load_recording(data_path("cascaded_tanks/estimation.csv"), columns={"t": "t_s", "op": "u_V", "pv": "y_V"},
                         op_range=(0, 10))
    res = diagnose(rec, plant="cascade", actuator="pump", holdout=1 / 3, op_lag=1,
                   candidates=("overflow", "sensor_curve"), effort="fast")
    h = res.to_dict()["holdout"]
    assert res.effects == ["overflow", "sensor_curve"]
    assert h["final_rmse"] < 0.18 < 0.5 * h["base_rmse"]               # 0.172 V (0.188 V with the zero at 0)
    assert 2.0 < res.final_split.physical["sensor_curve.zero"] < 6.0    # V of head above the outlet (4.2)
    assert any("above the outlet" in p for p in res.explanation)


def test_sensor_curve_zero_is_recovered_and_a_curve_from_the_outlet_misreads_it():
    """A cascade read through a curve whose zero sits above the outlet: the curve is named, fits to the noise
    with about the true exponent; with the zero held at the outlet the fit is worse and the exponent inflated
    (as on the real cascaded tanks, where the zero took gamma from 2.19 to 1.49)."""
    rng = np.random.default_rng(5)
    n, noise = 900, 0.01
    u = np.repeat(rng.uniform(0.2, 0.7, n // 30), 30)
    sc = DataScales.from_signals(u, 4.0 + 2.0 * np.sin(np.linspace(0, 6, n)), 4.0)
    ms = ModelStructure("cascade", "pump", ("sensor_curve",), sc, n_sub=1)
    base = ModelStructure("cascade", "pump", (), sc, n_sub=1)
    true = {k: float(a[0]) for k, a in base.decode(np.full((1, len(base.params)), 0.5)).items()}
    true.update(gamma=1.6, curve_zero=1.5, c=-1.5)
    y = ms.simulate(ms.encode(true)[None, :], u)[:, 0] + rng.normal(0.0, noise, n)
    rec = Recording(name="curved_cascade", t=4.0 * np.arange(n), dt=4.0, op=u, pv=y)
    res = diagnose(rec, plant="cascade", actuator="pump", holdout=1 / 3, op_lag=0, candidates=("sensor_curve",),
                   effort="fast", jobs=1)
    assert res.effects == ["sensor_curve"]
    fit = res.final
    assert fit.rmse < 1.5 * noise < 0.1 * res.base.rmse
    assert abs(fit.physical["sensor_curve.gamma"] - 1.6) < 0.15
    assert fit.physical["sensor_curve.zero"] > 0.5
    st = fit.structure
    w0 = fit.w.copy()
    w0[st.index("curve_zero")] = 0.0
    held = fit_structure(st, rec.op, rec.pv, seeds=w0[None, :], w_fixed=w0, rng=0, effort="fast",
                         free=[p.name for p in st.params if p.name != "curve_zero"])
    assert held.rmse > 1.5 * fit.rmse
    assert held.physical["sensor_curve.gamma"] > 1.8
