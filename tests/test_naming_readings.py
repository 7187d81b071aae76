"""The noise-model readings of ``benchmarks/naming_readings.py`` compute what their docstrings say."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.diagnosis.select import SelectionRule


@pytest.fixture(scope="module")
def nr(repo_module):
    return repo_module("benchmarks/naming_readings.py", "naming_readings")


def test_kalman_likelihood_is_the_dense_gaussian_one(nr):
    """``-2 log L`` with the scale profiled out, against the covariance written out: a stationary AR(1)
    state (pole rho, innovation variance lam) plus unit white noise."""
    rng = np.random.default_rng(3)
    n = 40
    r = np.cumsum(rng.normal(size=n)) * 0.3 + rng.normal(size=n)
    for rho, lam in ((0.0, 0.5), (0.9, 0.2), (0.995, 3.0)):
        lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        C = lam / (1.0 - rho ** 2) * rho ** lag + np.eye(n)
        q = float(r @ np.linalg.solve(C, r))
        dense = n * np.log(q / n) + np.linalg.slogdet(C)[1]
        assert abs(nr.kalman_m2ll(r, rho, lam) - dense) < 1e-8 * max(1.0, abs(dense))


def test_ar_filter_returns_the_innovations_of_an_ar_process(nr):
    rng = np.random.default_rng(0)
    e = rng.normal(size=500)
    x = np.zeros(500)
    for t in range(2, 500):
        x[t] = 1.2 * x[t - 1] - 0.5 * x[t - 2] + e[t]
    assert np.allclose(nr.ar_filter(x, np.array([1.2, -0.5])), e[2:])
    assert np.allclose(nr.ar_fit(x, 2), [1.2, -0.5], atol=0.1)


def test_the_decision_is_the_selection_rule(nr):
    """A candidate wins when the criterion falls past the margin, the held-out test passes for its size
    and its band governs the loop; the lowest criterion among those wins; none when nothing pays."""
    rule = SelectionRule()
    rows = [("leak", -10.0, -0.2, 1, True),              # pays
            ("slip_jump", -30.0, -0.01, 0, True),        # a swap: any held-out fall pays, lower criterion
            ("overflow", -50.0, -0.05, 2, True)]         # adds parameters: a 5 % held-out fall is not enough
    assert nr._decide(rows, rule) == "slip_jump"
    assert nr._decide([("slip_jump", -30.0, -0.01, 0, False)] + rows[:1], rule) == "leak"   # band too small
    assert nr._decide([("leak", -1.0, -0.5, 1, True), ("overflow", -50.0, 0.01, 2, True)], rule) == "none"


def test_block_wins_counts_the_blocks_where_the_candidate_fits_better(nr):
    base = np.ones(60)
    cand = np.ones(60)
    cand[:20] = 0.5                                   # better in the first third only
    assert nr.block_wins(base, cand, 6) == 2
    assert nr.block_wins(base, cand, 3) == 1
    assert nr.block_wins(base, base, 6) == 0          # equal is not better
    assert nr.block_wins(base, np.zeros(60), 9) == 9
