"""The adaptive stiction compensator: the block, its file (safetensors + JSON, validated) and its training."""
from __future__ import annotations

import json

import numpy as np
import pytest

from valve_gym.agents.adaptive import DEFAULT_ADAPTIVE, load_adaptive, save_adaptive
from valve_gym.agents.adaptive_train import AdaptiveTrainConfig, to_params, to_z, train_adaptive
from valve_gym.agents.controllers.adaptive import PARAM_NAMES, PARAMS, AdaptiveStiction

MID = np.array([(p[2] + p[3]) / 2.0 for p in PARAMS])


def test_block_is_bumpless_and_has_integral_action(stick_slip):
    blk = AdaptiveStiction(Kc=2.0, Ti=60.0)
    blk.reset(1.0, 1.0, 0.4)
    assert blk.step(1.0, 1.0) == 0.4
    ys, _ = stick_slip(AdaptiveStiction(Kc=2.0, Ti=60.0), S=0.0, J=0.0)
    assert abs(ys[-500:].mean() - 1.0) < 2e-3               # no steady offset on a healthy valve


def test_stick_band_estimate_follows_the_valve(stick_slip):
    est = {}
    for S in (0.01, 0.05):
        _, shat = stick_slip(AdaptiveStiction(Kc=2.0, Ti=60.0, **dict(zip(PARAM_NAMES, MID))), S, S / 2)
        est[S] = shat[-1]
    assert est[0.05] > 2.0 * est[0.01]


def test_settings_are_checked():
    with pytest.raises(ValueError, match="k_k"):
        AdaptiveStiction(k_k=5.0)
    with pytest.raises(ValueError, match="unknown setting"):
        AdaptiveStiction(S=0.02)


def test_file_round_trip_and_validation(tmp_path):
    v = MID.copy()
    save_adaptive(tmp_path / "a", v, {"seed": 1})
    blk = load_adaptive(tmp_path / "a.json", Kc=1.5, scan_s=2.0)
    assert blk.p["k_k"] == v[0] and blk.p["Kc"] == 1.5 and blk.scan_s == 2.0
    with pytest.raises(ValueError, match="outside"):
        save_adaptive(tmp_path / "b", np.where(np.arange(v.size) == 0, 99.0, v), {})
    from safetensors.numpy import save_file

    meta = json.loads((tmp_path / "a.json").read_text())
    for bad, match in [(v.astype(np.float32), "float64"), (v[:3], "shape"), (np.full(v.size, np.nan), "finite")]:
        save_file({"params": bad}, str(tmp_path / "c.safetensors"))
        (tmp_path / "c.json").write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=match):
            load_adaptive(tmp_path / "c.json")
    (tmp_path / "c.json").write_text(json.dumps({**meta, "format": "other"}))
    with pytest.raises(ValueError, match="format"):
        load_adaptive(tmp_path / "c.json")


def test_shipped_file_loads_through_the_registry():
    from valve_gym.agents import load_controller

    assert DEFAULT_ADAPTIVE.is_file()
    blk = load_controller("learned", Kc=1.0, Ti=30.0, scan_s=0.5)
    blk.reset(np.ones(3), np.ones(3), np.full(3, 0.5))
    assert np.asarray(blk.step(np.ones(3), np.full(3, 0.99))).shape == (3,)


def test_parameter_map_round_trips():
    np.testing.assert_allclose(to_params(to_z(MID)), MID)


def test_tiny_training_is_bit_reproducible():
    cfg = AdaptiveTrainConfig(generations=2, pairs=2, loops=3, episode_s=120.0)
    a, _ = train_adaptive(cfg)
    b, _ = train_adaptive(cfg)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, np.asarray(cfg.init))     # the update moved the numbers


