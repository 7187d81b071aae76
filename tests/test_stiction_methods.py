"""Each stiction method on signals whose answer is known (fast, no model fits)."""
import numpy as np
import pytest

from valve_gym.diagnosis.stiction import oscillation
from valve_gym.diagnosis.stiction.bicoherence import bicoherence, bicoherence_evidence
from valve_gym.diagnosis.stiction.ellipse import apparent_stiction, ellipse_evidence, ellipse_size, fit_ellipse
from valve_gym.diagnosis.stiction.episodes import episodes_evidence
from valve_gym.diagnosis.stiction.horch import horch_evidence
from valve_gym.diagnosis.stiction.waveform import stiction_shape_index, waveform_evidence


def _tri(t, period):
    ph = (t / period) % 1.0
    return 4 * np.abs(ph - 0.5) - 1


def test_oscillation_period_and_regularity():
    t = np.arange(2000.0)
    rng = np.random.default_rng(0)
    o = oscillation(np.sin(2 * np.pi * t / 50) + 0.1 * rng.normal(size=t.size))
    assert o.present and abs(o.period_samples - 50) < 2 and o.regularity > 1
    assert not oscillation(rng.normal(size=2000)).present
    assert not oscillation(np.ones(100)).present


def test_ellipse_recovers_phase_chord():
    t = np.arange(1000.0)
    phi = 0.7
    op = 0.5 + 0.02 * np.sin(2 * np.pi * t / 80)
    pv = 3.0 * np.sin(2 * np.pi * t / 80 - phi)
    e = fit_ellipse(op, pv)
    assert e is not None and abs(e.x0 - 0.5) < 1e-3
    assert apparent_stiction(e) == pytest.approx(2 * 0.02 * np.sin(phi), rel=1e-3)
    ev = ellipse_evidence(op, pv)
    assert ev.applicable and ev.value == pytest.approx(np.sin(phi), abs=0.05)
    assert ev.details["S_lo"] <= ev.details["S_app"] <= ev.details["S_hi"]
    assert fit_ellipse(np.arange(10.0), 2 * np.arange(10.0)) is None      # a line is no ellipse
    d = ev.details
    assert (d["S_est"], d["S_est_lo"], d["S_est_hi"]) == pytest.approx(ellipse_size(d["S_app"], d["S_lo"], d["S_hi"]))
    assert d["S_est_lo"] <= d["S_est"] <= d["S_est_hi"]


def test_ellipse_size_scales_and_widens_on_the_log_scale():
    assert ellipse_size(0.02, 0.015, 0.025, scale=1.0, discrepancy=0.0) == pytest.approx((0.02, 0.015, 0.025))
    s, lo, hi = ellipse_size(0.02, 0.015, 0.025, scale=2.0, discrepancy=np.log(1.5))
    assert (s, lo, hi) == pytest.approx((0.04, 0.03 / 1.5, 0.05 * 1.5))


def test_waveform_triangle_vs_sine():
    t = np.arange(3000.0)
    assert stiction_shape_index(_tri(t, 100), 100)[0] > 0.6
    assert stiction_shape_index(np.sin(2 * np.pi * t / 100), 100)[0] < 0.4
    rng = np.random.default_rng(1)
    ev = waveform_evidence(_tri(t, 100), np.sin(2 * np.pi * t / 100), plant="first_order")
    assert ev.verdict == "stiction" and ev.reliability > 0.5
    assert waveform_evidence(rng.normal(size=500), rng.normal(size=500)).verdict == "not applicable"


def test_horch_self_regulating_and_integrating():
    t = np.arange(3000.0)
    sq = np.sign(np.sin(2 * np.pi * t / 100))
    h = horch_evidence(np.cumsum(sq) / 50, sq, plant="first_order")     # OP integrates the PV's square wave
    assert h.applicable and h.value > 0.9 and h.verdict == "stiction"
    level = np.cumsum(sq) / 50                                           # integrating: triangular level
    hi = horch_evidence(-level, level, plant="integrating")
    assert hi.verdict == "stiction" and hi.value > 0.8
    hs = horch_evidence(-np.sin(2 * np.pi * t / 100), np.sin(2 * np.pi * t / 100), plant="integrating")
    assert hs.verdict != "stiction" and hs.value < 0.7


