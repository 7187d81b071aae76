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


def test_choudhury_small_back_and_forth_slips_at_once():
    """The paper's direction test (sign of the current increment, distance |u - u_s|): after a stop, a
    back-move of a (J < a < S) and a forward move slip at once, the stem jumping backwards (the weakness
    Kano et al. 2004 addressed)."""
    S, J, a, step = 0.04, 0.01, 0.02, 1e-4
    u, _, k_stop = _stop_back_forth(a, step)
    h = simulate(valve_model("choudhury", S, J, base=fine_base()), u).h[:, 0]
    k_fwd = k_stop + 50 + int(round(a / step))              # last sample of the back-move
    assert np.all(h[k_stop:k_fwd + 1] == h[k_stop])         # stuck through the stop and the back-move
    assert h[k_fwd + 1] < h[k_stop] - (a - J)               # the first forward sample jumps backwards


# --------------------------------------------------------------------------- kano
def _stop_back_forth(a, step, up=0.08, hold=50, fwd=0.05):
    """Input: up by ``up`` (valve moving), hold, back by ``a``, forward by ``a + fwd``."""
    u1 = 0.4 + step * np.arange(1, int(round(up / step)) + 1)
    u2 = np.full(hold, u1[-1])
    u3 = u1[-1] - step * np.arange(1, int(round(a / step)) + 1)
    u4 = u3[-1] + step * np.arange(1, int(round((a + fwd) / step)) + 1)
    return np.concatenate([u1, u2, u3, u4]), u1[-1], len(u1) - 1


@pytest.mark.parametrize("case", list(CASES))
def test_kano_sine_phase_plot_numbers(case):
    """Kano et al. (2004): on a sine the same phase plot as Choudhury's (oracle O4): stuck for S of input
    after each reversal, jump J, peak X - (S - J)/2, lag (S - J)/2 while moving."""
    S, J = CASES[case]
    X = 0.2
    p = replace(fine_base(), slip_jump=SlipJump(S=S, J=J, tau_p=DT, law="kano"))
    u, H, delta, n_per = sine_response(p, X)
    h = H[:, 0]
    assert np.max(h[n_per:]) - 0.5 == pytest.approx(X - (S - J) / 2, abs=delta)
    ev = reversal_events(u, h, n_per)
    assert len(ev) == 2
    for k, kb, h_stuck, h_new in ev:
        assert S < u[k] - u[kb] <= S + delta + 1e-12
        assert J - 1e-12 <= h_stuck - h_new <= J + delta + 1e-12
    k0 = 2 * n_per + 10
    assert u[k0] - h[k0] == pytest.approx((S - J) / 2, abs=1e-12)


def test_kano_equals_choudhury_on_smooth_inputs():
    """Oracle O5: once both have moved, Kano's and Choudhury's outputs agree sample for sample."""
    S = np.array([0.04, 0.04, 0.04, 0.03])
    J = np.array([0.0, 0.01, 0.04, 0.02])
    k = np.arange(12000)
    u = 0.5 + 0.15 * np.sin(2 * np.pi * k / 3000) + 0.05 * np.sin(2 * np.pi * k / 1700)
    hc = simulate(valve_model("choudhury", S, J, base=fine_base()), u, n=4).h
    hk = simulate(valve_model("kano", S, J, base=fine_base()), u, n=4).h
    np.testing.assert_array_equal(hk[3000:], hc[3000:])


def test_kano_stop_then_continue_needs_J():
    S, J = 0.04, 0.01
    p = valve_model("kano", S, J, base=fine_base())
    step = 1e-4
    up1 = 0.5 + step * np.arange(1, 801)
    u = np.concatenate([up1, np.full(50, up1[-1]), up1[-1] + step * np.arange(1, 401)])
    h = simulate(p, u).h[:, 0]
    k_stop = len(up1) - 1
    assert np.all(h[k_stop:k_stop + 51] == h[k_stop])
    kb = k_stop + 51 + int(np.argmax(h[k_stop + 51:] != h[k_stop]))
    assert J < u[kb] - u[k_stop] <= J + step + 1e-12
    assert h[kb] - h[k_stop] == pytest.approx(u[kb] - u[k_stop], abs=1e-12)  # jump J (+ the last step)