def test_travel_rule_is_checked_and_only_moves_the_travel_term():
    from valve_gym.agents.adaptive_train import draw_loops, evaluate
    from valve_gym.config import ConfigError

    with pytest.raises(ConfigError, match="travel_rule"):
        AdaptiveTrainConfig(travel_rule="mean")
    with pytest.raises(ConfigError, match="travel_limit"):
        AdaptiveTrainConfig(travel_limit=0.0)
    base = AdaptiveTrainConfig(loops=4, episode_s=300.0, w_travel=0.0)
    loops = draw_loops(base, 0)
    P = to_params(np.vstack([to_z(base.init), to_z(base.init) + 0.5]))
    f = {rule: evaluate(loops, P, AdaptiveTrainConfig(loops=4, episode_s=300.0, w_travel=0.0, travel_rule=rule))
         for rule in ("per_loop", "median")}
    np.testing.assert_array_equal(f["per_loop"], f["median"])      # without a travel weight the rule is moot
    charged = evaluate(loops, P, AdaptiveTrainConfig(loops=4, episode_s=300.0, travel_rule="median",
                                                     travel_limit=1e-6))
    assert np.all(charged < f["median"])          # a limit no valve meets is charged


def test_shipped_file_records_its_objective_and_the_first_file_still_loads(repo_module):
    meta = json.loads(DEFAULT_ADAPTIVE.read_text())
    assert meta["config"]["travel_rule"] == "median" and meta["config"]["travel_limit"] == 1.5
    first = DEFAULT_ADAPTIVE.parents[3] / "benchmarks" / "data" / "adaptive_first_objective.json"
    blk = load_adaptive(first)
    assert blk.p["beta"] == pytest.approx(0.536, abs=1e-3)
    val = repo_module("benchmarks/adaptive_validation.py", "adaptive_validation")
    with pytest.raises(SystemExit) as exc:
        val.main([str(first), "--vary", "beta=9"])
    assert exc.value.code == 2


def test_broad_family_extends_the_core_draw_and_is_checked():
    from valve_gym.agents.adaptive_train import FAMILIES, draw_loop
    from valve_gym.config import ConfigError

    with pytest.raises(ConfigError, match="family"):
        AdaptiveTrainConfig(family="wide")
    with pytest.raises(ValueError, match="family"):
        draw_loop(np.random.default_rng(0), family="wide")
    kinds, thetas = set(), []
    for i in range(40):
        core, _, _ = draw_loop(np.random.default_rng([7, i]), episode_s=600.0)
        broad, load, noise = draw_loop(np.random.default_rng([7, i]), episode_s=600.0, family="broad")
        assert "theta" not in core and core["scan"] in FAMILIES["core"]
        assert broad["scan"] in FAMILIES["broad"] and load.size == noise.size == round(600.0 / broad["scan"])
        for k in ("kind", "band", "model", "S", "J", "area", "q_max", "T", "noise"):   # the core loop, then extras
            assert broad[k] == core[k]
        assert np.isfinite(load).all() and np.isfinite(noise).all()
        kinds.add(broad["load_kind"])
        thetas.append(broad["theta"] / (broad["T"] if broad["kind"] == "first_order" else 1.0))
        assert 0.05 <= broad["tau_s"] <= 8.0 and 0.25 <= broad["tc_factor"] <= 2.5
    assert kinds == {"ou", "walk", "sine", "step"}
    assert min(thetas) == 0.0 and max(thetas) > 1.0          # loops without delay and dead-time-dominant ones


def test_broad_family_loops_run_with_their_dead_time_and_sensor_lag():
    """A broad draw's plants carry the delay and lag: the frictionless PI still holds the set point, and
    the measured error (through the sensor lag) is what is scored."""
    from valve_gym.agents.adaptive_train import PI_COLUMN, draw_loops, score_columns

    loops = draw_loops(AdaptiveTrainConfig(loops=8, episode_s=900.0, family="broad"), 3)
    assert any(r["theta"] > 0 for r in loops.rows)
    sc = score_columns(loops, PI_COLUMN[None, :])
    assert np.isfinite(sc["iae"]).all() and np.isfinite(sc["travel"]).all()
    sticky = ~sc["healthy"]
    if sticky.any():                    # the PI on a sticky valve is worse than on the frictionless one
        assert np.median(sc["iae"][1, sticky] / sc["iae"][2, sticky]) > 1.0


