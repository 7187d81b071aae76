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
    limit_cycle,
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
# Limit cycle
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_limit_cycle_recovers_sine_with_noise(seed):
    # A = 1.5, T = 8 s, 160 samples per period, noise std 5 % of A.
    # Tolerances: amplitude 5 %, period 1 %.
    rng = np.random.default_rng(seed)
    A, T, dt = 1.5, 8.0, 0.05
    t, e = sine(A, T, dt, 15, phase=rng.uniform(0, 2 * np.pi))
    e = e + 0.05 * A * rng.standard_normal(e.size)
    lc = limit_cycle(e, dt)
    assert lc.present
    assert lc.amplitude == pytest.approx(A, rel=0.05)
    assert lc.period == pytest.approx(T, rel=0.01)
    assert lc.n_cycles in (14, 15)
    assert lc.regularity > 1.0


def test_limit_cycle_with_offset_and_drift():
    # the linear detrend removes a ramp; a clean sine gives an accurate result
    A, T, dt = 2.0, 20.0, 0.1
    t, e = sine(A, T, dt, 10)
    lc = limit_cycle(e + 5.0 + 0.01 * t, dt)
    assert lc.present
    assert lc.amplitude == pytest.approx(A, rel=0.005)
    assert lc.period == pytest.approx(T, rel=0.001)


def test_limit_cycle_square_and_triangle_amplitude():
    t = np.arange(0.0, 200.0, 0.1)
    sq = 3.0 * np.sign(np.sin(2 * np.pi * t / 20 + 0.2))
    tri = 3.0 * signal.sawtooth(2 * np.pi * t / 20 + 0.2, 0.5)
    for x in (sq, tri):
        lc = limit_cycle(x, 0.1)
        assert lc.present
        assert lc.amplitude == pytest.approx(3.0, rel=0.01)
        assert lc.period == pytest.approx(20.0, rel=1e-3)


def test_no_limit_cycle_on_white_noise():
    for seed in range(5):
        e = np.random.default_rng(seed).standard_normal(3000)
        lc = limit_cycle(e, 0.1)
        assert not lc.present
        assert lc.amplitude == 0.0 and lc.period == math.inf
        assert lc.regularity < 1.0


@pytest.mark.parametrize("x", [np.full(100, 3.7), np.zeros(100), np.linspace(0, 5, 100)])
def test_no_limit_cycle_on_constant_or_ramp(x):
    lc = limit_cycle(x, 0.5)
    assert lc == (False, 0.0, math.inf, 0, 0.0)


def test_limit_cycle_min_cycles():
    _, e = sine(1.0, 10.0, 0.1, 3.5)          # 6 or 7 crossings: 3 whole cycles
    assert limit_cycle(e, 0.1, min_cycles=3).present
    lc = limit_cycle(e, 0.1, min_cycles=4)
    assert not lc.present and lc.n_cycles == 3 and lc.period == math.inf


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
    assert m["lc_amplitude"] == pytest.approx(2.0, rel=1e-3)
    assert m["lc_period"] == pytest.approx(60.0, rel=1e-3)
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
    lambda x: limit_cycle(x, 0.1), crest_factor, waveform_shape,
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
    for fn in (iae, ise, limit_cycle, reversals_per_hour):
        with pytest.raises(ValueError, match="dt"):
            fn([0.0, 1.0, 0.0], dt)


def test_bad_parameters():
    x = np.sin(np.arange(200) / 5)
    with pytest.raises(ValueError, match="min_cycles"):
        limit_cycle(x, 0.1, min_cycles=0)
    with pytest.raises(ValueError, match="detrend"):
        limit_cycle(x, 0.1, detrend="quadratic")
    with pytest.raises(ValueError, match="hysteresis"):
        limit_cycle(x, 0.1, hysteresis=-0.1)
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


# --------------------------------------------------------------------------- #
# ACF limit-cycle detector (Thornhill 2003 regularity + Miao & Seborg 1999 decay ratio)
# --------------------------------------------------------------------------- #
def _ar2(rng, n, zeta, period, sigma=1.0):
    """A damped second-order response to white noise (damping zeta, natural period [samples])."""
    w = 2 * np.pi / period
    a1, a2 = 2 * np.exp(-zeta * w) * np.cos(w * np.sqrt(1 - zeta**2)), -np.exp(-2 * zeta * w)
    return signal.lfilter([sigma], [1.0, -a1, -a2], rng.standard_normal(n))