@pytest.mark.parametrize("a", [0.005, 0.02, 0.035])
def test_kano_back_and_forth_inside_the_band_stays_stuck_until_J_past_the_stuck_point(a):
    """Kano's signed test: after a stop and a back-move smaller than S, the valve stays stuck while the
    input drifts forward again, until it is J past the stuck point; then it moves forwards."""
    S, J, step = 0.04, 0.01, 1e-4
    u, u_s, k_stop = _stop_back_forth(a, step)
    h = simulate(valve_model("kano", S, J, base=fine_base()), u).h[:, 0]
    kb = k_stop + int(np.argmax(h[k_stop:] != h[k_stop]))
    assert kb > k_stop
    assert J < u[kb] - u_s <= J + step + 1e-12
    assert h[kb] > h[k_stop]


def test_kano_starts_in_the_middle_of_its_band():
    """From the rest state (no direction yet) the first slip needs (S + J)/2 either way and jumps J."""
    S, J, step = 0.04, 0.01, 1e-4
    for sign in (1.0, -1.0):
        p = valve_model("kano", S, J, base=fine_base())
        u = 0.5 + sign * step * np.arange(1, 601)
        h = simulate(p, u).h[:, 0]
        kb = int(np.argmax(h != h[0]))
        assert (S + J) / 2 < abs(u[kb] - 0.5) <= (S + J) / 2 + step + 1e-12
        assert abs(h[kb] - h[0]) == pytest.approx(J, abs=step + 1e-12)


# --------------------------------------------------------------------------- karnopp
def karnopp(S, J, zeta=None, tau=0.1, dt=DT, **kw):
    p = valve_model("karnopp", S, J, base=ModelParams(valve=ValveParams(tau=tau), dt=dt))
    if zeta is not None or kw:
        p = replace(p, slip_jump=replace(p.slip_jump, **({"zeta": zeta} if zeta is not None else {}), **kw))
    return p


@pytest.mark.parametrize("dt", [1e-3, 0.02])
@pytest.mark.parametrize("S,J", [(0.03, 0.01), (0.02, 0.0), (0.02, 0.02)])
def test_karnopp_reversal_band_and_jump(S, J, dt):
    """Quasi-static sizing fs = (S + J)/2, fc = (S - J)/2: after a reversal the input travels S (plus the
    actuator lag's share s tau (1 + ln 2) and the viscous lag 2 zeta s / omega_n) with the stem exactly
    still, then the stem slips by J (overdamped default stem)."""
    s, Ts, tau = 1e-3, 0.1, 0.1
    p = karnopp(S, J, tau=tau, dt=dt)
    sj = p.slip_jump
    u, k_rev = ramp_up_down(0.4, 0.1, 0.1, s, Ts)
    h = simulate(p, u, n_sub=int(round(Ts / dt))).h[:, 0]
    kb, h_stuck = breakaway_after(u, h, k_rev)
    expect = S + s * tau * (1 + math.log(2)) + 2 * sj.zeta / sj.omega_n * s
    assert abs((u[k_rev] - u[kb]) - expect) <= 2 * s * Ts + 1e-6
    # no motion inside the band: from the stop after the reversal to the break-away the stem is still
    k_stop = k_rev + int(round(5 * tau / Ts))
    assert np.all(h[k_stop:kb] == h[k_stop])
    # the slip: stem displacement beyond the input's since break-away, once the slip is over (2 s)
    k2 = kb + int(round(2.0 / Ts))
    jump = (h_stuck - h[k2]) - (u[kb] - u[k2])
    assert abs(jump - J) <= s * Ts + 2e-4


def test_karnopp_light_damping_gives_stick_slip_steps():
    """zeta < 1: the slip overshoots to J (1 + Mp), Mp = exp(-pi zeta / sqrt(1 - zeta^2)); under a slow ramp
    the stem moves in a staircase of such steps, sticking in between."""
    S, J, zeta = 0.03, 0.01, 0.3
    s, Ts = 2e-4, 0.05
    p = karnopp(S, J, zeta=zeta)
    u = 0.5 + s * Ts * np.arange(int(round(0.15 / (s * Ts))))
    h = simulate(p, u, n_sub=int(round(Ts / DT))).h[:, 0]
    dh = np.diff(h)
    assert np.all(dh >= 0)
    stuck = dh == 0
    assert stuck.mean() > 0.9                                   # stuck most of the time
    plateaus = np.unique(h[1:][stuck])                          # stem positions where it stuck
    steps = np.diff(plateaus)
    assert len(steps) >= 5
    mp = math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2))
    # the first plateau after start-up is reached from the band's middle; the rest are full steps
    np.testing.assert_allclose(steps[1:], J * (1 + mp), rtol=0.01)