def test_a_trained_file_is_a_policy_row_with_each_loops_tuning():
    """``valve-gym benchmark --policy adaptive.json`` and the held-out scripts' ``--policy``: the file's numbers,
    rebuilt per loop with that loop's tuning and scan (``for_loop``), under the row's label."""
    from valve_gym.agents.bench.policies import as_block

    blk = as_block(str(DEFAULT_ADAPTIVE), name="mine")
    assert isinstance(blk, AdaptiveStiction) and blk.name == "mine"
    loop = blk.for_loop(2.5, 80.0, 0.5)
    assert loop.name == "mine" and loop.scan_s == 0.5
    assert loop.settings["Kc"] == 2.5 and loop.settings["Ti"] == 80.0
    assert all(loop.settings[k] == blk.settings[k] for k in PARAM_NAMES)
    switched = AdaptiveStiction(answer=1.0, k_i=0.5, Kc=1.0, Ti=30.0).for_loop(2.0, 60.0, 1.0)
    assert switched.settings["answer"] == 1.0 and switched.settings["k_i"] == 0.5     # untrained switches kept
    with pytest.raises(ValueError, match="^mine: setting Kc"):
        blk.for_loop(-1.0, 80.0, 0.5)


def _relaxing_error(blk, T=400):
    """A stuck valve on a first-order process: the error rises and settles at a plateau without ever turning."""
    blk.reset(1.0, 1.0, 0.5)
    armed = []
    for k in range(T):
        blk.step(1.0, 1.0 - 0.02 * (1.0 - np.exp(-k / 40.0)))
        armed.append(float(blk.state.armed[0]))
    return np.array(armed)


def test_reversal_answer_test_ignores_a_process_settling_while_the_stem_sticks():
    kw = dict(zip(PARAM_NAMES, MID), k_k=0.0, k_c=0.0, Kc=1.0, Ti=50.0)
    turn = _relaxing_error(AdaptiveStiction(answer=0.0, **kw))
    rev = _relaxing_error(AdaptiveStiction(answer=1.0, **kw))
    assert turn.max() == 1.0 and turn[-1] == 0.0        # armed at the reversal, then "answered" by the settling
    assert rev.max() == 1.0 and rev[-1] == 1.0          # still waiting: the trend never turned against the output


def test_trained_file_names_its_answer_test(tmp_path):
    from valve_gym.agents.adaptive import ANSWERS
    from valve_gym.config import ConfigError

    assert load_adaptive().settings["answer"] == 1.0                # the shipped file: trained with "reversal"
    turn = DEFAULT_ADAPTIVE.parents[3] / "benchmarks" / "data" / "adaptive_turn_test.json"
    assert load_adaptive(turn).settings["answer"] == 0.0            # the file before it names no test: "turn"
    save_adaptive(tmp_path / "rev", MID, {"answer": "reversal"})
    assert load_adaptive(tmp_path / "rev").settings["answer"] == ANSWERS["reversal"] == 1.0
    save_adaptive(tmp_path / "odd", MID, {"answer": "sideways"})
    with pytest.raises(ValueError, match="answer 'sideways' is not one of"):
        load_adaptive(tmp_path / "odd")
    with pytest.raises(ConfigError, match="answer"):
        AdaptiveTrainConfig(answer="sideways")
    save_adaptive(tmp_path / "boost", MID, {"k_i": 0.5})
    assert load_adaptive(tmp_path / "boost").settings["k_i"] == 0.5
    for bad in (-1.0, 11.0, "fast", True):
        save_adaptive(tmp_path / "bad", MID, {"k_i": bad})
        with pytest.raises(ValueError, match="k_i must be a number in"):
            load_adaptive(tmp_path / "bad")


