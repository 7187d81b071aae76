"""Tests of valve_gym.plant.Plant: steady reset, scan stepping, equivalence with the core, errors."""
from __future__ import annotations

import doctest

import numpy as np
import pytest

from valve_gym import core
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


# --------------------------------------------------------------------------- #
# run(), advance(), scan_args(), explicit initial states, set_params, check=False
# --------------------------------------------------------------------------- #
def _record(rng, T, n):
    u = np.clip(0.45 + np.cumsum(rng.normal(0, 0.01, (T, n)), axis=0), 0, 1)
    d = rng.normal(0, 1e-4, (T, n))
    return u, d


@pytest.mark.parametrize("model", FRICTION_MODELS)
def test_run_equals_stepping_scan_by_scan(model):
    rng = np.random.default_rng(7)
    n, T = 3, 80
    p = valve_model(model, rng.uniform(0.01, 0.05, n), rng.uniform(0.0, 0.01, n))
    u, d = _record(rng, T, n)
    a, b = Plant(p, n, scan_s=0.5), Plant(p, n, scan_s=0.5)
    a.reset(level=1.2)
    b.reset(level=1.2)
    y, stem, level = a.run(u[:40], D=d[:40])
    y2, stem2, level2 = a.run(u[40:], D=d[40:])            # a second run continues from the state
    outs = [b.step(u[k], d=d[k]) for k in range(T)]
    np.testing.assert_array_equal(np.vstack([y, y2]), [o.y for o in outs])
    np.testing.assert_array_equal(np.vstack([stem, stem2]), [o.stem for o in outs])
    np.testing.assert_array_equal(np.vstack([level, level2]), [o.pv for o in outs])
    assert a.t == b.t == pytest.approx(T * 0.5)
    for s1, s2 in zip(a.state, b.state):
        np.testing.assert_array_equal(s1, s2)


def test_run_shared_column_into_given_arrays_equals_advance():
    rng = np.random.default_rng(8)
    n, T = 4, 30
    p = valve_model("kano", 0.04, 0.01)
    u = rng.uniform(0.3, 0.7, T)
    a, b = Plant(p, n), Plant(p, n)
    a.reset()
    b.reset()
    out = tuple(np.full((T, n), np.nan) for _ in range(3))
    res = a.run(u, out=out)
    assert all(r is o for r, o in zip(res, out))
    for k in range(T):
        Y, H, LV = b.advance(np.full((1, 1), u[k]), np.zeros((1, 1)))
        np.testing.assert_array_equal(out[0][k], Y[0])
        np.testing.assert_array_equal(out[1][k], H[0])
        np.testing.assert_array_equal(out[2][k], LV[0])


def test_scan_args_is_advance_without_the_frame():
    p = valve_model("choudhury", 0.03, 0.01)
    a, b = Plant(p, 2), Plant(p, 2)
    a.reset()
    b.reset()
    U, D = np.zeros((1, 2)), np.zeros((1, 2))
    out = tuple(np.empty((1, 2)) for _ in range(3))
    args = a.scan_args(U, D, out)
    for k in range(20):
        U[0] = [0.4 + 0.01 * k, 0.6 - 0.01 * k]
        core.run_packed(*args)
        res = b.advance(U, D)
        for x, y in zip(out, res):
            np.testing.assert_array_equal(x, y)


def test_reset_at_a_given_stem_and_upper_level():
    p = ModelParams(process_kind="cascade", cascade=Cascade(), process=TankParams())
    plant = Plant(p, 2)
    out = plant.reset(level=[0.8, 1.1], stem=[0.2, 0.7], level_upper=[1.5, 0.9])
    st = plant.state
    np.testing.assert_array_equal(st.level2, [0.8, 1.1])
    np.testing.assert_array_equal(st.level, [1.5, 0.9])
    np.testing.assert_array_equal(st.h, [0.2, 0.7])
    np.testing.assert_array_equal(out.stem, [0.2, 0.7])
    np.testing.assert_array_equal(out.op, [0.2, 0.7])
    np.testing.assert_array_equal(out.pv, [0.8, 1.1])
    ref = simulate(p, np.full((20, 2), [0.2, 0.7]), n_sub=50,
                   state=initial_state(p, 2, level=[1.5, 0.9], level2=[0.8, 1.1], h=[0.2, 0.7]))
    _, _, lv = plant.run(np.full((20, 2), [0.2, 0.7]))
    np.testing.assert_array_equal(lv, ref.level)
    with pytest.raises(ParameterError, match="level_upper"):
        Plant(ModelParams(), 1).reset(level_upper=1.0)
    with pytest.raises(ParameterError, match="stem"):
        Plant(ModelParams(), 1).reset(stem=1.5)


@pytest.mark.parametrize("model", ["riihilahti", "kano"])
def test_valve_started_anywhere_in_its_band_stays_stuck(model):
    """A valve put at rest at a stem off the steady input holds it while the input stays inside the band."""
    p = valve_model(model, 0.05, 0.01)
    plant = Plant(p, 3)
    stems = np.array([0.48, 0.5, 0.52])
    plant.reset(level=1.0, stem=stems)
    _, stem, level = plant.run(np.full(30, 0.5))
    np.testing.assert_array_equal(stem, np.broadcast_to(stems, (30, 3)))
    assert level[-1, 0] < 1.0 < level[-1, 2]       # the flow follows the stuck stem, not the input


