"""valve_gym.agents.bench.scenarios: seeded, reproducible, prefix-stable loops with the configured bands."""
import numpy as np
import pytest

from valve_gym.agents.bench.config import BenchConfig, load_bench_config
from valve_gym.agents.bench.scenarios import band_labels, benchmark_scenarios, regulation_scenarios, servo_scenarios


def test_regulation_population_and_signals():
    cfg = BenchConfig()
    sc = regulation_scenarios(cfg)
    assert sc.n == 135 and sc.n_steps == 3600 and sc.duration_s == 3600.0
    for b in ("healthy", "sticky", "severe"):
        m = sc.band == b
        lo, hi = getattr(cfg.bands, b).S
        assert m.sum() == getattr(cfg.bands, b).n
        assert ((sc.S[m] >= lo) & (sc.S[m] <= hi)).all()
        assert set(sc.model[m]) == set(cfg.models)                  # every model in every band
    assert ((sc.J >= 0) & (sc.J <= sc.S)).all()
    assert (sc.sp == sc.sp[0]).all() and set(np.round(sc.sp[0], 9)) == set(cfg.regulation.levels)
    assert (sc.load[0] == 0).all()                                    # steady start: no load at t = 0
    # OU load and noise have the configured statistics (pooled over loops)
    assert np.std(sc.load[600:]) == pytest.approx(cfg.regulation.load.sigma, rel=0.1)
    assert np.std(sc.noise) == pytest.approx(cfg.regulation.noise_std, rel=0.02)


def test_reproducible_and_prefix_stable():
    cfg = BenchConfig()
    a, b = regulation_scenarios(cfg, n=9, seed=4), regulation_scenarios(cfg, n=9, seed=4)
    assert np.array_equal(a.S, b.S) and np.array_equal(a.noise, b.noise) and np.array_equal(a.load, b.load)
    c = regulation_scenarios(cfg, n=9, seed=5)
    assert not np.array_equal(a.noise, c.noise)
    short = regulation_scenarios(load_bench_config({"regulation": {"duration_s": 600.0}}), n=9, seed=4)
    assert np.array_equal(short.noise, a.noise[:600]) and np.array_equal(short.S, a.S)


def test_band_labels_proportions():
    cfg = BenchConfig()
    lab = band_labels(cfg, 27)
    assert lab.size == 27 and {str(x) for x in lab} == {"healthy", "sticky", "severe"}
    assert (lab == "sticky").sum() == 12
    with pytest.raises(ValueError, match="n must be >= 1"):
        band_labels(cfg, 0)


def test_servo_steps_and_subset():
    cfg = BenchConfig()
    sc = servo_scenarios(cfg, n=3)
    s0 = sc.sp[:, 0]
    step = cfg.servo.step
    k = int(cfg.servo.interval_s)
    assert s0[0] == s0[k - 1] and s0[k] == pytest.approx(s0[0] + step)
    assert s0[3 * k] == pytest.approx(s0[0] - step)
    sub = sc.subset(np.array([2]))
    assert sub.n == 1 and np.array_equal(sub.sp[:, 0], sc.sp[:, 2])
    both = benchmark_scenarios(cfg.quick_version())
    assert both.part("servo").part == "servo"
    with pytest.raises(ValueError, match="unknown part"):
        both.part("nope")
