"""Horch's cross-correlation stiction test on signals whose answer is known."""
from __future__ import annotations

import numpy as np

from valve_gym.diagnosis.indices import horch_ccf

T = np.arange(2000.0)
W = 2 * np.pi / 200.0


def test_odd_correlation_is_stiction():
    # stick-slip limit cycle: square-ish output, the process integrates it (triangle PV, a quarter period late)
    op = np.sign(np.sin(W * T))
    pv = np.cumsum(op) * 0.01
    h = horch_ccf(op, pv, dt=2.0)
    assert h["verdict"] == "stiction" and h["phase_index"] > 0.9
    assert abs(h["ccf_at_zero"]) < 0.1
    assert min(h["tau_left_s"], h["tau_right_s"]) < 10 and max(h["tau_left_s"], h["tau_right_s"]) > 80


def test_even_correlation_is_not_stiction():
    # aggressive tuning / external disturbance: output and PV in counter-phase
    rng = np.random.default_rng(0)
    op = np.sin(W * T) + 0.1 * rng.normal(size=T.size)
    pv = -np.sin(W * T) + 0.1 * rng.normal(size=T.size)
    h = horch_ccf(op, pv)
    assert h["verdict"] == "no stiction" and h["phase_index"] < 0.1
    assert h["ccf_at_zero"] < -0.9
    assert abs(h["tau_left_s"] - 50) < 3 and abs(h["tau_right_s"] - 50) < 3   # a quarter of the 200 s period


def test_out_of_scope_and_uninformative_records():
    rng = np.random.default_rng(1)
    op, pv = np.sign(np.sin(W * T)), np.cumsum(np.sign(np.sin(W * T)))
    assert horch_ccf(op, pv, plant="integrating")["verdict"] == "not applicable"
    assert horch_ccf(np.ones(500), rng.normal(size=500))["verdict"] == "undetermined"
    h = horch_ccf(rng.normal(size=3000), rng.normal(size=3000))
    assert h["verdict"] == "undetermined" and ("correlation" in h["reason"] or "oscillation" in h["reason"])
    h = horch_ccf(op[:10], pv[:10])
    assert h["verdict"] == "undetermined" and "too short" in h["reason"]


def test_white_noise_never_gives_a_verdict():
    rng = np.random.default_rng(2)
    verdicts = [horch_ccf(rng.normal(size=1500), rng.normal(size=1500))["verdict"] for _ in range(30)]
    assert verdicts.count("undetermined") >= 28, verdicts


def test_a_ramp_is_not_an_oscillation_and_bad_input_is_named():
    import pytest

    t = np.arange(600.0)
    h = horch_ccf(np.linspace(0.2, 0.7, 600), np.sin(2 * np.pi * t / 60))
    assert h["verdict"] == "undetermined" and "ramp" in h["reason"]
    op = np.sign(np.sin(2 * np.pi * t / 60))
    with pytest.raises(ValueError, match="same length"):
        horch_ccf(op, op[:-1])
    with pytest.raises(ValueError, match="NaN"):
        horch_ccf(np.r_[op[:-1], np.nan], op)
    with pytest.raises(ValueError, match="max_lag"):
        horch_ccf(op, op, max_lag=600)
    with pytest.raises(ValueError, match="dt"):
        horch_ccf(op, op, dt=0.0)


def test_quarter_period_shift_is_odd_even_with_a_zero_at_lag_zero(monkeypatch):
    # a pure quarter-period shift of a sine: the CCF is odd, zero (to round-off) at lag 0
    t = np.arange(1200.0)
    op = np.sin(2 * np.pi * t / 40)
    pv = np.cos(2 * np.pi * t / 40)
    h = horch_ccf(op, pv)
    assert h["verdict"] == "stiction" and h["phase_index"] > 0.9
    # the same with the lag-0 value made exactly zero: it is one crossing, not two
    from valve_gym.diagnosis import indices

    real = indices._ccf

    def exact_zero(*a):
        lags, c = real(*a)
        c = c.copy()
        c[len(c) // 2] = 0.0
        return lags, c

    monkeypatch.setattr(indices, "_ccf", exact_zero)
    h = horch_ccf(op, pv)
    assert h["verdict"] == "stiction" and h["phase_index"] > 0.9
