"""Knocker (Hägglund 2002): pulse amplitude, width, period and sign, through ``predict`` and the block."""
import numpy as np
import pytest

from valve_gym.agents import BlockPolicy, load_controller


def _knocker(**kw):
    """The knocker block with SB3's ``predict`` (what RL code runs)."""
    return BlockPolicy(load_controller("knocker", **kw))


def _pi(**kw):
    return BlockPolicy(load_controller("pi", **kw))


def _run(knocker, errors, u0=0.5):
    """Drive the knocker's ``predict`` with a given error sequence (no plant).

    Returns the knocker output and the PI output without the pulse, ``(T, n)``.
    """
    n = np.asarray(errors[0]).size
    state = None
    u_out, u_pi = [], []
    u_last = np.full(n, u0)
    kc = knocker.block.settings["Kc"] * knocker.block.settings["detune"]
    for e in errors:
        obs = np.zeros((n, 4))
        obs[:, 1] = 1.0
        obs[:, 2] = e
        obs[:, 3] = u_last
        a, state = knocker.predict(obs, state)
        u = (a[:, 0].astype(float) + 1) / 2
        u_out.append(u)
        u_pi.append(state.pi.integral + kc * np.asarray(e, float))
        u_last = u
    return np.array(u_out), np.array(u_pi)


@pytest.mark.parametrize("tau_k,h_k", [(1.0, 3.0), (2.0, 5.0), (1.0, 2.0)])
def test_pulse_timing_and_amplitude(tau_k, h_k):
    a = 0.04
    k = _knocker(Kc=1.0, Ti=10.0, a=a, tau_k=tau_k, h_k=h_k)
    T = 30
    # constant positive error: the integral part rises steadily -> positive pulses
    out, pi = _run(k, [np.array([0.01, -0.01])] * T)
    pulse = out - pi
    t = np.arange(T)
    in_pulse = (t % int(h_k)) < int(tau_k)
    assert np.allclose(pulse[in_pulse, 0], a, atol=1e-6) and np.allclose(pulse[~in_pulse, 0], 0.0, atol=1e-6)
    # the second valve's error is negative: the integral falls, pulses are negative
    assert np.allclose(pulse[in_pulse, 1], -a, atol=1e-6) and np.allclose(pulse[~in_pulse, 1], 0.0, atol=1e-6)


def test_pulse_sign_is_the_integral_parts_change_not_the_output_change():
    """Error +2 cm for 8 scans then -0.5 cm: the output drops at once (P kick), the integral keeps rising
    until it has integrated enough negative error; the pulses follow the integral."""
    k = load_controller("knocker", Kc=1.0, Ti=10.0, a=0.03, tau_k=1.0, h_k=4.0)
    k.reset(1.0, 1.0, 0.5)
    errs = [0.02] * 8 + [-0.005] * 40
    out, integral = [], [k.state.pi.integral[0]]
    for e in errs:
        out.append(k.step(1.0, 1.0 - e))
        integral.append(k.state.pi.integral[0])
    integral = np.array(integral)
    pulse = np.array(out) - (integral[1:] + np.array(errs))
    starts = np.arange(0, len(errs), 4)
    want = np.sign(integral[starts + 1] - integral[np.maximum(starts - 3, 0)])
    assert np.allclose(pulse[starts], 0.03 * want, atol=1e-9)
    # at t = 8 the PI output fell by 0.025 since t = 4 (P kick) but the integral rose: pulse up
    assert want[2] == 1 and out[8] < out[4]
    assert np.all(want[3:] == -1)


