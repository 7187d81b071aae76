"""valve_gym.loop: the one closed-loop runner, for any block, on one plant or on column groups."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.agents import load_controller
from valve_gym.control import PIParams
from valve_gym.friction import valve_model
from valve_gym.loop import PILaw, Scenario, run_closed_loop, run_pi_loop
from valve_gym.params import ModelParams
from valve_gym.plant import Plant, PlantOutput


def _scenario(T=200, n=4, seed=0):
    rng = np.random.default_rng(seed)
    sp = np.full((T, n), 1.0)
    sp[T // 2:] = 1.1
    return sp, 1e-5 * rng.standard_normal((T, n)), 1e-3 * rng.standard_normal((T + 1, n))


def test_column_groups_equal_separate_runs():
    sp, load, noise = _scenario()
    sc = Scenario(sp=sp, scan_s=1.0, load=load, noise=noise)
    S, J = np.array([0.02, 0.04, 0.01, 0.03]), np.array([0.01, 0.02, 0.005, 0.0])
    a, b = np.array([0, 2]), np.array([1, 3])
    plants = [(a, Plant(valve_model("choudhury", S[a], J[a]), 2)), (b, Plant(valve_model("kano", S[b], J[b]), 2))]
    both = run_closed_loop(plants, load_controller("knocker", S=0.02), sc)
    for cols, model in ((a, "choudhury"), (b, "kano")):
        one = run_closed_loop(Plant(valve_model(model, S[cols], J[cols]), 2), load_controller("knocker", S=0.02),
                              Scenario(sp=sp[:, cols], scan_s=1.0, load=load[:, cols], noise=noise[:, cols]))
        for x, y in zip(both, one):
            np.testing.assert_array_equal(x[:, cols], y)
    assert both.op.shape == (200, 4) and both.pv.shape == (201, 4)


def test_pi_block_and_pi_law_run_the_same_loop():
    sc = Scenario(*_scenario(n=1)[:1], scan_s=1.0, load=_scenario(n=1)[1], noise=_scenario(n=1)[2])
    plant = Plant(ModelParams(), 1)
    start = plant.reset(level=1.0)
    law = run_closed_loop(plant, PILaw(PIParams(Kc=1.89, Ti=42.4)), sc, start=start._replace(op=start.stem))
    blk = run_closed_loop(Plant(ModelParams(), 1), load_controller("pi", Kc=1.89, Ti=42.4), sc)
    np.testing.assert_allclose(law.op, blk.op, atol=1e-9)   # velocity and positional forms of one law


def test_a_plant_coded_apart_runs_through_the_protocol():
    class Tank:                      # integrating tank, the valve follows its input
        n, scan_s = 2, 1.0

        def __init__(self):
            self.y = np.ones(2)

        def scan(self, u, d):
            self.y = self.y + 0.1 * (u - 0.5) + d
            return self.y.copy(), u.copy(), self.y.copy()

    start = PlantOutput(pv=np.ones(2), stem=np.full(2, 0.5), op=np.full(2, 0.5), y=np.ones(2))
    run = run_closed_loop(Tank(), load_controller("pi", Kc=2.0, Ti=20.0), Scenario(np.full((300, 2), 1.2), 1.0),
                          start=start)
    assert np.allclose(run.level[-1], 1.2, atol=1e-3)
    with pytest.raises(ValueError, match="start="):
        run_closed_loop(Tank(), load_controller("pi"), Scenario(np.ones((5, 2)), 1.0))


class _Bad:
    name, scan_s = "bad", 1.0

    def reset(self, sp, pv, op):
        pass

    def step(self, sp, pv):
        return np.full(np.shape(sp), np.nan)


@pytest.mark.parametrize("kw, match", [
    (dict(sp=np.ones((5, 2))), "plant runs 1 loop"),
    (dict(sp=np.ones(5)), "sp must be a finite"),
    (dict(sp=np.ones((5, 1)), load=np.ones((4, 1))), "load must be"),
    (dict(sp=np.ones((5, 1)), noise=np.ones((7, 1))), "noise must be"),
    (dict(sp=np.ones((5, 1)), scan_s=2.0), "scan_s"),
])
def test_bad_scenarios_are_named(kw, match):
    kw = {"scan_s": 1.0, **kw}
    with pytest.raises(ValueError, match=match):
        run_closed_loop(Plant(ModelParams(), 1), load_controller("pi"), Scenario(**kw))


def test_non_finite_block_output_and_bad_groups_are_named():
    with pytest.raises(ValueError, match="'bad' returned a non-finite output at scan 0"):
        run_closed_loop(Plant(ModelParams(), 1), _Bad(), Scenario(np.ones((5, 1)), 1.0))
    p = Plant(ModelParams(), 1)
    with pytest.raises(ValueError, match="exactly once"):
        run_closed_loop([(np.array([0]), p), (np.array([0]), Plant(ModelParams(), 1))], _Bad(),
                        Scenario(np.ones((5, 2)), 1.0))


def test_pi_wrapper_draws_the_noise_from_the_generator():
    plant = Plant(ModelParams(), 1)
    start = plant.reset(level=1.0)
    run = run_pi_loop(plant, start, np.full((50, 1), 1.0), PIParams(Kc=1.0, Ti=30.0), 0.01, np.random.default_rng(4))
    z = 0.01 * np.random.default_rng(4).standard_normal((51, 1))
    np.testing.assert_allclose(run.pv - run.level, z, atol=1e-12)   # no sensor lag: pv = level + noise