def test_bicoherence_gaussian_vs_phase_coupled():
    rng = np.random.default_rng(2)
    n = 4096
    g = rng.normal(size=n)
    b2, crit = bicoherence(g, 64)
    assert np.mean(b2 > crit) < 0.15                                     # ~5 % false alarms
    t = np.arange(n)
    f1, f2 = 5 / 64, 9 / 64
    p1, p2 = rng.uniform(0, 2 * np.pi, 2)
    x = (np.cos(2 * np.pi * f1 * t + p1) + np.cos(2 * np.pi * f2 * t + p2)
         + np.cos(2 * np.pi * (f1 + f2) * t + p1 + p2) + 0.3 * rng.normal(size=n))
    b2c, _ = bicoherence(x, 64)
    assert b2c.max() > 0.8
    ev = bicoherence_evidence(np.zeros(n) + 0.5 + 0.01 * g, g)
    assert ev.verdict == "no stiction"


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="same length"):
        horch_evidence(np.ones(50), np.ones(49))
    with pytest.raises(ValueError, match="NaN"):
        waveform_evidence(np.r_[np.ones(49), np.nan], np.ones(50))
    with pytest.raises(ValueError, match="at least 20"):
        ellipse_evidence(np.ones(5), np.ones(5))


def test_stick_episodes_vs_regulation():
    rng = np.random.default_rng(3)
    n = 720
    # stuck valve: the PV sits 1 below the set point while the integral action ramps the OP,
    # then the valve breaks away and the PV jumps to the set point (repeated 3 times)
    op, pv = np.empty(n), np.empty(n)
    for k in range(3):
        s = slice(240 * k, 240 * k + 200)
        op[s] = 0.4 + 0.0005 * np.arange(200)
        pv[s] = 9.0
        op[240 * k + 200:240 * (k + 1)] = 0.5
        pv[240 * k + 200:240 * (k + 1)] = 10.0
    pv = pv + 0.02 * rng.normal(size=n)
    ev = episodes_evidence(op, pv, sp=np.full(n, 10.0))
    assert ev.applicable and ev.value > 0.8
    # a working valve: the OP counters a load while the PV stays at the set point
    load = np.cumsum(rng.normal(size=n)) * 0.002
    ok = episodes_evidence(0.5 + load, 10.0 + 0.02 * rng.normal(size=n), sp=np.full(n, 10.0))
    assert not ok.applicable or ok.value < 0.3


def test_regime_oscillating_loop_silences_the_episode_feature():
    from valve_gym.diagnosis.stiction import FEATURES, model_free_evidence
    from valve_gym.diagnosis.stiction.combine import features
    rng = np.random.default_rng(5)
    n = 1200
    t = np.arange(n, dtype=float)
    # a regular limit cycle: triangular OP, square-ish PV a quarter period later
    op = 0.5 + 0.03 * _tri(t, 60.0) + 0.001 * rng.normal(size=n)
    pv = 10.0 + np.sign(np.sin(2 * np.pi * (t - 15) / 60.0)) + 0.02 * rng.normal(size=n)
    ev = model_free_evidence(op, pv, 1.0, "first_order", np.full(n, 10.0))
    ep = next(e for e in ev if e.method == "episodes")
    assert ep.details["regular_oscillation"] == 1.0
    f = dict(zip(FEATURES, features(ev, "first_order")))
    assert f["oscillating"] == 1.0 and f["episodes"] == 0.0      # the cycle is read by the shape methods
    # no oscillation: a stuck valve's ramp episodes are read, the regime flag is 0
    op2 = np.concatenate([0.4 + 0.0005 * np.arange(400), np.full(200, 0.6), 0.6 - 0.0005 * np.arange(600)])
    pv2 = np.concatenate([np.full(400, 9.0), np.full(200, 10.0), np.full(600, 11.0)]) + 0.02 * rng.normal(size=n)
    ev2 = model_free_evidence(op2, pv2, 1.0, "first_order", np.full(n, 10.0))
    f2 = dict(zip(FEATURES, features(ev2, "first_order")))
    assert f2["oscillating"] == 0.0 and f2["episodes"] > 0.3
