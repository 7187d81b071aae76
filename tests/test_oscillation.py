"""The one oscillation detector (valve_gym.oscillation): each rule's behaviour, and its callers all use it."""
import math

import numpy as np
import pytest
from scipy import signal

from valve_gym.oscillation import BENCHMARK, RULES, SCREEN, STICTION, detect_oscillation


# --------------------------------------------------------------------------- #
# ACF limit-cycle detector (Thornhill 2003 regularity + Miao & Seborg 1999 decay ratio)
# --------------------------------------------------------------------------- #
def _ar2(rng, n, zeta, period, sigma=1.0):
    """A damped second-order response to white noise (damping zeta, natural period [samples])."""
    w = 2 * np.pi / period
    a1, a2 = 2 * np.exp(-zeta * w) * np.cos(w * np.sqrt(1 - zeta**2)), -np.exp(-2 * zeta * w)
    return signal.lfilter([sigma], [1.0, -a1, -a2], rng.standard_normal(n))


def test_benchmark_rule_false_alarm_rates():
    """White noise, a slow OU drift and a damped (zeta = 0.5) loop response: at most a few % false alarms."""
    def rate(make, n=60):
        return np.mean([detect_oscillation(make(np.random.default_rng(s)), 1.0).present for s in range(n)])

    assert rate(lambda g: 0.002 * g.standard_normal(3600)) == 0.0
    assert rate(lambda g: signal.lfilter([1.0], [1.0, -0.98], g.standard_normal(3600))) <= 0.05
    assert rate(lambda g: _ar2(g, 3600, 0.5, 120.0)) <= 0.07
    # ... while a lightly damped one (zeta = 0.05, Miao & Seborg's "excessively oscillatory") fires
    assert rate(lambda g: _ar2(g, 3600, 0.05, 120.0), 20) >= 0.9


@pytest.mark.parametrize("seed", range(4))
def test_benchmark_rule_silent_on_setpoint_step(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(3600.0)
    # error of a PI loop after a 0.2 m step at t = 300 s (closed loop time constant 25 s) plus 2 mm noise
    e = np.where(t >= 300, 0.2 * np.exp(-(t - 300) / 25.0) * (1 + (t - 300) / 25.0), 0.0)
    e = e + 0.002 * rng.standard_normal(t.size)
    assert not detect_oscillation(e, 1.0).present


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("wave", ["sine", "triangle", "square"])
def test_benchmark_rule_fires_on_cycle_with_amplitude_and_period(seed, wave):
    rng = np.random.default_rng(seed)
    T, A = 150.0, 0.01
    t = np.arange(3600.0)
    ph = 2 * np.pi * t / T
    x = {"sine": A * np.sin(ph), "triangle": A * signal.sawtooth(ph, 0.5),
         "square": A * np.sign(np.sin(ph + 0.1))}[wave]
    noisy = x + 0.002 * rng.standard_normal(t.size) + 0.004 * np.sin(2 * np.pi * t / 7200.0)  # noise + slow drift
    osc = detect_oscillation(noisy, 1.0)
    assert osc.present
    assert osc.period_s == pytest.approx(T, rel=0.03)
    assert osc.amplitude == pytest.approx(A, rel=0.12)
    assert osc.regularity > 1.0 and osc.decay_ratio > 0.5


def test_benchmark_rule_fires_on_weakly_damped_but_not_on_damped():
    rng = np.random.default_rng(3)
    # a sustained cycle vs the Miao & Seborg border: decay ratio rises with falling damping
    dr = [detect_oscillation(_ar2(rng, 20000, z, 100.0), 1.0).decay_ratio for z in (0.3, 0.1, 0.02)]
    assert dr[0] < dr[1] < dr[2]
    assert detect_oscillation(_ar2(rng, 20000, 0.01, 100.0), 1.0).present


def test_bad_input_and_quiet_signals():
    with pytest.raises(ValueError, match="dt"):
        detect_oscillation(np.zeros(100), 0.0)
    with pytest.raises(ValueError, match="finite"):
        detect_oscillation([0.0, np.nan] * 20, 1.0)
    with pytest.raises(ValueError, match="max_lag_frac"):
        detect_oscillation(np.zeros(100), 1.0, max_lag_frac=2.0)
    with pytest.raises(ValueError, match="min_crossings"):
        detect_oscillation(np.zeros(100), 1.0, min_crossings=2)
    with pytest.raises(ValueError, match="unknown oscillation rule 'fast'"):
        detect_oscillation(np.zeros(100), 1.0, "fast")
    for x in (np.ones(100), np.zeros(100), np.linspace(0, 5, 100), np.ones(5)):
        o = detect_oscillation(x, 1.0)
        assert not o.present and o.amplitude == 0.0 and math.isnan(o.period_s)




def _sine(n=3600, T=150.0, A=0.01, noise=0.002, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(float(n))
    return A * np.sin(2 * np.pi * t / T) + noise * rng.standard_normal(n)


@pytest.mark.parametrize("rule", list(RULES))
def test_every_rule_finds_a_clear_cycle_and_reads_the_same_period(rule):
    x = _sine()
    o = detect_oscillation(x, 2.0, rule)
    assert o.present and o.rule == rule
    assert o.period_s == pytest.approx(300.0, rel=0.03)          # 150 samples at 2 s
    assert o.period_samples == pytest.approx(150.0, rel=0.03)
    assert o.amplitude == pytest.approx(0.01, rel=0.15)
    assert 1.0 < o.regularity <= 99.0 and o.significant and o.decay_ratio > 0.5


@pytest.mark.parametrize("rule", list(RULES))
def test_no_rule_fires_on_white_noise(rule):
    hits = [detect_oscillation(np.random.default_rng(s).standard_normal(2000), 1.0, rule).present for s in range(20)]
    assert sum(hits) <= 1


def test_rules_differ_where_documented():
    # a cycle of 3.5 samples: regular, but below the screen's and the stiction rule's 4-sample minimum
    t = np.arange(2000.0)
    x = np.sin(2 * np.pi * t / 3.5)
    assert detect_oscillation(x, 1.0, BENCHMARK).present
    assert not detect_oscillation(x, 1.0, SCREEN).present
    assert "samples" in detect_oscillation(x, 1.0, STICTION).reason
    # two and a half cycles: the stiction rule needs 3
    x = np.sin(2 * np.pi * np.arange(250.0) / 100.0)
    o = detect_oscillation(x, 1.0, STICTION)
    assert not o.present


def test_the_result_is_frozen_and_invariant_to_units():
    x = _sine(seed=3)
    a, b = detect_oscillation(x, 1.0), detect_oscillation(x / 1000.0 + 7.0, 1.0)
    assert a.present == b.present and a.period_s == pytest.approx(b.period_s, rel=1e-9)
    assert b.amplitude == pytest.approx(a.amplitude / 1000.0, rel=1e-9)
    with pytest.raises(AttributeError):
        a.present = False  # type: ignore[misc]
