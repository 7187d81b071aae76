"""Controllers on loops outside the benchmark: other plants, units and operating points (public interface)."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.agents import load_controller


def _first_order_loop(ctrl, sp: float, load: float, n_scans: int = 2000, K: float = 100.0, T: float = 30.0):
    """Healthy valve (stem = op) on ``T dy/dt = K op + load - y`` (PV in %), 1 s scans, started at rest at ``sp``.

    Returns the PV of every scan; ``load`` is applied from scan 200 on.
    """
    y = sp
    op0 = sp / K
    ctrl.reset(sp, y, op0)
    pv = np.empty(n_scans)
    for k in range(n_scans):
        op = ctrl.step(sp, y)
        assert 0.0 <= op <= 1.0
        d = load if k >= 200 else 0.0
        for _ in range(10):                       # Euler, 0.1 s
            y += 0.1 * (K * op + d - y) / T
        pv[k] = y
    return pv


@pytest.mark.parametrize("sp, load", [(98.5, -1.0), (2.0, 1.5)])
def test_knocker_leaves_no_offset_near_an_output_limit(sp, load):
    # the valve must sit at 0.995 (or 0.005) of its stroke: the knocker's pulses are cut by the limit;
    # the cut part must not enter the integral, or the loop keeps a steady offset the PI does not have
    Kc, Ti = 30.0 / (100.0 * 10.6), 30.0          # SIMC for the plant in % (Kc in 1/%)
    pi = _first_order_loop(load_controller("pi", Kc=Kc, Ti=Ti), sp, load)
    kn = _first_order_loop(load_controller("knocker", Kc=Kc, Ti=Ti, S=0.03), sp, load)
    assert abs(np.mean(sp - pi[-600:])) < 0.01
    assert abs(np.mean(sp - kn[-600:])) < 0.05    # was 0.5 % (the cut part of every pulse, integrated)


def test_knocker_integral_is_the_pi_alone_when_a_pulse_is_cut():
    k = load_controller("knocker", Kc=1.0, Ti=10.0, a=0.1, tau_k=1.0, h_k=3.0)
    pi = load_controller("pi", Kc=1.0, Ti=10.0)
    k.reset(1.0, 1.0, 0.95)
    pi.reset(1.0, 1.0, 0.95)
    for _ in range(9):
        op_k = k.step(1.0, 0.99)
        pi.step(1.0, 0.99)
        assert op_k <= 1.0
    assert k.state.pi.integral[0] == pytest.approx(pi.state.integral[0])


# ------------------------------------------------------------------------------------------ learned block
def test_learned_network_takes_numpy_numbers_and_says_it_takes_no_per_loop_settings():
    blk = load_controller("learned_network", Kc=np.float64(1.89), Ti=np.float32(42.4), scan_s=np.int64(1))
    assert blk.settings["Kc"] == 1.89 and blk.settings["scan_s"] == 1.0
    with pytest.raises(ValueError, match=r"^learned_network: setting Kc must be one number for all loops"):
        load_controller("learned_network", Kc=np.array([1.0, 2.0]))


def test_learned_network_start_outside_its_output_limits_is_refused_not_bumped():
    blk = load_controller("learned_network", op_hi=0.8)
    with pytest.raises(ValueError, match=r"^learned_network: op must be the valve input now applied, within the output "
                                         r"limits \[op_lo, op_hi\] = \[0, 0.8\], got \[0.9\]"):
        blk.reset(1.0, 1.0, 0.9)           # was accepted, and the first scan jumped to 0.8
    blk.reset(1.0, 1.0, 0.8)
    assert blk.step(1.0, 1.0) == pytest.approx(0.8)


def test_learned_network_warns_outside_the_settings_it_was_trained_with():
    with pytest.warns(UserWarning, match=r"learned_network: scan_s = 10 \(trained: 1\): the network .* was trained"):
        load_controller("learned_network", scan_s=10.0)
    with pytest.warns(UserWarning, match=r"Kc = 0.0283 \(trained: 1.89\)"):
        load_controller("learned_network", Kc=0.0283)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_controller("learned_network")
        load_controller("learned_network", scan_s=1.0, Kc=1.89, op_hi=0.9)


def test_learned_is_the_adaptive_compensator_and_takes_per_loop_tuning():
    """``"learned"`` is the block trained over the randomised family: one block for many loops, each with its
    own tuning, and the earlier name ``learned_adaptive`` still builds it."""
    from valve_gym.agents.controllers.adaptive import AdaptiveStiction

    blk = load_controller("learned", Kc=np.array([1.0, 2.0]), Ti=np.array([30.0, 60.0]), scan_s=np.int64(2))
    assert isinstance(blk, AdaptiveStiction) and blk.name == "learned" and blk.scan_s == 2.0
    blk.reset(np.ones(2), np.ones(2), np.full(2, 0.5))
    op = blk.step(np.ones(2), np.array([0.99, 0.99]))
    assert op.shape == (2,) and op[1] > op[0] > 0.5                # the higher gain moves further
    old = load_controller("learned_adaptive", Kc=1.0, Ti=30.0)
    assert isinstance(old, AdaptiveStiction) and old.settings == load_controller("learned", Kc=1.0, Ti=30.0).settings
