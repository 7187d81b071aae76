"""Tests of valve_gym.metrics: each metric on a signal with a known answer."""
import doctest
import math

import numpy as np
import pytest
from scipy import signal

from valve_gym import metrics
from valve_gym.metrics import (
    CREST_FACTORS,
    LOOP_METRIC_KEYS,
    crest_factor,
    error_std,
    hagglund_oscillation,
    iae,
    ise,
    loop_metrics,
    reversals,
    reversals_per_hour,
    travel,
    waveform_shape,
)


def sine(A, T, dt, n_periods, phase=0.3):
    t = np.arange(0.0, n_periods * T, dt)
    return t, A * np.sin(2 * np.pi * t / T + phase)


# --------------------------------------------------------------------------- #
# Integral criteria
# --------------------------------------------------------------------------- #
def test_iae_ise_std_of_constant():
    e = np.full(50, -2.0)
    assert iae(e, 0.1) == pytest.approx(2.0 * 50 * 0.1, rel=1e-12)
    assert ise(e, 0.1) == pytest.approx(4.0 * 50 * 0.1, rel=1e-12)
    assert error_std(e) == 0.0


def test_iae_of_sine_is_4A_over_omega_per_period():
    A, T, dt, n = 2.0, 5.0, 1e-3, 4
    _, e = sine(A, T, dt, n)
    omega = 2 * np.pi / T
    assert iae(e, dt) == pytest.approx(n * 4 * A / omega, rel=1e-5)


def test_ise_and_std_of_sine():
    A, T, dt, n = 3.0, 5.0, 1e-2, 4
    _, e = sine(A, T, dt, n)
    # mean of A^2 sin^2 over whole periods is A^2/2 (exact for uniform sampling)
    assert ise(e, dt) == pytest.approx(A**2 / 2 * n * T, rel=1e-9)
    assert error_std(e) == pytest.approx(A / math.sqrt(2), rel=1e-9)


def test_integrals_return_python_floats():
    for v in (iae([1, 2], 1.0), ise([1, 2], 1.0), error_std([1, 2])):
        assert type(v) is float


# --------------------------------------------------------------------------- #
# Crest factor / waveform shape
# --------------------------------------------------------------------------- #
T_WAVE = np.arange(0.0, 40.0, 0.01)


@pytest.mark.parametrize("name, x", [
    ("square", np.where((T_WAVE % 10.0) < 5.0, 1.0, -1.0) + 4.0),
    ("sine", 2.0 * np.sin(2 * np.pi * T_WAVE / 10.0) - 1.0),
    ("triangle", signal.sawtooth(2 * np.pi * T_WAVE / 10.0, 0.5)),
])
def test_crest_factor_and_shape(name, x):
    assert crest_factor(x) == pytest.approx(CREST_FACTORS[name], rel=2e-3)
    assert waveform_shape(x) == name


def test_crest_factor_exact_values():
    assert CREST_FACTORS == pytest.approx(
        {"square": 1.0, "sine": 1.41421356, "triangle": 1.7320508})
    assert crest_factor([2.0, 0.0, 2.0, 0.0]) == 1.0


def test_flat_signal_shape_none():
    assert crest_factor(np.full(20, 0.3)) == 0.0
    assert waveform_shape(np.full(20, 0.3)) == "none"
    assert waveform_shape(np.zeros(20)) == "none"


def test_waveform_shape_tol():
    noise = np.random.default_rng(0).standard_normal(5000)  # crest ~ 3.5 to 4
    assert waveform_shape(noise) == "triangle"             # nearest, by definition
    assert waveform_shape(noise, tol=0.15) == "none"


