"""valve_gym.agents.bench.scores: compensation ratio on constructed numbers, bootstrap CIs, the learned comparison."""
import numpy as np
import pytest

from valve_gym.agents.bench.config import BenchConfig
from valve_gym.agents.bench.scenarios import regulation_scenarios
from valve_gym.agents.bench.scores import (
    REFERENCE_FRICTIONLESS,
    REFERENCE_PI,
    LoopScores,
    bootstrap_mean,
    bootstrap_median,
    compare_learned,
    compensation_ratio,
    summarise,
)


def test_compensation_ratio_constructed():
    pi = np.array([2.0, 2.0, 2.0, 2.0, 1.0])
    c = np.array([2.0, 1.5, 1.0, 2.5, 0.99])
    zero = np.array([1.0, 1.0, 1.0, 1.0, 1.0])
    # 0 = as PI, 0.5 = half of stiction's cost removed, 1 = frictionless, -0.5 = worse than PI;
    # last loop: no stiction cost (healthy), denominator floored at 0.1 * IAE_0
    assert compensation_ratio(pi, c, zero).tolist() == pytest.approx([0.0, 0.5, 1.0, -0.5, 0.1])
    assert np.isfinite(compensation_ratio([1.0], [1.0], [1.0])).all()
    with pytest.raises(ValueError, match="floor"):
        compensation_ratio(pi, c, zero, floor=0.0)


def test_bootstrap_median_coverage():
    """The 95 % interval covers the true median in about 95 % of samples (exponential data)."""
    rng = np.random.default_rng(0)
    true = np.log(2.0)
    hits = [(lambda e: e.lo <= true <= e.hi)(bootstrap_median(rng.exponential(size=80), n_boot=400, seed=s))
            for s in range(200)]
    assert 0.88 <= np.mean(hits) <= 0.99


def test_bootstrap_deterministic_and_empty():
    x = np.arange(20.0)
    assert bootstrap_mean(x, seed=3) == bootstrap_mean(x, seed=3)
    e = bootstrap_median([], seed=1)
    assert e.n == 0 and np.isnan(e.value)


def _scores(label, iae, travel, n):
    z = np.zeros(n)
    return LoopScores(label, "regulation", z.astype(bool), z, np.full(n, np.inf), np.asarray(iae, float), z,
                      np.asarray(travel, float), z)


def test_summary_and_comparison_within_travel_budget():
    cfg = BenchConfig().quick_version()
    sc = regulation_scenarios(cfg, n=60, seed=1)
    n = sc.n
    rng = np.random.default_rng(2)
    base = 1.0 + rng.random(n)
    scores = {REFERENCE_FRICTIONLESS: _scores(REFERENCE_FRICTIONLESS, base, np.full(n, 10.0), n),
              REFERENCE_PI: _scores(REFERENCE_PI, 2 * base, np.full(n, 2.0), n),
              "cheap": _scores("cheap", 1.8 * base, np.full(n, 3.0), n),       # R = 0.2, in budget
              "wild": _scores("wild", 1.1 * base, np.full(n, 50.0), n),        # R = 0.9, over budget
              "learned": _scores("learned", 1.5 * base, np.full(n, 4.0), n)}   # R = 0.5
    rows = summarise(scores, sc, cfg)
    r = {(x.controller, x.band, x.metric): x.estimate for x in rows}
    assert r[("cheap", "sticky+severe", "R")].value == pytest.approx(0.2)
    assert r[("learned", "healthy", "iae_vs_pi")].value == pytest.approx(0.75)
    assert r[("wild", "sticky", "travel_vs_frictionless")].value == pytest.approx(5.0)
    comp = compare_learned(scores, sc, cfg, ["cheap", "wild", REFERENCE_PI])
    assert comp is not None and comp.best_classical == "cheap" and set(comp.within_budget) == {"cheap", REFERENCE_PI}
    d = comp.difference
    assert d.value == pytest.approx(0.3) and d.lo == pytest.approx(0.3) and d.hi == pytest.approx(0.3)
    assert compare_learned({k: v for k, v in scores.items() if k != "learned"}, sc, cfg, ["cheap"]) is None
