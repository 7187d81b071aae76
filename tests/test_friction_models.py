"""Each friction model against its paper's published (or derived) input-output behaviour.

Numbers, not shapes: break-away travel after a reversal, jump size, offset while
moving, peak of a sinusoid response, with tolerances derived from the sampling
(the input moves at most ``delta`` per controller sample, so an event detected
at a sample is known to within ``delta`` of input travel).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from valve_gym.core import simulate
from valve_gym.friction import FRICTION_MODELS, friction_spec, valve_model
from valve_gym.friction import riihilahti as rmod
from valve_gym.params import ModelParams, ParameterError, SlipJump, ValveParams

DT = 1e-3


def fine_base(tau=DT, dt=DT):
    """Default tank, Euler step ``dt``; positioner ``tau = dt`` makes the stem equal the block output."""
    return ModelParams(valve=ValveParams(tau=tau), dt=dt)


def ramp_up_down(u0, up, down, rate, Ts):
    """Input samples: from ``u0`` up by ``up`` then down by ``down`` at ``rate`` per s, sample period ``Ts``."""
    k_up = int(round(up / (rate * Ts)))
    k_dn = int(round(down / (rate * Ts)))
    a = u0 + rate * Ts * np.arange(1, k_up + 1)
    b = a[-1] - rate * Ts * np.arange(1, k_dn + 1)
    return np.concatenate([a, b]), k_up - 1          # index of the reversal (last rising sample)


def breakaway_after(u, h, k_rev, eps=1e-9):
    """First sample after the reversal ``k_rev`` at which the stem is below its post-reversal maximum."""
    hmax = h[k_rev]
    for k in range(k_rev + 1, len(h)):
        hmax = max(hmax, h[k])
        if h[k] < hmax - eps:
            return k, hmax
    raise AssertionError("the stem never broke away after the reversal")


# --------------------------------------------------------------------------- registry
def test_registry_lists_the_models_in_order():
    assert FRICTION_MODELS[:3] == ("none", "riihilahti", "choudhury")
    for name in FRICTION_MODELS:
        spec = friction_spec(name)
        assert spec.name == name
        assert spec.citation and spec.kernel and spec.signature
        for p in spec.params:
            assert p.unit and p.lo <= p.default <= p.hi and p.prior in ("lin", "log", "sq", "fixed")
        text = spec.describe(0.02, 0.01)
        assert isinstance(text, str) and len(text) > 20


def test_unknown_model_lists_the_known_ones():
    with pytest.raises(ValueError, match="unknown friction model 'lugre'.*choudhury"):
        valve_model("lugre", 0.02, 0.01)
    with pytest.raises(ValueError, match="known models"):
        friction_spec("Choudhury")


@pytest.mark.parametrize("S,J,match", [
    (0.02, 0.03, "J <= S"),
    (-0.01, 0.0, ">= 0"),
    (2.0, 0.01, "fraction of the stroke below 1"),
    (float("nan"), 0.0, "finite"),
    (np.array([0.02, 0.03]), np.array([0.01, 0.01, 0.01]), "same number"),
    ("abc", 0.0, "numbers"),
])
def test_bad_band_is_a_clear_error(S, J, match):
    with pytest.raises(ParameterError, match=match):
        valve_model("choudhury", S, J)


def test_base_must_be_model_params():
    with pytest.raises(ParameterError, match="ModelParams"):
        valve_model("none", 0.0, 0.0, base={"dt": 0.1})


@pytest.mark.parametrize("model", ["none", "riihilahti", "choudhury"])
def test_batched_band_gives_a_batch(model):
    S = np.array([0.0, 0.01, 0.05])
    J = np.array([0.0, 0.005, 0.05])
    p = valve_model(model, S, J)
    assert p.batch_size() == (1 if model == "none" else 3)
    u = np.linspace(0.3, 0.7, 50)
    tr = simulate(p, u, n_sub=10, n=3)
    assert np.isfinite(tr.y).all()


def test_base_friction_is_removed_and_plant_kept():
    base = ModelParams(valve=ValveParams(e_dead=0.03, z_max=0.3, tau=0.2), slip_jump=SlipJump(S=0.1, J=0.05),
                       dt=0.05).with_effect("leak")
    p = valve_model("none", 0.02, 0.01, base=base)
    assert p.slip_jump is None and p.valve.e_dead == 0.0 and p.valve.z_max == 0.0
    assert p.valve.tau == 0.2 and p.leak == base.leak and p.dt == 0.05
    c = valve_model("choudhury", 0.02, 0.01, base=base)
    assert c.slip_jump == SlipJump(S=0.02, J=0.01, tau_p=0.2) and c.valve.e_dead == 0.0


# --------------------------------------------------------------------------- none
def test_none_follows_a_ramp_with_the_positioner_lag_only():
    # first-order lag tau on a ramp of slope s: steady lag s*tau (no dead band, no stick)
    tau, s, Ts = 0.1, 0.01, 0.05
    p = valve_model("none", 0.05, 0.02, base=ModelParams(valve=ValveParams(tau=tau), dt=DT))
    u, k_rev = ramp_up_down(0.3, 0.2, 0.2, s, Ts)
    tr = simulate(p, u, n_sub=int(round(Ts / DT)))
    h = tr.h[:, 0]
    k = k_rev - 10                              # moving steadily (many tau after the start)
    # the input is a staircase held over Ts: mean lag s*(tau + Ts/2) at the end of a sample -> s*tau - s*Ts/2
    lag = u[k] - h[k]
    assert abs(lag - s * (tau - Ts / 2)) < 0.05 * s * tau
    # reversal: the stem turns within one sample, no stick band
    kb, _ = breakaway_after(u, h, k_rev)
    assert kb - k_rev <= 3


# --------------------------------------------------------------------------- riihilahti
@pytest.mark.parametrize("S,J", [(0.02, 0.01), (0.04, 0.01), (0.01, 0.0), (0.03, 0.03)])
def test_riihilahti_mapping_reproduces_S_and_J_at_the_reference_speed(S, J):
    """O2: after a ramp reversal at s_ref the input travels S before break-away; the error beyond
    the dead band at break-away (the catch-up) is J."""
    s, Ts, tau = rmod.REF_RATE, 0.05, 0.1
    p = valve_model("riihilahti", S, J, base=ModelParams(valve=ValveParams(tau=tau), dt=DT))
    e_dead, z_max = p.valve.e_dead, p.valve.z_max
    expect = max(S, J + s * tau * math.log(2))   # e_dead clipped at 0 when J ~ S (documented)
    assert rmod.breakaway_travel(e_dead, z_max, tau, s) == pytest.approx(expect, rel=1e-12)
    u, k_rev = ramp_up_down(0.4, 3 * S + 0.01, 3 * S + 0.01, s, Ts)
    tr = simulate(p, u, n_sub=int(round(Ts / DT)))
    h = tr.h[:, 0]
    kb, hstuck = breakaway_after(u, h, k_rev)
    travel = u[k_rev] - u[kb]
    # staircase input: the ramp is delayed by Ts/2 on average and the break-away is seen at the
    # end of a sample; each costs at most one sample of input travel s*Ts
    assert abs(travel - expect) <= 2 * s * Ts + 1e-6
    # the catch-up: |e| beyond the dead band at break-away equals 2 sqrt(s z_max) = J
    catch_up = (hstuck - u[kb]) - e_dead
    assert abs(catch_up - J) <= 2 * s * Ts + 0.05 * J + 1e-6


def test_riihilahti_band_grows_with_input_speed():
    """The documented limit: the catch-up scales as sqrt(speed), 2x at 4x the reference speed."""
    S, J, tau, Ts = 0.03, 0.012, 0.1, 0.01
    base = ModelParams(valve=ValveParams(tau=tau, v_max=10.0), dt=DT)
    p = valve_model("riihilahti", S, J, base=base)
    travels = []
    for s in (rmod.REF_RATE, 4 * rmod.REF_RATE):
        u, k_rev = ramp_up_down(0.4, 0.1, 0.1, s, Ts)
        h = simulate(p, u, n_sub=int(round(Ts / DT))).h[:, 0]
        kb, _ = breakaway_after(u, h, k_rev)
        travels.append(u[k_rev] - u[kb])
        want = rmod.breakaway_travel(p.valve.e_dead, p.valve.z_max, tau, s)
        assert abs(travels[-1] - want) <= 2 * s * Ts + 1e-6
    assert travels[1] - travels[0] == pytest.approx(J + 3 * rmod.REF_RATE * tau * math.log(2), abs=0.002)


# --------------------------------------------------------------------------- choudhury
def sine_response(p, X, n_per=4000, periods=3, centre=0.5):
    k = np.arange(n_per * periods)
    u = centre + X * np.sin(2 * np.pi * k / n_per)
    tr = simulate(p, u, n_sub=1, n=p.batch_size())
    delta = 2 * np.pi * X / n_per                 # largest input change per sample
    return u, tr.h, delta, n_per


def reversal_events(u, h, start):
    """(k_peak, k_break, stuck_stem, new_stem) for every top reversal of u after ``start``."""
    out = []
    for k in range(start + 1, len(u) - 1):
        if u[k] > u[k - 1] and u[k + 1] < u[k]:            # top of the sine
            kb = k + 1
            while kb < len(u) and h[kb] == h[k]:
                kb += 1
            if kb < len(u):
                out.append((k, kb, h[k], h[kb]))
    return out


CASES = {"dead band J=0": (0.04, 0.0), "undershoot J<S": (0.04, 0.015), "no offset J=S": (0.04, 0.04),
         "overshoot J>S": (0.03, 0.045)}


@pytest.mark.parametrize("case", list(CASES))
def test_choudhury_sine_phase_plot_numbers(case):
    """Choudhury et al. (2005), figs. of the four cases: stuck after each reversal until the input has
    moved S, then a jump of J; peak X - (S - J)/2; lag (S - J)/2 while moving (oracle O4)."""
    S, J = CASES[case]
    X = 0.2
    p = replace(fine_base(), slip_jump=SlipJump(S=S, J=J, tau_p=DT))
    u, H, delta, n_per = sine_response(p, X)
    h = H[:, 0]
    last = slice(n_per, None)
    assert np.max(h[last]) - 0.5 == pytest.approx(X - (S - J) / 2, abs=delta)
    ev = reversal_events(u, h, n_per)
    assert len(ev) == 2
    for k, kb, h_stuck, h_new in ev:
        travel = u[k] - u[kb]
        assert S < travel <= S + delta + 1e-12
        jump = h_stuck - h_new
        assert J - 1e-12 <= jump <= J + delta + 1e-12
    # while moving up (zero crossing of the sine) the stem lags by (S - J)/2
    k0 = 2 * n_per + 10
    assert u[k0] - h[k0] == pytest.approx((S - J) / 2, abs=1e-12)


def test_choudhury_built_by_valve_model_matches_the_block():
    p = valve_model("choudhury", 0.04, 0.015, base=fine_base())
    q = replace(fine_base(), slip_jump=SlipJump(S=0.04, J=0.015, tau_p=DT))
    u = 0.5 + 0.1 * np.sin(np.linspace(0, 12, 3000))
    np.testing.assert_array_equal(simulate(p, u).h, simulate(q, u).h)


def test_choudhury_stop_then_same_direction_needs_J():
    """A stop (du = 0) sticks the valve; going on the same way it slips after J, not S."""
    S, J = 0.04, 0.01
    p = valve_model("choudhury", S, J, base=fine_base())
    step = 1e-4
    up1 = 0.5 + step * np.arange(1, 801)                 # move 8 % up (breaks away, moving)
    hold = np.full(50, up1[-1])                          # stop
    up2 = up1[-1] + step * np.arange(1, 401)             # go on up
    u = np.concatenate([up1, hold, up2])
    h = simulate(p, u).h[:, 0]
    k_stop = len(up1) - 1
    assert np.all(h[k_stop:k_stop + 51] == h[k_stop])
    kb = k_stop + 51 + int(np.argmax(h[k_stop + 51:] != h[k_stop]))
    assert J < u[kb] - u[k_stop] <= J + step + 1e-12