# --------------------------------------------------------------------------- #
# Hägglund
# --------------------------------------------------------------------------- #
def test_hagglund_sustained_oscillation_raises_alarm():
    # amplitude 2 % of span > a = 1 %, period 10 s, 200 s of data.
    # Crossings at t_k = (k*pi - 0.3)/omega = 5k - 0.477 s, k = 1..40:
    # 40 crossings -> 39 complete half periods, each with IAE = 2A/omega > 2a/omega.
    t, e = sine(0.02, 10.0, 0.01, 20)
    res = hagglund_oscillation(e, 0.01, span=1.0)
    assert res.omega_u == pytest.approx(2 * np.pi / 10.0, rel=1e-3)
    assert res.iae_lim == pytest.approx(2 * 0.01 / (2 * np.pi / 10.0), rel=1e-3)
    assert res.t_sup == pytest.approx(500.0, rel=1e-3)
    assert res.n_detections == 39
    expected_t = (np.arange(2, 41) * np.pi - 0.3) / (2 * np.pi / 10.0)
    np.testing.assert_allclose(res.detection_times, expected_t, atol=1e-3)
    assert res.alarm and res.n_alarms == 1 and res.max_count == 39


def test_hagglund_small_oscillation_no_alarm():
    t, e = sine(0.005, 10.0, 0.01, 20)                 # 0.5 % < a = 1 %
    res = hagglund_oscillation(e, 0.01, span=1.0)
    assert res.n_detections == 0 and not res.alarm and res.n_alarms == 0
    assert res.detection_times.shape == (0,)


def test_hagglund_sliding_window_count():
    # detections every 5 s; a window of 52 s holds 11 of them (> 10), 48 s only 10
    t, e = sine(2.0, 10.0, 0.01, 20)
    w = 2 * np.pi / 10.0
    assert hagglund_oscillation(e, 0.01, a=1.0, omega_u=w, t_sup=52.0).alarm
    res = hagglund_oscillation(e, 0.01, a=1.0, omega_u=w, t_sup=48.0)
    assert res.n_detections == 39 and res.max_count == 10 and not res.alarm
    # a explicit and larger than the amplitude: nothing detected
    assert hagglund_oscillation(e, 0.01, a=2.5, omega_u=w).n_detections == 0


def test_hagglund_single_load_disturbance():
    # one negative lobe of area 5 between two sign changes: exactly one detection
    dt = 0.1
    e = np.concatenate([np.full(100, 0.01), np.full(50, -1.0), np.full(100, 0.01)])
    res = hagglund_oscillation(e, dt, a=0.01, omega_u=0.1)   # IAE_lim = 0.2
    assert res.n_detections == 1 and not res.alarm
    assert res.detection_times[0] == pytest.approx(15.0, abs=dt)


def test_hagglund_needs_omega_u_without_limit_cycle():
    with pytest.raises(ValueError, match="omega_u"):
        hagglund_oscillation(np.random.default_rng(0).standard_normal(500), 0.1)


# --------------------------------------------------------------------------- #
# Travel and reversals
# --------------------------------------------------------------------------- #
def test_travel():
    assert travel([0.0, 1.0, 0.0, 2.0, 2.0, -1.0]) == 7.0
    assert travel([5.0, 5.0, 5.0]) == 0.0


def test_reversals_exact():
    assert reversals([0, 1, 0, 1, 0]) == 3
    assert reversals([0, 1, 1, 1, 0]) == 1          # flat stretches are skipped
    assert reversals([0, 1, 2, 3]) == 0
    assert reversals([3, 3, 3]) == 0
    x = [0.0, 1.0, 0.8, 2.0, 1.5, 1.7, 0.0]
    assert reversals(x) == 5
    assert reversals(x, deadband=0.3) == 1         # 0.2 dips are inside the band


def test_reversals_deadband_is_strict():
    x = [0.0, 1.0, 0.5, 1.0]                        # moves of exactly 0.5
    assert reversals(x, deadband=0.5) == 0
    assert reversals(x, deadband=0.49) == 2


def test_reversals_deadband_hides_chatter():
    # up 0 -> 3, down 3 -> 0, up 0 -> 2, with 0.1 dips/bumps on the way
    x = [0.0, 1.0, 0.9, 2.0, 1.9, 3.0, 2.0, 1.0, 1.1, 0.0, 0.1, 1.0, 2.0]
    assert reversals(x, deadband=0.5) == 2
    assert reversals(x, deadband=0.05) == 8
    assert reversals(x) == 8


def test_reversals_deadband_zero_matches_loop():
    # the vectorised deadband=0 path and the hysteresis loop agree
    x = np.round(np.random.default_rng(3).standard_normal(500), 1)
    assert metrics._reversals(x, 0.0) == metrics._reversals(x, 1e-12)


