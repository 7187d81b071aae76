"""Reading how a recorder pairs OP and PV from the controller's reaction (:mod:`valve_gym.diagnosis.pairing`)."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.diagnosis.pairing import Z_MARGIN, controller_reaction
from valve_gym.diagnosis.stiction.loops import LoopSpec, simulate_loop
from valve_gym.diagnosis.synthetic import make_case


def _pi_loop(n=1500, seed=0, drain=False):
    """A PI level loop on an integrating tank, logged two ways: (op[k] from pv[k]) and (pv[k] after op[k])."""
    rng = np.random.default_rng(seed)
    g = -0.02 if drain else 0.02                  # PV change per sample per unit of output
    kc = -4.0 if drain else 4.0
    level, integ = 1.0, 0.5
    op, pv = np.empty(n), np.empty(n)
    for k in range(n):
        meas = level + 0.003 * rng.standard_normal()
        e = 1.0 - meas
        integ += 0.05 * kc * e
        u = float(np.clip(integ + kc * e, 0.0, 1.0))
        op[k], pv[k] = u, meas
        level += g * (u - 0.5) + 0.0005 * rng.standard_normal()
    return op, pv


@pytest.mark.parametrize("drain", [False, True])
def test_a_scan_logged_beside_its_pv_and_the_model_convention(drain):
    op, pv = _pi_loop(drain=drain)
    sign = -1.0 if drain else 1.0
    same_row = controller_reaction(op, pv, sign)
    assert same_row["op_lag"] == 1 and same_row["reaction"]["0"] > 0.5
    shifted = controller_reaction(op[:-1], pv[1:], sign)        # pv[k] now measured after op[k] acted
    assert shifted["op_lag"] == 0 and shifted["reaction"]["1"] > 0.5
    # the process's sign matters: read with the wrong one, the reaction is not that of a controller
    wrong = controller_reaction(op, pv, -sign)
    assert wrong["op_lag"] != 1


def test_margin_is_three_standard_errors():
    op, pv = _pi_loop(n=401)
    r = controller_reaction(op, pv)
    assert r["n"] == 400 and r["margin"] == pytest.approx(Z_MARGIN / 20.0)


def test_simulators_logged_each_way():
    # the package's generator logs pv[k] after op[k] acted; the textbook simulator logs op[k] from pv[k]
    for seed in range(3):
        rec = make_case("slip_jump", seed=seed, n=1800).recording
        assert controller_reaction(rec.op, rec.pv)["op_lag"] == 0
    spec = LoopSpec(process="tank", valve="choudhury", S=0.03, J=0.02, area=0.25, q_max=0.012, c_out=0.005,
                    Kc=3.0, Ti=60.0, Ts=1.0, theta=0.0, noise=0.003, tau_v=0.2, n=1200, sp_moves=0.3)
    rec = simulate_loop(spec, seed=1)
    assert controller_reaction(rec.op, rec.pv)["op_lag"] == 1


def test_open_loop_records():
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(0.2, 0.8, 50), 20)                # open loop: a staircase input
    kern = np.full(30, 1 / 30)
    noise = 0.001 * rng.standard_normal(len(u))
    # the PV read before the row's input acts (a zero-order hold sampled with the output): nothing to read
    before = np.convolve(np.r_[u[0], u[:-1]], kern)[: len(u)] + noise
    r = controller_reaction(u, before)
    assert r["op_lag"] is None and "no clear controller reaction" in r["reason"]
    # the PV read after the row's input acted: the process answers in the same row, as in the model's pairing
    after = np.convolve(u, kern)[: len(u)] + noise
    assert controller_reaction(u, after)["op_lag"] == 0


@pytest.mark.parametrize("op, pv", [(np.full(100, 0.5), np.linspace(0, 1, 100)),
                                    (np.linspace(0, 1, 100), np.full(100, 2.0)),
                                    (np.linspace(0, 1, 10), np.linspace(0, 1, 10))])
def test_too_little_to_read(op, pv):
    r = controller_reaction(op, pv)
    assert r["op_lag"] is None and "too few moves" in r["reason"]


def test_missing_values_are_skipped():
    op, pv = _pi_loop()
    pv = pv.copy()
    pv[100:103] = np.nan
    r = controller_reaction(op, pv)
    assert r["op_lag"] == 1 and np.isfinite(r["reaction"]["0"])


def test_partial_regression_reads_a_pv_whose_moves_correlate_from_row_to_row():
    # coloured measurement noise and a spilling tank: the PV's moves correlate from one row to the next,
    # so the controller's reaction shows in the correlations at both lags and they do not decide; the
    # regression on both rows' moves finds the reaction to the row the controller read and none to the other
    spec = LoopSpec(process="tank", valve="linear", S=0.0, J=0.0, area=0.2465, q_max=0.00939, c_out=0.00542,
                    Kc=7.38, Ti=14.2, Ts=1.0, theta=0.0, noise=0.00109, noise_pole=0.79, load=0.00039,
                    tau_v=0.29, n=1800, sp_moves=0.1875, level_max=0.6476)
    rec = simulate_loop(spec, seed=107)                  # logs op[k] computed from pv[k]: pairing 1
    r = controller_reaction(rec.op, rec.pv)
    assert abs(r["reaction"]["0"] - r["reaction"]["1"]) <= r["margin"]      # the correlations: undecided
    assert r["method"] == "partial regression" and r["op_lag"] == 1
    assert r["t"]["0"] > Z_MARGIN > r["t"]["1"]
    assert "regressed on both rows' PV moves" in r["reason"]
    # read with the wrong process sign, the reaction is not a controller's
    assert controller_reaction(rec.op, rec.pv, -1.0)["op_lag"] != 1


def test_partial_regression_stays_undecided_when_both_rows_answer():
    # a controller that acts on the mean of its last two readings (a PV filter): it answers both rows
    # alike, the correlations do not decide, and the regression finds both, so the pairing is not read
    rng = np.random.default_rng(3)
    pv = 1.0 + 0.01 * np.cumsum(rng.standard_normal(1500)) / 30 + 0.003 * rng.standard_normal(1500)
    op = np.empty(1500)
    op[0] = 0.5
    op[1:] = 0.5 - 4.0 * (0.5 * (pv[1:] + pv[:-1]) - 1.0)
    r = controller_reaction(op, pv)
    assert r["method"] == "partial regression" and r["op_lag"] is None
    assert r["t"]["0"] > Z_MARGIN and r["t"]["1"] > Z_MARGIN
