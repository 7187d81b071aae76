"""How the diagnosis pairs the controller output with the PV (``op_lag``)."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.stiction.loops import LoopSpec, simulate_loop
from valve_gym.diagnosis.synthetic import make_case

# a textbook level loop: its simulator logs op[k] computed from the pv[k] beside it
SCAN_LOGGED = LoopSpec(process="tank", valve="linear", S=0.0, J=0.0, area=0.25, q_max=0.012, c_out=0.005, Kc=3.0,
                       Ti=60.0, Ts=1.0, theta=0.0, noise=0.003, tau_v=0.2, n=600, sp_moves=0.3)


def test_auto_pairs_a_scan_logged_record_with_the_next_pv():
    rec = simulate_loop(SCAN_LOGGED, seed=0)
    res = diagnose(rec, candidates=(), effort="fast", op_lag="auto")
    test = res.settings["op_lag_test"]
    assert test["tested"] and test["method"] == "controller reaction" and res.settings["op_lag"] == 1
    r = test["controller_reaction"]
    assert r["reaction"]["0"] - r["reaction"]["1"] > r["margin"] > 0
    assert "delta_ic" not in test                      # decided before fitting: one base fit only
    assert len(res.recording) == len(rec) - 1
    np.testing.assert_array_equal(res.recording.op, rec.op[:-1])
    np.testing.assert_array_equal(res.recording.pv, rec.pv[1:])
    from valve_gym.diagnosis.report import render_markdown
    md = render_markdown(res)
    assert "**Pairing of OP and PV:** each controller output paired with the PV of the next sample" in md
    assert "read from the controller's reaction to the PV" in md


def test_auto_keeps_the_models_own_pairing():
    rec = make_case("none", seed=0, n=1800).recording     # the package's generator: pv[k] after op[k] acted
    res = diagnose(rec, candidates=(), effort="fast", op_lag="auto")
    test = res.settings["op_lag_test"]
    assert res.settings["op_lag"] == 0 and test["method"] == "controller reaction"
    assert test["controller_reaction"]["reaction"]["1"] > test["controller_reaction"]["reaction"]["0"]
    assert len(res.recording) == len(rec)


def test_auto_without_a_controller_fits_both_pairings():
    """The cascaded tanks (open loop, a pump voltage held from each sample on) show no controller
    reaction: the base model fitted both ways decides."""
    from valve_gym.diagnosis.recording import data_path, load_recording
    rec = load_recording(data_path("cascaded_tanks/estimation.csv"), op_range=(0, 10))
    res = diagnose(rec, plant="cascade", actuator="pump", candidates=(), effort="fast", op_lag="auto")
    test = res.settings["op_lag_test"]
    assert test["controller_reaction"]["op_lag"] is None and test["method"] == "model fit"
    assert set(test["rmse_fit_part"]) == {"0", "1"}
    assert res.settings["op_lag"] == (1 if test["delta_ic"] < -2.0 else 0)


def test_fixed_op_lag_is_not_tested():
    rec = make_case("none", seed=1, n=300).recording
    res = diagnose(rec, candidates=(), effort="fast", op_lag=1)
    assert res.settings["op_lag"] == 1 and res.settings["op_lag_test"] == {"asked": 1, "chosen": 1, "tested": False}
    from valve_gym.diagnosis.report import render_markdown
    assert "as asked (--op-lag 1)" in render_markdown(res)
    res0 = diagnose(rec, candidates=(), effort="fast", op_lag=0)
    assert res0.settings["op_lag"] == 0 and "Pairing of OP and PV" not in render_markdown(res0)
    res_auto = diagnose(rec, candidates=(), effort="fast")                                      # the default
    assert res_auto.settings["op_lag_test"]["tested"] and res_auto.settings["op_lag"] == 0
    assert "read from the controller's reaction" in render_markdown(res_auto)


@pytest.mark.parametrize("bad", [2, -1, "1", True, None])
def test_bad_op_lag(bad):
    rec = make_case("none", seed=1, n=300).recording
    with pytest.raises(ValueError, match="op_lag must be 'auto', 0 or 1"):
        diagnose(rec, candidates=(), effort="fast", op_lag=bad)


@pytest.mark.parametrize("flip", [False, True])
def test_auto_takes_the_process_sign_from_the_base_fit(flip):
    """A first-order loop (its gain's sign is fitted): read the same with the PV's sign flipped."""
    from dataclasses import replace
    spec = LoopSpec(process="foptd", valve="linear", S=0.0, J=0.0, Kc=1.0, Ti=30.0, Ts=1.0, noise=0.003,
                    tau_v=0.2, n=600, sp_moves=0.3)
    rec = simulate_loop(spec, seed=0)
    if flip:
        rec = replace(rec, pv=-rec.pv)
    res = diagnose(rec, plant="first_order", candidates=(), effort="fast", op_lag="auto")
    test = res.settings["op_lag_test"]
    assert test["controller_reaction"]["process_sign"] == (-1.0 if flip else 1.0)
    assert test["method"] == "controller reaction" and res.settings["op_lag"] == 1


@pytest.mark.slow
def test_data_driven_evidence_reads_the_record_as_logged():
    # the pairing is the model's business: the shape methods (Horch, bicoherence, ellipse, waveform,
    # stick episodes) read the record as logged, so their features do not move with op_lag
    spec = LoopSpec(process="tank", valve="choudhury", S=0.04, J=0.01, area=0.25, q_max=0.012, c_out=0.005,
                    Kc=3.0, Ti=60.0, Ts=1.0, theta=0.0, noise=0.002, tau_v=0.2, n=900, sp_moves=0.0)
    rec = simulate_loop(spec, seed=3)
    f = {lag: diagnose(rec, plant="tank", candidates=(), effort="fast", op_lag=lag).stiction
         for lag in (0, 1)}
    shape = ("horch_ccf", "horch_int", "bicoherence", "ellipse", "waveform", "episodes", "oscillating")
    assert any(f[0]["features"][k] != 0.0 for k in shape)          # the loop cycles: the methods read it
    for k in shape:
        assert f[1]["features"][k] == f[0]["features"][k], k
    assert f[1]["horch"] == f[0]["horch"]
    assert f[1]["features"]["hammerstein"] != f[0]["features"]["hammerstein"]   # the fits see the pairing