def test_karnopp_no_motion_while_force_inside_static_friction():
    """A stuck stem does not move at all while |p - x| <= fs, even with input wiggles inside the band."""
    S, J = 0.04, 0.02
    p = karnopp(S, J)
    k = np.arange(4000)
    u = 0.5 + 0.8 * (S + J) / 2 * np.sin(2 * np.pi * k / 1000)   # never more than 0.8 fs from the rest point
    h = simulate(p, u).h[:, 0]
    assert np.all(h == 0.5)


def test_karnopp_stiff_stem_is_refused_with_advice():
    p = karnopp(0.02, 0.01, dt=0.02)
    with pytest.raises(ParameterError, match="omega_n.*sub-steps.*use dt <="):
        simulate(replace(p, slip_jump=replace(p.slip_jump, omega_n=1e4)), np.full(5, 0.5))
    with pytest.raises(ParameterError, match="J must be <= S"):
        SlipJump(S=0.01, J=0.02, law="karnopp")
    with pytest.raises(ParameterError, match="law must be one of"):
        SlipJump(law="lugre")
    with pytest.raises(ParameterError, match="zeta"):
        SlipJump(law="karnopp", zeta=-1.0)


# --------------------------------------------------------------------------- a model in one file (docs)
def plant_stems(p, u):
    from valve_gym.plant import Plant

    plant = Plant(p, p.batch_size(), scan_s=p.dt)
    plant.reset()
    return np.array([plant.step(uk).stem for uk in u])


def test_docs_example_model_registers_and_runs(he_model):
    assert friction_spec("he") is he_model.SPEC
    p = valve_model("he", 0.04, 0.01, base=fine_base())
    assert p.slip_jump.law == "he" and p.friction_model == "he"
    with pytest.raises(ParameterError, match="per-sample friction law.*Plant"):
        simulate(p, np.full(10, 0.5))
    u = 0.5 + 1e-4 * np.arange(1, 401)
    h = plant_stems(p, u)
    kb = int(np.argmax(h[:, 0] != 0.5))                      # first slip from rest: (S + J)/2, jump J
    assert (0.04 + 0.01) / 2 - 1e-12 < u[kb] - 0.5 <= (0.04 + 0.01) / 2 + 1e-4 + 1e-12
    assert h[kb, 0] - 0.5 == pytest.approx(0.01, abs=1e-4 + 1e-12)


def test_docs_example_model_staircase_under_slow_input(he_model):
    """He et al. (2007), oracle O6: input steps smaller than J move the stem in steps of about J."""
    S, J, du = 0.03, 0.01, 1e-4
    p = valve_model("he", S, J, base=fine_base())
    h = plant_stems(p, 0.5 + du * np.arange(1, 1201))[:, 0]
    steps = np.diff(h)[np.diff(h) > 0]
    assert len(steps) >= 5
    assert np.all((steps[1:] > J) & (steps[1:] <= J + du + 1e-12))
    assert np.mean(np.diff(h) == 0) > 0.95                     # stuck between the steps


def test_docs_example_model_equals_choudhury_for_a_pure_dead_band(he_model):
    """Oracle O5: He(fs = fd = S/2), i.e. J = 0, is Choudhury's model (after the first reversal)."""
    S = np.array([0.02, 0.05])
    k = np.arange(6000)
    u = 0.5 + 0.1 * np.sin(2 * np.pi * k / 2000)
    he = plant_stems(valve_model("he", S, 0.0, base=fine_base()), u)
    ch = plant_stems(valve_model("choudhury", S, 0.0, base=fine_base()), u)
    np.testing.assert_allclose(he[1000:], ch[1000:], rtol=0, atol=1e-12)


