"""Controller blocks (valve_gym.agents.controllers): the DCS interface, the registry and each compensator's law."""
import json
import sys
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from valve_gym import core
from valve_gym.agents import available_controllers, load_controller
from valve_gym.agents.controllers import ConstantReinforcement, IntegralFreeze, Knocker, PIBlock, TwoMove
from valve_gym.agents.controllers.registry import ControllerLoadError
from valve_gym.agents.controllers.two_move import HOLD, NORMAL, ValveEstimate, valve_estimate
from valve_gym.params import ModelParams, SlipJump

BLOCKS = ["pi", "knocker", "constant_reinforcement", "two_move", "integral_freeze"]


def _signals(T, n, seed):
    rng = np.random.default_rng(seed)
    sp = 1.0 + 0.05 * (np.arange(T)[:, None] >= T // 2) * rng.uniform(-1, 1, n)
    pv = sp + np.cumsum(rng.normal(0, 0.003, (T, n)), axis=0) * 0.5 + rng.normal(0, 0.002, (T, n))
    return sp, pv


# ----------------------------------------------------------------------------------------- interface
def test_available_controllers():
    assert available_controllers() == ("pi", "knocker", "constant_reinforcement", "two_move",
                                       "integral_freeze", "learned", "learned_network")


@pytest.mark.parametrize("name", BLOCKS)
def test_scalar_and_batched_runs_agree(name):
    T, n = 300, 4
    sp, pv = _signals(T, n, seed=3)
    op0 = np.array([0.3, 0.5, 0.7, 0.45])
    batched = load_controller(name)
    batched.reset(sp[0], pv[0], op0)
    singles = [load_controller(name) for _ in range(n)]
    for i, c in enumerate(singles):
        c.reset(float(sp[0, i]), float(pv[0, i]), float(op0[i]))
    for t in range(T):
        ob = batched.step(sp[t], pv[t])
        assert isinstance(ob, np.ndarray) and ob.shape == (n,)
        os_ = [c.step(float(sp[t, i]), float(pv[t, i])) for i, c in enumerate(singles)]
        assert all(isinstance(o, float) for o in os_)
        np.testing.assert_array_equal(ob, np.array(os_))
        assert np.all((ob >= 0.0) & (ob <= 1.0))


@pytest.mark.parametrize("name", BLOCKS)
def test_bumpless_reset(name):
    ctrl = load_controller(name)
    ctrl.reset(1.2, 1.2, 0.37)
    assert ctrl.step(1.2, 1.2) == 0.37                    # no error: the output stays where it was
    ctrl.reset([1.0, 1.0], [1.0, 0.9], [0.6, 0.6])
    op = np.asarray(ctrl.step([1.0, 1.0], [1.0, 0.9]))
    assert op[0] == 0.6
    kc, ti = ctrl.settings["Kc"], ctrl.settings["Ti"]
    if name in ("pi", "integral_freeze"):               # with an error: one integral step, no P kick
        assert op[1] == pytest.approx(0.6 + kc / ti * 0.1)


def test_scalar_setpoint_is_shared_by_all_loops():
    c = load_controller("pi", Kc=1.0, Ti=10.0)
    c.reset(1.0, [1.0, 0.9], [0.5, 0.5])
    np.testing.assert_allclose(c.step(1.0, [1.0, 0.9]), [0.5, 0.51])
    np.testing.assert_allclose(c.step(1.0, 1.0), [0.5, 0.41])   # scalar pv too: both loops at 1.0


@pytest.mark.parametrize("name", BLOCKS)
def test_settings_are_resolved_and_json(name):
    ctrl = load_controller(name, S=0.03) if name != "pi" else load_controller(name)
    s = ctrl.settings
    assert all(v is not None for v in s.values())
    again = load_controller(name, **json.loads(json.dumps(s)))
    assert again.settings == s
    assert ctrl.name == name and ctrl.scan_s == 1.0
    assert s["Kc"] == pytest.approx(1.887, abs=1e-3) and s["Ti"] == pytest.approx(42.4, abs=1e-6)


def test_detune_scales_the_gain():
    c = PIBlock(detune=0.5)
    assert c.settings == load_controller("pi", detune=0.5).settings
    assert c.settings["detune"] == 0.5 and c.Kc == pytest.approx(0.5 * c.settings["Kc"])
    c.reset(1.0, 1.0, 0.5)
    assert c.step(1.0, 0.9) == pytest.approx(0.5 + c.Kc * 0.1 + c.Kc / c.Ti * 0.1)


def test_anti_windup_by_output_tracking():
    pi = PIBlock(Kc=2.0, Ti=20.0)
    pi.reset(1.0, 0.5, 0.5)
    for _ in range(500):                        # +0.5 m error for 500 s: the output saturates
        op = pi.step(1.0, 0.5)
    assert op == 1.0
    assert pi.state.integral[0] == pytest.approx(1.0 - 2.0 * 0.5)   # integral tracks the limit
    assert pi.step(1.0, 1.01) < 1.0             # error changes sign: off the limit at the next scan
    # a compensator's addition is clipped, and the integral still tracks only the clipped part
    k = Knocker(Kc=2.0, Ti=20.0, a=0.2)
    k.reset(1.0, 0.5, 0.9)
    for _ in range(100):
        assert k.step(1.0, 0.5) <= 1.0
    assert k.state.pi.integral[0] <= 1.0 - 2.0 * 0.5 + 1e-12
    assert k.step(1.0, 1.01) < 1.0


# -------------------------------------------------------------------------------------------- errors
def test_unknown_name_lists_the_controllers():
    with pytest.raises(ValueError, match="unknown controller 'pid'; available: pi, knocker, "
                                         "constant_reinforcement, two_move, integral_freeze, learned"):
        load_controller("pid")


@pytest.mark.parametrize("name,kw,msg", [
    ("pi", {"kc": 1.0}, r"unknown setting\(s\) \['kc'\]; known settings: Kc \[1/m\] in \(0, 10000\]"),
    ("pi", {"Kc": "2"}, r"Kc must be a number .* got '2' of type str"),
    ("pi", {"Kc": True}, r"Kc must be a number"),
    ("pi", {"Ti": -1.0}, r"Ti = -1.0 is out of range; allowed: Ti \[s\] in \(0, 1e\+06\]"),
    ("pi", {"Kc": float("nan")}, r"Kc = nan is out of range"),
    ("pi", {"op_lo": 0.6, "op_hi": 0.4}, "op_lo < op_hi"),
    ("knocker", {"S": 0.7}, r"S = 0.7 is out of range; allowed: S \[-\] in \[0, 0.5\]"),
    ("knocker", {"tau_k": 0.5}, "whole number"),
    ("knocker", {"h_k": 1.0}, "h_k > tau_k"),
    ("constant_reinforcement", {"S": 0.02, "J": 0.03}, "J <= S"),
    ("two_move", {"S": 0.02, "J": 0.03}, "J <= S"),
    ("two_move", {"S": 0.0, "noise": 0.0}, "no default release band"),
    ("integral_freeze", {"band": -1.0}, r"band = -1.0 is out of range"),
])
def test_bad_settings(name, kw, msg):
    with pytest.raises(ValueError, match=msg):
        load_controller(name, **kw)


def test_bad_signals():
    c = load_controller("knocker")
    with pytest.raises(ValueError, match=r"step\(\) called before reset\(\); call reset\(sp, pv, op\) first"):
        c.step(1.0, 1.0)
    with pytest.raises(ValueError, match=r"different lengths \{'sp': 2, 'pv': 3\}"):
        c.reset([1.0, 1.0], [1.0, 1.0, 1.0], 0.5)
    with pytest.raises(ValueError, match=r"pv contains NaN or inf at loop\(s\) \[1\]"):
        c.reset([1.0, 1.0], [1.0, np.nan], 0.5)
    with pytest.raises(ValueError, match=r"op must be the valve input now applied, within the output limits"):
        c.reset(1.0, 1.0, 1.5)
    with pytest.raises(ValueError, match=r"scalar or an \(n,\) array"):
        c.reset(np.ones((2, 2)), 1.0, 0.5)
    with pytest.raises(ValueError, match="must be a number or an"):
        c.reset("one", 1.0, 0.5)
    c.reset([1.0, 1.0], [1.0, 1.0], [0.5, 0.5])
    with pytest.raises(ValueError, match=r"reset\(\) was given 2 loop\(s\) but step\(\) 3"):
        c.step([1.0] * 3, [1.0] * 3)
    with pytest.warns(RuntimeWarning, match="output held"):
        held = c.step(1.0, [1.0, np.inf])               # a bad PV holds that loop's output (DCS bad-PV hold)
    assert held[1] == 0.5 and c.held.tolist() == [False, True]
    assert np.shape(c.step(1.0, [1.0, 1.0])) == (2,)      # the block is still usable


def test_learned_network_is_loaded_lazily_and_failures_say_why(monkeypatch):
    seen = {}

    def load_learned(path=None, **settings):
        seen.update(path=path, **settings)
        if path == "missing":
            raise FileNotFoundError("no weights in 'missing'")
        return PIBlock()

    monkeypatch.setitem(sys.modules, "valve_gym.agents.learned", types.SimpleNamespace(load_learned=load_learned))
    assert isinstance(load_controller("learned_network", path="run1", S=0.02), PIBlock)
    assert seen == {"path": "run1", "S": 0.02, "name": "learned_network"}
    with pytest.raises(ControllerLoadError, match="learned network could not be loaded: "
                                                  "FileNotFoundError: no weights in 'missing'"):
        load_controller("learned_network", path="missing")
    monkeypatch.setitem(sys.modules, "valve_gym.agents.learned", None)      # module not importable
    with pytest.raises(ValueError, match="learned network could not be loaded: module valve_gym.agents.learned"):
        load_controller("learned_network")


# ----------------------------------------------------------------------------------------------- laws
def _pi_part(block, e):
    return block.state.pi.integral + block.pi.Kc * np.asarray(e)


def test_constant_reinforcement_adds_exactly_plus_minus_a():
    cr = ConstantReinforcement(S=0.04, Kc=1.0, Ti=10.0, noise=0.0)
    a = cr.settings["a"]
    assert a == pytest.approx((0.04 - 0.02) / 2)             # (S - J)/2 with J = S/2
    cr.reset(1.0, 1.0, 0.5)
    errors = [0.01] * 20 + [-0.01] * 40 + [0.01] * 40
    added = []
    for e in errors:
        op = cr.step(1.0, 1.0 - e)
        added.append(op - _pi_part(cr, e)[0])
    added = np.round(added, 12)
    assert set(np.unique(added)) <= {-a, 0.0, a}
    assert np.all(added[1:20] == a) and np.all(added[22:60] == -a) and np.all(added[62:] == a)


def test_constant_reinforcement_hysteresis_ignores_noise_sized_wiggles():
    cr = ConstantReinforcement(S=0.04, Kc=1.0, Ti=10.0, hyst=0.01)
    cr.reset(1.0, 1.0, 0.5)
    for _ in range(6):
        cr.step(1.0, 0.98)                       # integral +0.002 per scan: up once past 0.01
    assert cr.state.d[0] == 1
    rng = np.random.default_rng(0)
    for _ in range(200):                         # zero-mean wiggles: the integral walks < 0.01 from its top
        cr.step(1.0, 1.0 + 0.002 * np.sign(rng.standard_normal()))
        top = cr.state.i_ext[0]
        if cr.state.pi.integral[0] < top - 0.01:
            break
        assert cr.state.d[0] == 1


def test_integral_freeze_holds_the_integral_inside_the_band():
    f = IntegralFreeze(S=0.02, noise=0.001)
    band = f.settings["band"]
    assert band == pytest.approx(max(0.02 / (2 * f.pi.Kc), 0.003))
    f.reset(1.0, 1.0, 0.5)
    i0 = f.state.integral.copy()
    for e in np.linspace(-0.99, 0.99, 50) * band:
        f.step(1.0, 1.0 - e)
        np.testing.assert_array_equal(f.state.integral, i0)
    f.step(1.0, 1.0 - 1.5 * band)
    assert f.state.integral[0] == pytest.approx(i0[0] + f.pi.Kc / f.pi.Ti * 1.5 * band)


def test_two_move_places_the_stem_and_holds():
    S, J = 0.04, 0.01
    tm = TwoMove(S=S, J=J, Kc=1.0, Ti=1.0, hyst=0.001, noise=0.0)
    tm.reset(1.0, 1.0, 0.5)
    errors = [0.005] * 4 + [-0.005] * 8 + [0.005] * 8 + [-0.005] * 8
    ops, modes, xs = [], [], []
    model = ValveEstimate(x=np.full(1, 0.5), u_s=np.full(1, 0.5), stuck=np.ones(1), d=np.zeros(1),
                          u_prev=np.full(1, 0.5))
    for e in errors:
        ops.append(tm.step(1.0, 1.0 - e))
        modes.append(tm.state.mode[0])
        model = valve_estimate(model, np.array([ops[-1]]), S, J)
        xs.append(model.x[0])
    trig = modes.index(1.0)
    assert trig == 20                             # the third reversal of the PI output (not the first cycle)
    u_hi = max(ops[:trig])
    # move 1: S above the top; the estimate (valve never moved, reversal needs S) asks 0.5 + 1.5 S < that
    assert ops[trig] == pytest.approx(max(u_hi + S, 0.5 + 1.5 * S))
    # move 2 reverses by more than S and lands the estimated stem on x_ss = the cycle's mean estimate (0.5)
    assert ops[trig] - ops[trig + 1] > S
    assert ops[trig + 1] == pytest.approx(0.5 - (S - J) / 2)
    assert xs[trig + 1] == pytest.approx(0.5)
    assert modes[trig + 1:] == [HOLD] * (len(errors) - trig - 1)
    assert all(o == ops[trig + 1] for o in ops[trig + 1:])          # held
    # release when the error leaves the band: the PI resumes from the held output without a bump
    held = ops[-1]
    big = 2 * tm.settings["release"]
    op = tm.step(1.0, 1.0 - big)
    assert tm.state.mode[0] == NORMAL
    assert op == pytest.approx(held + 1.0 * (big + 0.005) + 1.0 * big)


def test_knocker_pulse_train_on_a_ramping_integral():
    k = Knocker(S=0.03, Kc=1.0, Ti=10.0, tau_k=2.0, h_k=5.0)
    assert k.settings["a"] == 0.015
    k.reset(1.0, 1.0, 0.5)
    pulses = []
    for t in range(20):
        e = 0.01 if t < 10 else -0.01
        op = k.step(1.0, 1.0 - e)
        pulses.append(round(op - _pi_part(k, e)[0], 12))
    assert pulses[:10] == [0.015, 0.015, 0, 0, 0] * 2
    # at t = 10 the integral has fallen one step but is still above its value at the t = 5 pulse: up;
    # at t = 15 it is below its value at t = 10: down (sign of the change since the last pulse)
    assert pulses[10:] == [0.015, 0.015, 0, 0, 0, -0.015, -0.015, 0, 0, 0]


# ----------------------------------------------------------------------------------- closed loop
def _closed_loop(names_kw, S=0.02, J=0.01, T=1800, level0=0.95):
    """Default tank, Choudhury valve (slip_jump) S, J; one loop per controller; start off the set point."""
    n = len(names_kw)
    p = ModelParams().with_effect("slip_jump", SlipJump(S=S, J=J))
    st = core.initial_state(p, n=n, level=level0)
    ctrls = [load_controller(name, **kw) for name, kw in names_kw]
    y = st.y.copy()
    for i, c in enumerate(ctrls):
        c.reset(1.0, y[i], st.h[i])
    ys, hs = [], []
    for _ in range(T):
        u = np.array([c.step(1.0, y[i]) for i, c in enumerate(ctrls)])
        st, y = core.step(st, u, p, n_sub=50)
        ys.append(y.copy())
        hs.append(st.h.copy())
    return np.array(ys)[T // 3:], np.array(hs)[T // 3:]


def test_pi_cycles_on_a_sticky_valve_and_compensators_reduce_the_cycle():
    S, J = 0.02, 0.01
    ys, hs = _closed_loop([("pi", {}), ("knocker", {"S": S}), ("two_move", {"S": S, "J": J})], S, J)
    amp = (ys.max(axis=0) - ys.min(axis=0)) / 2          # half peak-to-peak of the level [m]
    dh = np.diff(hs, axis=0)
    moves = [np.sign(d[np.abs(d) > 1e-6]) for d in dh.T]
    reversals = [int(np.sum(m[1:] != m[:-1])) for m in moves]
    kc = load_controller("pi").settings["Kc"]
    # PI at a constant set point: a sustained stick-slip cycle of about S/(2 Kc) = 5.3 mm (DOMAIN O8)
    assert amp[0] > 0.6 * S / (2 * kc) and reversals[0] >= 8
    # the knocker and the two-move cut the cycle to well under half
    assert amp[1] < 0.5 * amp[0]
    assert amp[2] < 0.5 * amp[0]


# ------------------------------------------------------------------------------------ per-loop settings
@pytest.mark.parametrize("name", ["knocker", "constant_reinforcement", "two_move", "integral_freeze"])
def test_per_loop_stiction_estimates_equal_one_block_per_loop(name):
    """``S`` as an (n,) array runs each loop exactly as a block built with that loop's S."""
    S = np.array([0.005, 0.02, 0.06])
    T = 400
    sp, pv = _signals(T, 3, seed=5)
    batched = load_controller(name, S=S)
    assert batched.settings["S"] == S.tolist()
    json.dumps(batched.settings)
    singles = [load_controller(name, S=float(s)) for s in S]
    batched.reset(sp[0], pv[0], 0.5)                  # scalar op: shared by the 3 loops of the settings
    for i, c in enumerate(singles):
        c.reset(float(sp[0, i]), float(pv[0, i]), 0.5)
    for t in range(T):
        ob = np.asarray(batched.step(sp[t], pv[t]))
        np.testing.assert_array_equal(ob, [c.step(float(sp[t, i]), float(pv[t, i])) for i, c in enumerate(singles)])


def test_per_loop_settings_errors():
    with pytest.raises(ValueError, match=r"setting S\[1\] = 0.7 is out of range; allowed: S \[-\] in \[0, 0.5\]"):
        load_controller("knocker", S=[0.01, 0.7])
    with pytest.raises(ValueError, match=r"per-loop settings have different lengths \{'S': 2, 'a': 3\}"):
        load_controller("knocker", S=[0.01, 0.02], a=[0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match=r"setting scan_s must be a number \("):
        load_controller("pi", scan_s=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"J <= S .* got S = \[0.01, 0.02\], J = \[0.005, 0.03\]"):
        load_controller("two_move", S=[0.01, 0.02], J=[0.005, 0.03])
    c = load_controller("knocker", S=[0.01, 0.02])
    with pytest.raises(ValueError, match=r"per-loop settings are for 2 loops, reset\(\) got 3"):
        c.reset(1.0, [1.0, 1.0, 1.0], 0.5)


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(BLOCKS), data=st.data())
def test_any_setting_in_range_is_accepted_and_any_outside_is_refused(name, data):
    from valve_gym.agents.controllers.registry import _BLOCKS

    table = {s.name: s for s in _BLOCKS[name].SETTINGS}
    key = data.draw(st.sampled_from(sorted(k for k in table if k not in ("tau_k", "h_k", "op_lo", "op_hi", "action"))))
    s = table[key]
    ok = data.draw(st.floats(min_value=s.lo, max_value=s.hi, exclude_min=s.lo_open, allow_nan=False))
    kw = {key: ok}
    if key == "J":
        kw["S"] = 0.5                    # J <= S for any J in range
    if key == "S" and "J" in table:
        kw["J"] = 0.0
    if name == "two_move" and key in ("S", "noise"):
        kw["release"] = 0.01
    bad = data.draw(st.one_of(st.floats(min_value=s.hi, exclude_min=True, allow_infinity=True),
                              st.floats(max_value=s.lo, exclude_max=not s.lo_open, allow_infinity=True),
                              st.just(float("nan"))))
    with pytest.raises(ValueError, match=f"{key}.*out of range"):
        load_controller(name, **{key: bad})
    try:
        ctrl = load_controller(name, **kw)
    except ValueError as exc:            # a rule-derived setting would leave its range: said so, and how to fix
        assert " or give " in str(exc) and "explicitly" in str(exc) and "the rule for" in str(exc)
        assert "check the settings it is made from (" in str(exc)
        return
    assert ctrl.settings[key] == pytest.approx(ok)
    assert load_controller(name, **json.loads(json.dumps(ctrl.settings))).settings == ctrl.settings
