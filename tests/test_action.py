"""Direct-acting loops: every block takes ``action = -1`` (opening the valve lowers pv) with a positive Kc."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.agents import available_controllers, load_controller


def _ops(blk, sp, pv, op0=0.5):
    blk.reset(sp[0], pv[0], op0)
    return np.array([blk.step(s, p) for s, p in zip(sp, pv)])


@pytest.mark.filterwarnings("ignore:learned_network")       # the network warns for a tuning it was not trained on
@pytest.mark.parametrize("name", available_controllers())
def test_a_direct_acting_block_is_the_reverse_acting_block_on_the_mirrored_measurement(name):
    rng = np.random.default_rng(4)
    sp = 1.0 + np.repeat(rng.normal(0.0, 0.02, 6), 50)
    pv = sp + np.cumsum(rng.normal(0.0, 0.003, sp.size))
    kw = dict(Kc=1.5, Ti=30.0)
    direct = _ops(load_controller(name, action=-1.0, **kw), sp, pv)
    mirrored = _ops(load_controller(name, **kw), -sp, -pv)
    np.testing.assert_array_equal(direct, mirrored)
    # and not the reverse-acting block on the same signals: the output moves the other way
    plain = _ops(load_controller(name, **kw), sp, pv)
    assert np.corrcoef(np.diff(direct), np.diff(plain))[0, 1] < 0.0


@pytest.mark.parametrize("name", ["pi", "knocker", "learned"])
def test_direct_acting_blocks_hold_a_level_on_an_outlet_valve(name, stick_slip):
    kw = dict(Kc=2.0, Ti=60.0, **({"S": 0.03} if name == "knocker" else {}))
    held, _ = stick_slip(load_controller(name, action=-1.0, **kw), S=0.03, J=0.02, outlet=True)
    assert abs(np.mean(held[1500:]) - 1.0) < 0.01                 # around the set point
    lost, _ = stick_slip(load_controller(name, **kw), S=0.03, J=0.02, outlet=True)   # the reverse action: closed
    assert abs(np.mean(lost[1500:]) - 1.0) > 0.2


def test_action_per_loop_mixes_both_kinds_in_one_batch():
    sp, pv = np.array([1.0, 1.0]), np.array([0.99, 0.99])
    blk = load_controller("knocker", Kc=1.0, Ti=10.0, S=0.02, action=np.array([1.0, -1.0]))
    blk.reset(sp, pv, np.array([0.5, 0.5]))
    op = blk.step(sp, pv)
    assert op[0] > 0.5 > op[1]                  # the level is low: open an inflow valve, close an outlet valve


@pytest.mark.parametrize("bad", [0.0, 2.0, -0.5, np.array([1.0, 0.0])])
def test_an_action_other_than_plus_or_minus_one_is_refused(bad):
    for name in ("pi", "learned"):
        with pytest.raises(ValueError, match="action.*\\+1 .*-1"):
            load_controller(name, Kc=1.0, Ti=10.0, action=bad)
    if np.ndim(bad) == 0:
        with pytest.raises(ValueError, match="action.*\\+1 .*-1"):
            load_controller("learned_network", action=bad)


def test_a_negative_gain_is_refused_with_the_way_to_a_direct_acting_loop():
    with pytest.raises(ValueError, match="Kc .*positive whichever way the loop acts \\(see action\\)"):
        load_controller("pi", Kc=-1.0, Ti=10.0)


def test_a_subclass_that_calls_super_is_mirrored_once():
    from valve_gym.agents.controllers.knocker import Knocker

    class Logged(Knocker):
        name = "logged_knocker"

        def advance(self, state, sp, pv):
            return super().advance(state, sp, pv)

    sp, pv = np.full(40, 1.0), 1.0 + 0.01 * np.sin(np.arange(40) / 5.0)
    kw = dict(Kc=1.0, Ti=10.0, S=0.02, action=-1.0)
    np.testing.assert_array_equal(_ops(Logged(**kw), sp, pv), _ops(Knocker(**kw), sp, pv))