@pytest.mark.parametrize("S,J", [(0.03, 0.0), (0.03, 0.01), (0.03, 0.03)])
def test_karnopp_sine_phase_plot_numbers(S, J):
    """The force balance on a slow sine gives the data-driven phase plot (Choudhury et al. 2005, the
    cases J = 0, J < S, J = S): peak X - (S - J)/2, stuck for S of input after each reversal, slip J.
    Tolerance: the actuator lag tau_p and the viscous lag 2 zeta/omega_n times the input speed at
    break-away, plus one sample of input change."""
    X, period, Ts, tau = 0.1, 100.0, 0.01, 0.1
    p = karnopp(S, J, tau=tau, dt=0.005)
    k = np.arange(int(2.5 * period / Ts))
    u = 0.5 + X * np.sin(2 * np.pi * k * Ts / period)
    h = simulate(p, u, n_sub=2).h[:, 0]
    w = 2 * np.pi / period
    speed_b = X * w * math.sqrt(1 - ((X - S) / X) ** 2)          # input speed at break-away
    lag_tol = speed_b * (tau * (1 + math.log(2)) + 2 * p.slip_jump.zeta / p.slip_jump.omega_n) + X * w * Ts
    last = slice(int(period / Ts), None)
    assert np.max(h[last]) - 0.5 == pytest.approx(X - (S - J) / 2, abs=X * w * Ts + 1e-4)
    ev = reversal_events(u, h, int(period / Ts))
    assert len(ev) >= 1
    for kp, _, _, _ in ev:
        kstop = kp + int(round(1.0 / Ts))                        # the stem has stopped 10 tau after the top
        kb = kstop + int(np.argmax(h[kstop:] != h[kstop]))       # break-away: the stem moves again
        assert kb > kstop and np.all(h[kstop:kb] == h[kstop])    # no motion inside the band
        assert abs((u[kp] - u[kb]) - S) <= lag_tol
        k2 = kb + int(round(0.5 / Ts))
        jump = (h[kstop] - h[k2]) - (u[kb] - u[k2])
        assert abs(jump - J) <= lag_tol + 2e-4


def test_choudhury_block_start_from_the_core_rest_state():
    """The documented start of the core's Choudhury block: from rest (no direction yet) it slips after J of
    input, to u - (S - J)/2, i.e. against the input when J < S/3."""
    S, J, step = 0.05, 0.01, 1e-4
    u = 0.5 + step * np.arange(1, 300)
    h = simulate(valve_model("choudhury", S, J, base=fine_base()), u).h[:, 0]
    kb = int(np.argmax(h != 0.5))
    assert J - 1e-12 < u[kb] - 0.5 <= J + step + 1e-12
    assert h[kb] == pytest.approx(u[kb] - (S - J) / 2, abs=1e-12)
    assert h[kb] < 0.5


def test_friction_module_doctests():
    import doctest

    import valve_gym.friction as fpkg
    from valve_gym.friction import choudhury, frictionless, kano, karnopp, riihilahti, spec

    attempted = 0
    for mod in (fpkg, choudhury, frictionless, kano, karnopp, riihilahti, spec):
        res = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
        assert res.failed == 0, mod.__name__
        attempted += res.attempted
    assert attempted > 0


def test_param_spec_rejects_inconsistent_declarations():
    from valve_gym.friction import ParamSpec

    with pytest.raises(ValueError, match="log prior needs lo > 0"):
        ParamSpec("zeta", "-", 0.0, 10.0, 1.0, "log", "damping")
    with pytest.raises(ValueError, match="outside"):
        ParamSpec("S", "-", 0.0, 0.5, 0.7, "lin", "band")
    with pytest.raises(ValueError, match="prior must be"):
        ParamSpec("S", "-", 0.0, 0.5, 0.1, "uniform", "band")


@pytest.mark.parametrize("model", ["riihilahti", "choudhury", "kano", "karnopp"])
def test_mapped_parameters_fall_in_the_declared_ranges(model):
    S = np.array([0.0, 0.005, 0.05, 0.1, 0.5])
    J = np.array([0.0, 0.005, 0.01, 0.1, 0.5])
    p = valve_model(model, S, J)
    spec = friction_spec(model)
    block = p.valve if model == "riihilahti" else p.slip_jump
    for ps in spec.params:
        v = np.asarray(getattr(block, ps.name), float)
        assert np.all((v >= ps.lo) & (v <= ps.hi)), (model, ps.name, v)