def test_set_state_from_initial_state_and_partial_index():
    rng = np.random.default_rng(9)
    n, T = 4, 25
    p = valve_model("kano", 0.04, 0.01)
    u, d = _record(rng, T, n)
    st = initial_state(p, n, level=rng.uniform(0.8, 1.2, n), h=rng.uniform(0.3, 0.6, n))
    plant = Plant(p, n)
    plant.set_state(st)
    assert plant.t == 0.0
    y, stem, level = plant.run(u, D=d)
    ref = simulate(p, u, state=st, d=d, n_sub=50)
    np.testing.assert_array_equal(y, ref.y)
    np.testing.assert_array_equal(stem, ref.h)
    np.testing.assert_array_equal(level, ref.level)
    before = plant.state
    one = initial_state(p, 1, level=0.9, h=0.55)
    plant.set_state(one, index=np.array([False, True, False, True]))
    after = plant.state
    for f in range(len(before) - 1):
        np.testing.assert_array_equal(after[f][[0, 2]], before[f][[0, 2]])
        np.testing.assert_array_equal(after[f][[1, 3]], np.repeat(one[f], 2))
    assert plant.t == pytest.approx(T)               # a partial write does not restart the time


def test_set_params_keeps_the_state():
    rng = np.random.default_rng(10)
    n, T = 2, 20
    pa = valve_model("kano", 0.04, 0.01)
    pb = valve_model("kano", 0.02, 0.005)
    u, d = _record(rng, 2 * T, n)
    plant = Plant(pa, n)
    plant.reset()
    plant.run(u[:T], D=d[:T])
    plant.set_params(pb)
    _, _, level = plant.run(u[T:], D=d[T:])
    first = simulate(pa, u[:T], d=d[:T], n_sub=50, n=n)
    second = simulate(pb, u[T:], state=first.final, d=d[T:], n_sub=50, n=n)
    np.testing.assert_array_equal(level, second.level)


def test_check_false_packs_invalid_rows_and_gives_their_columns():
    bad = ModelParams(valve=ValveParams(tau=np.array([0.1, 0.001])))   # tau < dt: unstable Euler
    with pytest.raises(ParameterError, match="too large"):
        Plant(bad, 2)
    plant = Plant(bad, 2, check=False)
    plant.reset(level=np.array([1.0, np.nan]))
    y, stem, level = plant.run(np.full(10, 0.6))
    assert np.isfinite(level[:, 0]).all() and np.isnan(level[:, 1]).all()
    good = Plant(ModelParams(), 1)
    good.reset()
    np.testing.assert_array_equal(level[:, 0], good.run(np.full(10, 0.6))[2][:, 0])


def test_run_and_state_errors():
    plant = Plant(ModelParams(), 3)
    with pytest.raises(RuntimeError, match="reset"):
        plant.run(np.zeros(5))
    with pytest.raises(RuntimeError, match="reset"):
        plant.advance(np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(RuntimeError, match="without index"):
        plant.set_state(initial_state(ModelParams(), 3), index=[0])
    plant.reset()
    with pytest.raises(ValueError, match=r"shape \(T,\), \(T, 1\) or \(T, n\)"):
        plant.run(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="NaN or inf"):
        plant.run(np.array([0.5, np.nan]))
    with pytest.raises(ValueError, match="rows"):
        plant.run(np.zeros(5), D=np.zeros(4))
    with pytest.raises(ValueError, match="out must be"):
        plant.run(np.zeros(5), out=(np.zeros((5, 3)),) * 2)
    with pytest.raises(ValueError, match="core.State"):
        plant.set_state({"level": 1.0})
    with pytest.raises(ValueError, match="1 or n = 3 loops"):
        plant.set_state(initial_state(ModelParams(), 2))
    with pytest.raises(ValueError, match="out of range"):
        plant.set_state(initial_state(ModelParams(), 1), index=[5])
    with pytest.raises(ParameterError, match="NaN or inf"):
        plant.set_state(initial_state(ModelParams(), 1, level=np.nan))


def test_run_with_a_per_scan_friction_law_equals_stepping(he_model):
    rng = np.random.default_rng(11)
    n, T = 2, 60
    p = valve_model("he", np.array([0.03, 0.05]), np.array([0.01, 0.02]))
    u, d = _record(rng, T, n)
    a, b = Plant(p, n), Plant(p, n)
    assert a.sample_law is not None
    a.reset()
    b.reset()
    y, stem, level = a.run(u, D=d)
    outs = [b.step(u[k], d=d[k]) for k in range(T)]
    np.testing.assert_array_equal(stem, [o.stem for o in outs])
    np.testing.assert_array_equal(level, [o.pv for o in outs])
    assert np.ptp(stem[:, 0]) > 0.01                  # the valve did move
    with pytest.raises(ValueError, match="advance"):
        a.scan_args(np.zeros((1, n)), np.zeros((1, n)), tuple(np.empty((1, n)) for _ in range(3)))