def test_integral_boost_acts_only_while_a_reversal_awaits_its_answer():
    kw = dict(zip(PARAM_NAMES, MID), k_k=0.0, k_c=0.0, Kc=1.0, Ti=10.0)
    runs = {}
    for k_i in (0.0, 1.0):
        blk = AdaptiveStiction(k_i=k_i, **kw)
        blk.reset(1.0, 1.0, 0.5)
        integral, armed = [], []
        for _ in range(6):                              # a steady error: the integral turns up and waits
            blk.step(1.0, 0.99)
            integral.append(float(blk.state.pi.integral[0]))
            armed.append(float(blk.state.armed[0]))
        runs[k_i] = (np.diff(integral), armed)
    plain, boosted = runs[0.0][0], runs[1.0][0]
    armed = np.array(runs[1.0][1])
    assert armed[0] == 0.0 and armed[-1] == 1.0 and runs[0.0][1] == runs[1.0][1]   # it turns, then no answer
    waiting = armed[:-1] == 1.0                            # increments of the scans that start armed
    np.testing.assert_allclose(boosted[waiting], 2.0 * plain[waiting])   # (1 + k_i) times the PI's own
    np.testing.assert_allclose(boosted[~waiting], plain[~waiting])       # before the turn: the plain PI
    assert load_adaptive().settings["k_i"] == 0.0         # files without it: no boost


def test_integral_dead_zone_holds_the_integral_inside_its_band_and_is_off_by_default():
    kw = dict(zip(PARAM_NAMES, MID), k_k=0.0, k_c=0.0, S0=0.02, f_tau=0.02, Kc=2.0, Ti=10.0)
    band = 1.0 * 0.02 / (2.0 * 2.0)                        # k_z S_hat / (2 Kc) = 5 mm at the start
    runs = {}
    for k_z in (0.0, 1.0):
        blk = AdaptiveStiction(k_z=k_z, **kw)
        blk.reset(1.0, 1.0, 0.5)
        steps = []
        for pv in (0.998, 0.998, 0.97, 0.97):             # 2 mm error: inside the band; 30 mm: outside
            i0 = float(blk.state.pi.integral[0])
            blk.step(1.0, pv)
            steps.append(float(blk.state.pi.integral[0]) - i0)
            assert abs(float(blk.state.e_f[0])) < band or pv == 0.97
        runs[k_z] = np.array(steps)
    assert (runs[0.0] > 0).all()                          # the PI integrates every scan
    np.testing.assert_array_equal(runs[1.0][:2], 0.0)     # inside the band: held
    assert (runs[1.0][2:] > 0).all()                      # outside it: integrates again (the filtered error left it)
    assert load_adaptive().settings["k_z"] == 0.0          # the shipped file: no dead zone


def test_integral_dead_zone_in_a_file_is_checked(tmp_path):
    save_adaptive(tmp_path / "quiet", MID, {"k_z": 1.0})
    assert load_adaptive(tmp_path / "quiet").settings["k_z"] == 1.0
    for bad in (-0.5, 5.0, "wide", False):
        save_adaptive(tmp_path / "bad", MID, {"k_z": bad})
        with pytest.raises(ValueError, match="k_z must be a number in"):
            load_adaptive(tmp_path / "bad")
    with pytest.raises(ValueError, match="k_z"):
        AdaptiveStiction(k_z=-1.0, Kc=1.0, Ti=10.0)


def test_integral_dead_zone_breaks_a_stick_slip_cycle_at_the_price_of_an_offset(stick_slip):
    """On an integrating level with a slip-jump valve the PI's cycle goes with a dead zone sized to it; what is
    left is a steady error inside the band (the trade-off docs/learned.md measures on whole families)."""
    from valve_gym.oscillation import detect_oscillation

    kw = dict(zip(PARAM_NAMES, MID), Kc=2.0, Ti=60.0)
    found = {}
    for k_z in (0.0, 1.0):
        ys, _ = stick_slip(AdaptiveStiction(k_z=k_z, **kw), S=0.04, J=0.03, T=3000)
        e = 1.0 - ys[1500:]
        found[k_z] = (detect_oscillation(e, 1.0).present, abs(e.mean()))
    assert found[0.0][0] and not found[1.0][0]             # the regular cycle is gone
    assert found[1.0][1] > 5.0 * max(found[0.0][1], 1e-4)  # and a steady offset took its place