def test_reversals_per_hour():
    assert reversals_per_hour([0.0, 1.0, 0.0, 1.0, 0.0], dt=900.0) == 3.0
    assert reversals_per_hour([0.0, 1.0, 0.0, 1.0, 0.0], dt=1.0) == 3.0 * 900.0


# --------------------------------------------------------------------------- #
# loop_metrics
# --------------------------------------------------------------------------- #
def stiction_loop():
    t = np.arange(0.0, 600.0, 0.5)
    sp = 50.0
    pv = 50.0 + 2.0 * np.sign(np.sin(2 * np.pi * t / 60.0 + 0.1))   # square pv
    op = 40.0 + 5.0 * signal.sawtooth(2 * np.pi * t / 60.0, 0.5)     # triangle op
    mv = 40.0 + 5.0 * np.sign(np.sin(2 * np.pi * t / 60.0 + 0.1))   # jumping stem
    return t, sp, pv, op, mv


def test_loop_metrics_values():
    t, sp, pv, op, mv = stiction_loop()
    m = loop_metrics(t, sp, pv, op, mv, span=100.0)
    assert tuple(m) == LOOP_METRIC_KEYS
    assert all(type(v) is float and not math.isnan(v) for v in m.values())
    assert m["iae"] == pytest.approx(2.0 * 600.0)
    assert m["ise"] == pytest.approx(4.0 * 600.0)
    assert m["error_std"] == pytest.approx(2.0, rel=1e-3)
    assert m["lc_present"] == 1.0
    # the detector's window amplitude of the least-squares-detrended square wave (10 periods): within 1 %
    assert m["lc_amplitude"] == pytest.approx(2.0, rel=1e-2)
    assert m["lc_period"] == pytest.approx(60.0, rel=3e-3)     # from the ACF zero crossings
    assert m["crest_factor"] == pytest.approx(1.0, rel=1e-3)
    # pv flips at t_k = 30 k - 0.955 s, k = 1..20 (20 flips in 600 s):
    # 19 complete half periods, each with IAE 60 > IAE_lim = 2*1/(2 pi/60) = 19.1
    # (2 % of span > a = 1 %), all inside T_sup = 3000 s: one alarm episode
    assert m["hagglund_detections"] == 19.0 and m["hagglund_alarms"] == 1.0
    # op: triangle of amplitude 5 -> 20 per period; extremes at 30, 60, ..., 570 s
    assert m["op_travel"] == pytest.approx(10 * 20.0, rel=1e-3)
    assert m["op_reversals_per_hour"] == pytest.approx(19 * 3600 / 599.5, rel=1e-12)
    # mv: 20 jumps of 10, alternating
    assert m["valve_travel"] == pytest.approx(200.0, rel=1e-12)
    assert m["valve_reversals_per_hour"] == pytest.approx(19 * 3600 / 599.5, rel=1e-12)


def test_loop_metrics_dt_equals_time_vector_and_no_mv():
    t, sp, pv, op, mv = stiction_loop()
    a = loop_metrics(t, np.full(t.size, sp), pv, op, mv)
    b = loop_metrics(0.5, sp, pv, op, mv)
    assert a == b
    c = loop_metrics(0.5, sp, pv, op)
    assert "valve_travel" not in c and tuple(c) == LOOP_METRIC_KEYS[:-2]


def test_loop_metrics_quiet_loop():
    pv = np.full(100, 3.0)
    m = loop_metrics(1.0, 3.0, pv, np.full(100, 20.0), span=10.0)
    assert m["iae"] == 0.0 and m["lc_present"] == 0.0
    assert m["lc_period"] == math.inf and m["lc_amplitude"] == 0.0
    assert m["crest_factor"] == 0.0 and m["hagglund_alarms"] == 0.0
    assert m["op_travel"] == 0.0 and m["op_reversals_per_hour"] == 0.0


