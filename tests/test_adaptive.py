"""The adaptive stiction compensator: the block, its file (safetensors + JSON, validated) and its training."""
from __future__ import annotations

import json

import numpy as np
import pytest

from valve_gym.agents.adaptive import DEFAULT_ADAPTIVE, load_adaptive, save_adaptive
from valve_gym.agents.adaptive_train import AdaptiveTrainConfig, to_params, to_z, train_adaptive
from valve_gym.agents.controllers.adaptive import PARAM_NAMES, PARAMS, AdaptiveStiction

MID = np.array([(p[2] + p[3]) / 2.0 for p in PARAMS])


def _stick_slip_loop(blk, S, J, T=3000, seed=0):
    """An integrating level with a two-parameter stick-slip valve (a loop written here, no core code)."""
    rng = np.random.default_rng(seed)
    x, ref, last = 0.5, 0.5, 1.0
    y, sp = 1.0, 1.0
    blk.reset(sp, y, 0.5)
    ys, shat = [], []
    for _ in range(T):
        u = blk.step(sp, y + 0.001 * rng.standard_normal())
        d = u - ref
        if abs(d) > (J if d * last > 0 else S):
            last = np.sign(d)
            x, ref = u - last * (S - J) / 2.0, u
        y += (0.01 * x - 0.0052) / 0.5                      # pumped outlet slightly above the valve's flow
        ys.append(y)
        shat.append(blk.state.s_hat[0])
    return np.array(ys), np.array(shat)


def test_block_is_bumpless_and_has_integral_action():
    blk = AdaptiveStiction(Kc=2.0, Ti=60.0)
    blk.reset(1.0, 1.0, 0.4)
    assert blk.step(1.0, 1.0) == 0.4
    ys, _ = _stick_slip_loop(AdaptiveStiction(Kc=2.0, Ti=60.0), S=0.0, J=0.0)
    assert abs(ys[-500:].mean() - 1.0) < 2e-3               # no steady offset on a healthy valve


def test_stick_band_estimate_follows_the_valve():
    est = {}
    for S in (0.01, 0.05):
        _, shat = _stick_slip_loop(AdaptiveStiction(Kc=2.0, Ti=60.0, **dict(zip(PARAM_NAMES, MID))), S, S / 2)
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
    blk = load_controller("learned_adaptive", Kc=1.0, Ti=30.0, scan_s=0.5)
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
