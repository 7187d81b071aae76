"""Tests of valve_gym.diagnosis.locate: regions, conditions, residual tests."""
from __future__ import annotations

import numpy as np

from valve_gym.diagnosis.locate import apparent_band, condition_masks, dominant_period, locate_mismatch, op_reversals


def test_region_found_where_the_model_misses():
    rng = np.random.default_rng(0)
    t = np.arange(2000.0)
    y = np.sin(t / 50) + 0.01 * rng.normal(size=t.size)
    ys = y.copy()
    ys[800:950] += 0.3                      # the model misses from 800 s to 950 s
    rep = locate_mismatch(t, 0.5 + 0.1 * np.sin(t / 50), y, ys)
    assert rep.regions, "no region found"
    r = rep.regions[0]
    assert 780 <= r.t_start <= 810 and 940 <= r.t_end <= 975
    assert r.share_sse > 0.9
    assert not rep.tests.white


def test_white_residual_is_white_and_has_no_region():
    rng = np.random.default_rng(1)
    t = np.arange(3000.0)
    y = rng.normal(size=t.size)
    rep = locate_mismatch(t, 0.5 + 0.1 * np.sin(t / 40), y, np.zeros_like(y))
    assert rep.tests.white
    assert rep.tests.ljung_box_p > 0.05
    assert rep.tests.acf_outside < 0.15
    assert abs(rep.tests.acf_bound - 1.96 / np.sqrt(t.size)) < 1e-12
    assert rep.regions == [] or sum(r.share_sse for r in rep.regions) < 0.2


def test_condition_statistics_point_at_high_level():
    rng = np.random.default_rng(2)
    t = np.arange(3000.0)
    y = np.sin(t / 100)
    r = 0.01 * rng.normal(size=t.size)
    r[y > 0.9] += 0.2                      # misses only when the level is high
    rep = locate_mismatch(t, 0.5 + 0.2 * y, y + r, y)
    c = rep.condition("pv_high")
    assert c is not None and c.significant and c.ratio > 3


def test_input_cross_correlation_peak_at_the_delay():
    rng = np.random.default_rng(3)
    T = 4000
    u = rng.normal(size=T)
    r = np.roll(u, 5) * 0.5 + 0.1 * rng.normal(size=T)   # residual follows the input 5 samples later
    rep = locate_mismatch(np.arange(T, dtype=float), 0.5 + 0.05 * u, r, np.zeros(T))
    assert rep.tests.ccf_peak_lag == 5
    assert rep.tests.ccf_peak > 5 * rep.tests.ccf_bound


def test_op_reversals_and_masks():
    u = 0.5 + 0.1 * np.sin(np.arange(400) / 10)
    rev = op_reversals(u)
    assert len(rev) >= 10
    m = condition_masks(u, u, dt=1.0, window=5)
    assert {"op_rising", "op_falling", "near_op_reversal", "pv_high"} <= set(m)


def test_dominant_period():
    t = np.arange(5000.0)
    assert abs(dominant_period(np.sin(2 * np.pi * t / 120), 1.0) - 120) < 2


def test_apparent_band_of_a_backlash():
    u = 0.5 + 0.05 * np.sin(np.arange(2000) / 20)
    b, x, h = 0.02, 0.5, np.empty(2000)
    for k in range(2000):
        x = min(max(x, u[k] - b / 2), u[k] + b / 2)
        h[k] = x
    out = apparent_band(u, h)
    assert abs(out["band"] - b) < 0.002
    assert out["stuck_through"] == 0