# --------------------------------------------------------------------------- #
# Bad input
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("fn", [
    lambda x: iae(x, 0.1), lambda x: ise(x, 0.1), error_std,
    crest_factor, waveform_shape,
    lambda x: hagglund_oscillation(x, 0.1, omega_u=1.0), travel, reversals,
    lambda x: reversals_per_hour(x, 0.1),
])
def test_bad_signals(fn):
    with pytest.raises(ValueError, match=r"1-D array.*shape \(2, 3\)"):
        fn(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="at least 2 samples, got 1"):
        fn([1.0])
    with pytest.raises(ValueError, match=r"non-finite.*index 1"):
        fn([0.0, np.nan, 1.0])
    with pytest.raises(ValueError, match="non-finite"):
        fn([0.0, 1.0, np.inf])
    with pytest.raises(ValueError, match="real numbers"):
        fn(["a", "b"])


@pytest.mark.parametrize("dt", [0.0, -0.1, np.nan, np.inf, [0.1, 0.2], True])
def test_bad_dt(dt):
    for fn in (iae, ise, reversals_per_hour):
        with pytest.raises(ValueError, match="dt"):
            fn([0.0, 1.0, 0.0], dt)


def test_bad_parameters():
    x = np.sin(np.arange(200) / 5)
    with pytest.raises(ValueError, match="deadband"):
        reversals(x, deadband=-1.0)
    with pytest.raises(ValueError, match="omega_u"):
        hagglund_oscillation(x, 0.1, omega_u=0.0)
    with pytest.raises(ValueError, match="`a`"):
        hagglund_oscillation(x, 0.1, a=-1.0, omega_u=1.0)
    with pytest.raises(ValueError, match="t_sup"):
        hagglund_oscillation(x, 0.1, omega_u=1.0, t_sup=0.0)
    with pytest.raises(ValueError, match="n_lim"):
        hagglund_oscillation(x, 0.1, omega_u=1.0, n_lim=-1)
    with pytest.raises(ValueError, match="tol"):
        waveform_shape(x, tol=-1)


def test_loop_metrics_bad_input():
    t, sp, pv, op, mv = stiction_loop()
    with pytest.raises(ValueError, match=r"`op` has 1199 samples but `pv` has 1200"):
        loop_metrics(t, sp, pv, op[:-1])
    with pytest.raises(ValueError, match="`mv` has"):
        loop_metrics(t, sp, pv, op, mv[1:])
    with pytest.raises(ValueError, match="`sp` has"):
        loop_metrics(t, pv[:-2], pv, op)
    with pytest.raises(ValueError, match="`t_or_dt` has 1199 time stamps"):
        loop_metrics(t[:-1], sp, pv, op)
    t_bad = t.copy()
    t_bad[10] += 0.2
    with pytest.raises(ValueError, match="not uniformly sampled"):
        loop_metrics(t_bad, sp, pv, op)
    with pytest.raises(ValueError, match="strictly increasing"):
        loop_metrics(t[::-1], sp, pv, op)
    with pytest.raises(ValueError, match="t_or_dt"):
        loop_metrics(-1.0, sp, pv, op)
    with pytest.raises(ValueError, match="span"):
        loop_metrics(0.5, sp, pv, op, span=0.0)
    with pytest.raises(ValueError, match="`sp`"):
        loop_metrics(0.5, np.nan, pv, op)
    pv_nan = pv.copy()
    pv_nan[5] = np.nan
    with pytest.raises(ValueError, match=r"`pv` contains 1 non-finite"):
        loop_metrics(0.5, sp, pv_nan, op)


# --------------------------------------------------------------------------- #
# The docstring examples run and are right
# --------------------------------------------------------------------------- #
def test_docstring_examples():
    res = doctest.testmod(metrics, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.attempted > 10 and res.failed == 0


@pytest.mark.parametrize("deadband", [0.0, 0.05, 0.3])
def test_reversal_counts_match_reversals(deadband):
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.standard_normal((400, 7)), axis=0) * 0.1
    x[50:80, 2] = x[50, 2]  # a flat stretch
    got = metrics.reversal_counts(x, deadband)
    assert got.tolist() == [reversals(x[:, i], deadband) for i in range(7)]
    with pytest.raises(ValueError, match=r"\(T, n\)"):
        metrics.reversal_counts(x[:, 0])
