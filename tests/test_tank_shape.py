"""The tank's cross-section as a function of the level (``tank_shape``): kernel, stability check, diagnosis."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from valve_gym.core import check_dt, simulate, tank_shape_factor
from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.stiction.loops import LoopSpec, simulate_loop
from valve_gym.params import AREA_FLOOR, Actuator, FirstOrderParams, ModelParams, ParameterError, TankParams, TankShape

PUMP = ModelParams(process=TankParams(area=0.2, q_max=0.01, k_out=0.005, level0=1.0),
                   actuator=Actuator(kind="pump"), dt=0.1)


def _euler(u, area_of, q_max=0.01, k_out=0.005, level=1.0, dt=0.1):
    """An independent Euler integration of ``A(L) dL/dt = q_max u - k_out sqrt(L)``, one step per sample."""
    out = []
    for uk in u:
        level = max(level + dt * (q_max * uk - k_out * np.sqrt(level)) / area_of(level), 0.0)
        out.append(level)
    return np.array(out)


def test_a_cone_follows_its_own_balance():
    u = np.r_[np.full(300, 0.8), np.full(300, 0.2), np.full(300, 0.5)]
    cone = replace(PUMP, tank_shape=TankShape(taper=2.0, curvature=1.0, L_ref=1.0))
    y = simulate(cone, u).y[:, 0]
    ref = _euler(u, lambda L: 0.2 * max(L * L, AREA_FLOOR))        # A ~ L^2, apex down
    np.testing.assert_allclose(y, ref, rtol=1e-10, atol=1e-12)
    cyl = simulate(PUMP, u).y[:, 0]
    # above L_ref the cone is wider than the cylinder of the same area at L_ref: it fills more slowly
    assert 1.0 < y[299] < cyl[299] - 0.01


def test_the_cylinder_is_nested():
    u = np.linspace(0.2, 0.9, 500)
    flat = replace(PUMP, tank_shape=TankShape(taper=0.0, curvature=0.0, L_ref=0.7))
    np.testing.assert_array_equal(simulate(flat, u).y, simulate(PUMP, u).y)


def test_a_batch_of_shapes_runs_in_one_call():
    u = np.full(200, 0.3)
    taper = np.array([0.0, 1.0, 2.0])
    ys = simulate(replace(PUMP, tank_shape=TankShape(taper=taper, curvature=0.0, L_ref=1.0)), u).y
    for i, a in enumerate(taper):
        one = simulate(replace(PUMP, tank_shape=TankShape(taper=float(a), curvature=0.0, L_ref=1.0)), u).y[:, 0]
        np.testing.assert_allclose(ys[:, i], one, rtol=1e-12)


def test_the_area_floor_and_the_stability_check():
    sh = TankShape(taper=2.0, curvature=1.0, L_ref=1.0)
    np.testing.assert_allclose(tank_shape_factor(sh, np.array([0.0, 0.5, 1.0, 2.0])), [AREA_FLOOR, 0.25, 1.0, 4.0])
    # the stability check reads the area where the tank is narrowest in its check (10 % inflow):
    # a step that suits the cylinder is refused for the cone
    mp = replace(PUMP, dt=5.0)                   # cylinder: 2 A sqrt(L)/k = 16 s at 10 % inflow
    check_dt(mp)
    with pytest.raises(ParameterError, match="outflow time constant"):
        check_dt(replace(mp, tank_shape=sh))


def test_the_shape_needs_a_level():
    mp = ModelParams(process=FirstOrderParams(), process_kind="first_order", tank_shape=TankShape())
    with pytest.raises(ParameterError, match="tank_shape needs a tank"):
        simulate(mp, np.full(10, 0.5))
    with pytest.raises(ParameterError, match="L_ref"):
        TankShape(L_ref=0.0)


@pytest.mark.slow
def test_diagnosis_names_a_cone_and_leaves_a_cylinder():
    """Loops of the independent textbook simulator: a conical tank is named with its taper, a cylinder is not."""
    spec = LoopSpec(process="tank", valve="linear", S=0.0, J=0.0, theta=0.0, area=0.25, q_max=0.011,
                    c_out=0.005, Kc=8.0, Ti=15.0, Ts=1.0, noise=0.002, tau_v=0.2, n=1200, sp_moves=0.25)
    cone = diagnose(simulate_loop(replace(spec, shape="cone"), seed=0), plant="tank", actuator="valve",
                    candidates=("tank_shape", "leak"), jobs=1)
    assert cone.effects == ["tank_shape"]
    ph = cone.final.physical
    assert 1.2 < ph["tank_shape.taper"] < 2.8                      # the cone's is 2
    assert ph["tank_shape.area_at_min_pv"] < 1.0 < ph["tank_shape.area_at_max_pv"]
    assert any(p.startswith("Tank shape") for p in cone.explanation)
    cyl = diagnose(simulate_loop(spec, seed=0), plant="tank", actuator="valve",
                   candidates=("tank_shape", "leak"), jobs=1)
    assert cyl.effects == []


def test_the_suite_generator_conceals_a_shaped_tank():
    from valve_gym.diagnosis.synthetic import SUITE_EFFECTS, make_case

    assert "tank_shape" in SUITE_EFFECTS
    case = make_case("tank_shape", seed=4, n=400)
    sh = case.params.tank_shape
    e = case.truth["tank_shape.taper"]
    assert 1.0 <= e <= 2.0 and sh.taper == e and sh.L_ref == 1.0
    assert case.truth["tank_shape.curvature"] == pytest.approx(e * (e - 1) / 2)
    plain = make_case("none", seed=4, n=400)
    assert plain.params.tank_shape is None