def test_acf_oscillation_false_alarm_rates():
    """White noise, a slow OU drift and a damped (zeta = 0.5) loop response: at most a few % false alarms."""
    def rate(make, n=60):
        return np.mean([metrics.acf_oscillation(make(np.random.default_rng(s)), 1.0).present for s in range(n)])

    assert rate(lambda g: 0.002 * g.standard_normal(3600)) == 0.0
    assert rate(lambda g: signal.lfilter([1.0], [1.0, -0.98], g.standard_normal(3600))) <= 0.05
    assert rate(lambda g: _ar2(g, 3600, 0.5, 120.0)) <= 0.07
    # ... while a lightly damped one (zeta = 0.05, Miao & Seborg's "excessively oscillatory") fires
    assert rate(lambda g: _ar2(g, 3600, 0.05, 120.0), 20) >= 0.9


@pytest.mark.parametrize("seed", range(4))
def test_acf_oscillation_silent_on_setpoint_step(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(3600.0)
    # error of a PI loop after a 0.2 m step at t = 300 s (closed loop time constant 25 s) plus 2 mm noise
    e = np.where(t >= 300, 0.2 * np.exp(-(t - 300) / 25.0) * (1 + (t - 300) / 25.0), 0.0)
    e = e + 0.002 * rng.standard_normal(t.size)
    assert not metrics.acf_oscillation(e, 1.0).present


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("wave", ["sine", "triangle", "square"])
def test_acf_oscillation_fires_on_cycle_with_amplitude_and_period(seed, wave):
    rng = np.random.default_rng(seed)
    T, A = 150.0, 0.01
    t = np.arange(3600.0)
    ph = 2 * np.pi * t / T
    x = {"sine": A * np.sin(ph), "triangle": A * signal.sawtooth(ph, 0.5),
         "square": A * np.sign(np.sin(ph + 0.1))}[wave]
    noisy = x + 0.002 * rng.standard_normal(t.size) + 0.004 * np.sin(2 * np.pi * t / 7200.0)  # noise + slow drift
    osc = metrics.acf_oscillation(noisy, 1.0)
    assert osc.present
    assert osc.period == pytest.approx(T, rel=0.03)
    assert osc.amplitude == pytest.approx(A, rel=0.12)
    assert osc.regularity > 1.0 and osc.decay_ratio > 0.5


def test_acf_oscillation_fires_on_weakly_damped_but_not_on_damped():
    rng = np.random.default_rng(3)
    # a sustained cycle vs the Miao & Seborg border: decay ratio rises with falling damping
    dr = [metrics.acf_oscillation(_ar2(rng, 20000, z, 100.0), 1.0).decay_ratio for z in (0.3, 0.1, 0.02)]
    assert dr[0] < dr[1] < dr[2]
    assert metrics.acf_oscillation(_ar2(rng, 20000, 0.01, 100.0), 1.0).present


def test_acf_oscillation_bad_input():
    with pytest.raises(ValueError, match="at least 16"):
        metrics.acf_oscillation(np.zeros(5), 1.0)
    with pytest.raises(ValueError, match="dt"):
        metrics.acf_oscillation(np.zeros(100), 0.0)
    with pytest.raises(ValueError, match="max_lag_frac"):
        metrics.acf_oscillation(np.zeros(100), 1.0, max_lag_frac=2.0)
    with pytest.raises(ValueError, match="min_intervals"):
        metrics.acf_oscillation(np.zeros(100), 1.0, min_intervals=2)
    assert metrics.acf_oscillation(np.ones(100), 1.0) == metrics.AcfOscillation(False, 0.0, math.inf, 0.0, 0.0, 0)


@pytest.mark.parametrize("deadband", [0.0, 0.05, 0.3])
def test_reversal_counts_match_reversals(deadband):
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.standard_normal((400, 7)), axis=0) * 0.1
    x[50:80, 2] = x[50, 2]  # a flat stretch
    got = metrics.reversal_counts(x, deadband)
    assert got.tolist() == [reversals(x[:, i], deadband) for i in range(7)]
    with pytest.raises(ValueError, match=r"\(T, n\)"):
        metrics.reversal_counts(x[:, 0])
