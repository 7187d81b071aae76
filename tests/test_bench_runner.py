"""valve_gym.agents.bench.runner: batched runs equal single-loop runs; banks of blocks; the detector on real loops."""
import numpy as np
import pytest

from valve_gym.agents import load_controller
from valve_gym.agents.bench.config import BenchConfig, load_bench_config
from valve_gym.agents.bench.runner import ControllerBank, ControllerSpec, lineup, make_controller, run_loops, run_spec
from valve_gym.agents.bench.scenarios import regulation_scenarios, servo_scenarios
from valve_gym.oscillation import detect_oscillation

CFG = load_bench_config({"regulation": {"duration_s": 400.0}})


def test_batch_equals_single_loops():
    sc = regulation_scenarios(CFG, n=6, seed=3)
    both = run_loops(load_controller("pi"), sc)
    for i in (0, 4):
        one = run_loops(load_controller("pi"), sc.subset(np.array([i])))
        np.testing.assert_allclose(one.level[:, 0], both.level[:, i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(one.op[:, 0], both.op[:, i], rtol=0, atol=1e-12)
    # steady start: the level starts at the set point, and the noise is what the controller saw
    np.testing.assert_allclose(both.level[0], sc.sp[0])
    np.testing.assert_allclose(both.pv - both.level, sc.noise)


def test_per_loop_estimates_equal_separate_blocks():
    """The block the benchmark builds (per-loop S) = one block per loop; a ControllerBank of them too."""
    sc = regulation_scenarios(CFG, n=6, seed=3)
    spec = ControllerSpec("knocker", "knocker", "compensator", estimate=1.0)
    est = np.maximum(sc.S, 1e-3)
    runs = run_loops(make_controller(spec, sc), sc)
    blocks = [load_controller("knocker", S=float(s)) for s in est]
    bank = ControllerBank(blocks, [np.array([i]) for i in range(sc.n)], sc.n)
    banked = run_loops(bank, sc)
    np.testing.assert_allclose(banked.op, runs.op, rtol=0, atol=1e-12)
    for i in (0, 5):
        alone = run_loops(load_controller("knocker", S=float(est[i])), sc.subset(np.array([i])))
        np.testing.assert_allclose(alone.op[:, 0], runs.op[:, i], rtol=0, atol=1e-12)


def test_frictionless_run_is_the_same_loop_without_friction():
    sc = regulation_scenarios(CFG, n=6, seed=3)
    sticky = run_spec(ControllerSpec("PI (SIMC)", "pi", "pi"), sc)
    free = run_spec(ControllerSpec("PI frictionless", "pi", "frictionless", frictionless=True), sc)
    assert np.array_equal(sticky.sp, free.sp)
    # the frictionless stem follows the output (positioner lag only), the sticky ones do not
    assert np.abs(free.stem[2:] - free.op[1:-1]).max() < 0.01
    assert np.abs(sticky.stem[2:] - sticky.op[1:-1])[:, sc.band == "severe"].max() > 0.01


def test_lineup_names_and_sensitivity_rows():
    specs = lineup(BenchConfig())
    labels = [s.label for s in specs]
    assert labels[:2] == ["PI frictionless", "PI (SIMC)"] and "PI Kc x0.25" in labels
    for comp in ("knocker", "constant_reinforcement", "two_move", "integral_freeze"):
        assert {comp, f"{comp} S x0.5", f"{comp} S x1.5"} <= set(labels)
    assert labels[-2:] == ["learned", "learned_network"]


@pytest.mark.parametrize("part", ["regulation", "servo"])
def test_detector_silent_on_healthy_pi_loops(part):
    """Constant set point with load and 2 mm noise, and set-point steps: no limit cycle on a frictionless valve."""
    cfg = BenchConfig()
    sc = (regulation_scenarios if part == "regulation" else servo_scenarios)(cfg, n=6, seed=11)
    runs = run_spec(ControllerSpec("PI frictionless", "pi", "frictionless", frictionless=True), sc)
    e = runs.sp - runs.pv
    assert not any(detect_oscillation(e[:, i], 1.0).present for i in range(sc.n))