def test_sign_does_not_follow_white_noise_on_the_pv():
    """A small steady error (2 mm: the PI output ramps up slowly) under 2 mm white measurement noise.

    The integral part changes by Kc Ts/Ti times the sum of 3 errors per pulse period (mean 6 mm, standard
    deviation 3.5 mm): the pulse points up with probability Phi(1.73) = 0.96. The raw output change over the
    same period is dominated by Kc times the noise difference: up with probability about 0.5.
    """
    rng = np.random.default_rng(0)
    T, n = 3000, 20
    k = load_controller("knocker")          # SIMC PI, S = 0.02, h_k = 3 s
    k.reset(1.0, np.ones(n), np.full(n, 0.5))
    pv = 1.0 - 0.002 + 0.002 * rng.standard_normal((T, n))
    ops, signs = [], []
    for t in range(T):
        ops.append(k.step(1.0, pv[t]))
        if t % 3 == 0:
            signs.append(k.state.sign.copy())
    up_pulse = np.mean(np.array(signs)[1:] > 0)
    pi_out = np.array(ops) - np.where((np.arange(T) % 3 == 0)[:, None], k.settings["a"] * np.array(
        [signs[t // 3] for t in range(T)]), 0.0)
    up_raw = np.mean(pi_out[3::3] - pi_out[:-3:3] > 0)
    assert up_pulse > 0.9
    assert up_raw < 0.65


def test_no_pulse_without_change():
    k = _knocker(Kc=1.0, Ti=10.0, a=0.05, tau_k=1.0, h_k=2.0)
    out, pi = _run(k, [np.zeros(3)] * 10, u0=0.4)
    assert np.allclose(out, 0.4) and np.allclose(pi, 0.4)


def test_zero_amplitude_equals_pi():
    pi = _pi(Kc=1.5, Ti=30.0)
    k = _knocker(Kc=1.5, Ti=30.0, a=0.0)
    rng = np.random.default_rng(0)
    obs = np.column_stack([np.ones(4), np.ones(4), rng.normal(0, 0.05, 4), rng.uniform(0, 1, 4)])
    s1 = s2 = None
    for _ in range(10):
        a1, s1 = pi.predict(obs, s1)
        a2, s2 = k.predict(obs, s2)
        assert np.array_equal(a1, a2)
        obs[:, 2] = rng.normal(0, 0.05, 4)


def test_output_clipped_and_pulse_not_integrated():
    k = _knocker(Kc=1.0, Ti=10.0, a=0.2, tau_k=1.0, h_k=2.0)
    out, _ = _run(k, [np.array([0.05, -0.05])] * 10, u0=0.95)
    assert out.max() <= 1.0 and out.min() >= 0.0
    # a pulse never enters the integral: the integral after 10 scans is what the error alone gives
    k2 = load_controller("knocker", Kc=1.0, Ti=10.0, a=0.1, tau_k=1.0, h_k=2.0)
    k2.reset(1.0, 1.0, 0.5)
    for _ in range(10):
        k2.step(1.0, 0.99)
    assert k2.state.pi.integral[0] == pytest.approx(0.5 - 0.0 + 10 * 0.1 * 0.01)


def test_episode_start_restarts_pulse_train():
    k = _knocker(Kc=1.0, Ti=10.0, a=0.05, tau_k=1.0, h_k=3.0)
    obs = np.array([[1.0, 1.0, 0.01, 0.5], [1.0, 1.0, 0.01, 0.5]])
    _, s = k.predict(obs)
    _, s = k.predict(obs, s)
    assert list(s.phase) == [2, 2]
    _, s = k.predict(obs, s, episode_start=np.array([True, False]))
    assert list(s.phase) == [1, 0]


def test_defaults_are_the_rule_at_the_default_stiction_estimate():
    block = load_controller("knocker")
    assert block.settings["S"] == 0.02
    assert {k: block.settings[k] for k in ("a", "tau_k", "h_k")} == {"a": 0.01, "tau_k": 1.0, "h_k": 3.0}
    assert load_controller("knocker", S=0.05, scan_s=0.5).settings["a"] == 0.025
    assert load_controller("knocker", scan_s=0.5).settings["h_k"] == 1.5


@pytest.mark.parametrize("kw,msg", [
    ({"tau_k": 1.5}, "whole number"),
    ({"h_k": 1.0, "tau_k": 1.0}, "h_k > tau_k"),
    ({"a": -0.1}, r"a = -0.1 is out of range; allowed: a \[-\] in \[0, 1\]"),
    ({"a": "big"}, "a must be a number"),
    ({"h_k": 0.0}, r"h_k = 0.0 is out of range"),
])
def test_bad_parameters(kw, msg):
    with pytest.raises(ValueError, match=msg):
        load_controller("knocker", **kw)