def _pending(blk, state, trend, o, flipped=False):
    """One call of the block's estimate with the output at ``o`` and the error's trend ``trend`` (d = +1)."""
    one = np.ones(1)
    return blk._estimate(state, np.array([flipped]), one, o * one, state.o_flip, trend * one, 0.001 * one)


@pytest.mark.parametrize("confirm", [0.0, 1.0])
def test_an_answer_must_hold_for_confirm_filter_time_constants(confirm):
    kw = dict(zip(PARAM_NAMES, MID), Kc=1.0, Ti=100.0, f_tau=0.05, scan_s=1.0, answer=1.0, confirm=confirm)
    blk = AdaptiveStiction(**kw)
    st = blk.initial_state(np.ones(1), np.ones(1), np.full(1, 0.5))
    st = st._replace(d=np.ones(1), armed=np.ones(1), o_flip=np.full(1, 0.5), trend0=np.zeros(1), s_hat=np.full(1, 0.02))
    # the error's trend turns against the output (d = +1) after a travel of 0.01: an answer, or one to confirm
    s_hat, armed, p_travel, p_age = _pending(blk, st, -1.0, 0.51)
    if confirm == 0.0:
        assert armed[0] == 0.0 and s_hat[0] != 0.02           # taken at once
        return
    assert armed[0] == 1.0 and s_hat[0] == 0.02 and p_age[0] == 0.0 and p_travel[0] == pytest.approx(0.01)
    # the turn goes back before the window (confirm f_tau Ti = 5 s = 5 scans): no answer, still waiting
    st1 = st._replace(armed=armed, p_travel=p_travel, p_age=p_age)
    s_hat, armed, p_travel, p_age = _pending(blk, st1, +1.0, 0.52)
    assert armed[0] == 1.0 and s_hat[0] == 0.02 and p_age[0] == -1.0
    # a turn that holds for the window counts, with the travel at the turn (not the output's later travel)
    st2 = st1._replace(armed=armed, p_travel=p_travel, p_age=p_age)
    for k in range(6):                                        # the turn, then five scans that hold it
        s_hat, armed, p_travel, p_age = _pending(blk, st2, -1.0, 0.53 + 0.01 * k)
        st2 = st2._replace(s_hat=s_hat, armed=armed, p_travel=p_travel, p_age=p_age)
        assert (armed[0] == 1.0) == (k < 5) and (s_hat[0] == 0.02) == (k < 5)
    beta, eta, rho = MID[PARAM_NAMES.index("beta")], MID[PARAM_NAMES.index("eta")], MID[PARAM_NAMES.index("rho")]
    meas = beta * 0.03 - 0.02                                 # the turn came at 0.53 - 0.50
    assert s_hat[0] == pytest.approx(0.02 + eta * (1.0 if meas > 0 else rho) * meas)
    assert load_adaptive().settings["confirm"] == 0.0        # the shipped file: answers taken at once


def test_a_training_config_names_the_confirm_window_and_its_file_keeps_it(tmp_path):
    from valve_gym.agents.adaptive_train import load_train_config
    from valve_gym.config import ConfigError

    cfg = AdaptiveTrainConfig(generations=1, pairs=1, loops=2, episode_s=120.0, confirm=0.5)
    train_adaptive(cfg, tmp_path)
    assert json.loads((tmp_path / "adaptive.json").read_text())["confirm"] == 0.5
    assert load_adaptive(tmp_path / "adaptive.json").settings["confirm"] == 0.5
    assert load_train_config(DEFAULT_ADAPTIVE.parents[3] / "configs" / "learned_adaptive_confirm.yaml").confirm == 0.5
    for bad in (-1.0, 6.0, True):
        with pytest.raises(ConfigError, match="confirm must be a number in"):
            AdaptiveTrainConfig(confirm=bad)
