"""Tests of valve_gym.plant.Plant: steady reset, scan stepping, equivalence with the core, errors."""
from __future__ import annotations

import doctest

import numpy as np
import pytest

from valve_gym import plant as plant_mod
from valve_gym.core import initial_state, simulate, steady_input
from valve_gym.friction import FRICTION_MODELS, valve_model
from valve_gym.params import Cascade, ModelParams, ParameterError, TankParams, ValveParams
from valve_gym.plant import Plant, PlantOutput


def test_module_doctest():
    res = doctest.testmod(plant_mod, optionflags=doctest.ELLIPSIS)
    assert res.failed == 0 and res.attempted > 0


@pytest.mark.parametrize("model", FRICTION_MODELS)
def test_reset_is_a_steady_state(model):
    p = valve_model(model, np.array([0.01, 0.03, 0.05]), np.array([0.0, 0.01, 0.05]))
    plant = Plant(p, 3)
    out = plant.reset(level=np.array([0.5, 1.0, 1.5]))
    assert isinstance(out, PlantOutput)
    np.testing.assert_array_equal(out.pv, [0.5, 1.0, 1.5])
    np.testing.assert_allclose(out.op, steady_input(p, out.pv, 3))
    np.testing.assert_array_equal(out.stem, out.op)
    for _ in range(100):
        o = plant.step(out.op)
    np.testing.assert_allclose(o.pv, out.pv, atol=1e-9)
    np.testing.assert_array_equal(o.stem, out.stem)
    assert plant.t == pytest.approx(100.0)


@pytest.mark.parametrize("model", FRICTION_MODELS)
def test_steps_equal_the_core_simulation(model):
    rng = np.random.default_rng(3)
    n, T = 4, 120
    p = valve_model(model, rng.uniform(0.01, 0.05, n), rng.uniform(0.0, 0.01, n))
    u = np.clip(0.45 + np.cumsum(rng.normal(0, 0.01, (T, n)), axis=0), 0, 1)
    d = rng.normal(0, 1e-4, (T, n))
    plant = Plant(p, n, scan_s=0.5)
    plant.reset(level=1.0)
    st = initial_state(p, n, level=1.0)
    tr = simulate(p, u, state=st, d=d, n_sub=int(round(0.5 / p.dt)), n=n)
    for k in range(T):
        o = plant.step(u[k], d=d[k])
        np.testing.assert_array_equal(o.pv, tr.level[k])
        np.testing.assert_array_equal(o.stem, tr.h[k])
        np.testing.assert_array_equal(o.y, tr.y[k])
        np.testing.assert_array_equal(o.op, tr.u[k])
    assert plant.t == pytest.approx(T * 0.5)
    for a, b in zip(plant.state, tr.final):
        np.testing.assert_array_equal(a, b)


def test_op_saturates_and_scalar_broadcasts():
    plant = Plant(ModelParams(), 2)
    plant.reset()
    o = plant.step(1.7)
    np.testing.assert_array_equal(o.op, [1.0, 1.0])
    o = plant.step(np.array([-0.2, 0.4]))
    np.testing.assert_array_equal(o.op, [0.0, 0.4])


def test_inflow_disturbance_raises_the_level():
    p = valve_model("none", 0.0, 0.0)
    plant = Plant(p, 2)
    op = plant.reset(level=1.0).op
    for _ in range(20):
        o = plant.step(op, d=np.array([0.0, 0.002]))
    assert o.pv[0] == pytest.approx(1.0, abs=1e-9)
    assert o.pv[1] > 1.05


def test_cascade_reset_is_steady():
    p = ModelParams(process_kind="cascade", cascade=Cascade(), process=TankParams())
    plant = Plant(p, 1)
    out = plant.reset(level=0.8)
    for _ in range(200):
        o = plant.step(out.op)
    assert o.pv[0] == pytest.approx(0.8, abs=1e-9)


def test_reset_restarts_time_and_state():
    plant = Plant(valve_model("choudhury", 0.03, 0.01), 1)
    a = plant.reset(level=1.0)
    plant.step(0.8)
    plant.step(0.8)
    b = plant.reset(level=1.0)
    assert plant.t == 0.0
    np.testing.assert_array_equal(a.stem, b.stem)


@pytest.mark.parametrize("kwargs,match", [
    (dict(n=0), "positive integer"),
    (dict(n=2.5), "positive integer"),
    (dict(n=2, scan_s=0.03), "whole multiple"),
    (dict(n=2, scan_s=-1.0), "positive number of seconds"),
])
def test_bad_construction(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        Plant(ModelParams(), **kwargs)


def test_bad_inputs():
    plant = Plant(ModelParams(), 3)
    with pytest.raises(RuntimeError, match="reset"):
        plant.step(0.5)
    plant.reset()
    with pytest.raises(ValueError, match="NaN"):
        plant.step(np.array([0.5, np.nan, 0.5]))
    with pytest.raises(ValueError, match=r"\(n,\) = \(3,\)"):
        plant.step(np.zeros(2))
    with pytest.raises(ValueError, match="d must be"):
        plant.step(0.5, d=np.zeros((3, 2)))
    with pytest.raises(ParameterError, match="level"):
        plant.reset(level=-1.0)
    with pytest.raises(ParameterError, match="ModelParams"):
        Plant("tank", 2)


@pytest.mark.parametrize("model", ["kano", "karnopp"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_sticky_valve_starts_in_the_middle_of_its_band(model, sign):
    """From reset, Kano's and the force-balance valve's first move needs (S + J)/2 of input either way
    and jumps J, never against the input."""
    S, J, du = 0.05, 0.01, 1e-4
    p = valve_model(model, S, J, base=ModelParams(dt=1e-3, valve=ValveParams(tau=1e-3)))
    plant = Plant(p, 1, scan_s=1e-3)
    u0 = plant.reset().op[0]
    us = u0 + sign * du * np.arange(1, 600)
    stems = np.array([plant.step(u).stem[0] for u in us])
    kb = int(np.argmax(stems != u0))
    travel = sign * (us[kb] - u0)
    if model == "kano":
        assert (S + J) / 2 - 1e-12 < travel <= (S + J) / 2 + du + 1e-12
    else:   # actuator lag tau_p = 1 ms: at most a few samples of input more
        assert (S + J) / 2 - 1e-12 < travel <= (S + J) / 2 + 3 * du
    k2 = kb + 100
    speed = du / 1e-3
    viscous = 2 * p.slip_jump.zeta / p.slip_jump.omega_n * speed if model == "karnopp" else 0.0
    assert sign * (stems[k2] - u0) - sign * (us[k2] - us[kb]) == pytest.approx(J - viscous, abs=3 * du)
    assert np.all(sign * (stems - u0) >= 0)
