"""The eighth held-out family (``benchmarks/learned_eighth_check.py``): its simulators under the PI alone."""
from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest


@pytest.fixture(scope="module")
def eighth(repo_module):
    return repo_module("benchmarks/learned_eighth_check.py", "learned_eighth_check")


def test_the_design_is_a_balanced_factorial_with_every_third_valve_healthy(eighth):
    rows = eighth.draw(48, 8181)
    assert len({(r["kind"], r["valve"], r["load"]) for r in rows}) == 48
    sticky = np.array([r["S"] >= eighth.HEALTHY_S for r in rows])
    assert not sticky[::3].any() and sticky[1::3].all() and sticky[2::3].all()
    S, J = np.array([r["S"] for r in rows]), np.array([r["J"] for r in rows])
    assert S[sticky].min() >= 0.005 and S[sticky].max() <= 0.10 and S[~sticky].max() < eighth.HEALTHY_S
    assert (J >= 0).all() and (J <= S).all()
    combos = Counter((r["kind"], r["valve"]) for r, s in zip(rows, sticky) if s)
    assert len(combos) == 12 and min(combos.values()) >= 2
    assert Counter(r["load"] for r in rows) == {lk: 12 for lk in eighth.LOAD_KINDS}
    assert Counter(r["kind"] for r in rows) == {k: 12 for k in eighth.KINDS}
    scans = Counter(r["scan"] for r in rows)
    assert set(scans) == {0.5, 1.0, 2.0}
    for r in rows:
        assert r["scan"] in eighth.SCANS[r["kind"]]
        lo, hi = eighth.NOISE[r["kind"]]
        assert 0.0005 <= lo <= r["noise"] <= hi <= 0.003
        assert 0.35 <= r["x0"] <= 0.65 and 0.2 <= r["tau_p"] <= 2.0 and 0.1 <= r["tau_a"] <= 0.4
        assert 0.6 <= r["zeta"] <= 0.9 and 0.01 <= r["z_s"] <= 0.02 and 20.0 <= r["tau_k"] <= 120.0
        if r["load"] == "ou_small":
            assert 0.001 <= r["ou"] <= 0.005 and not r["steps"] and r["sine"] == 0.0
        elif r["load"] == "ou_large":
            assert 0.01 <= r["ou"] <= 0.03 and not r["steps"] and r["sine"] == 0.0
        elif r["load"] == "steps":
            assert 2 <= len(r["steps"]) <= 4 and r["ou"] == 0.001 and r["sine"] == 0.0
            assert all(0.1 <= w <= 0.9 and 0.005 <= abs(d) <= 0.02 for w, d in r["steps"])
        else:
            assert 0.005 <= r["sine"] <= 0.02 and 3 * 3600 <= r["period"] <= 8 * 3600 and not r["steps"]
        if r["kind"] == "pipeline":
            assert 30.0 <= r["tau_r"] <= 150.0 and 0.05 <= r["loss"] <= 0.25
        if r["kind"] == "analyser":
            assert 30 <= r["cycle"] <= 120 and r["cycle"] == int(r["cycle"]) and 10.0 <= r["line"] <= 40.0
        if r["kind"] == "turbine":
            assert 3.0 <= r["tau"] <= 12.0


def test_every_loop_starts_at_rest_at_its_set_point(eighth, starts_at_rest):
    starts_at_rest(eighth.EighthLoops, eighth.draw(12, 7), output_above=True, read=True)


def test_loops_are_finite_and_the_frictionless_pi_holds_the_set_point(eighth):
    rows = eighth.draw(12, 3)
    res = eighth.check_family(eighth.EighthLoops, rows, ["pi"], 3600.0, test_s=eighth.TEST_S)
    sticky = np.array([r["S"] >= eighth.HEALTHY_S for r in rows])
    assert sticky.sum() == 8 and {r["valve"] for r in rows} == set(eighth.VALVE_KINDS)
    assert {r["kind"] for r in rows} == set(eighth.KINDS)
    for label in ("PI frictionless", "pi"):
        for key, v in res[label].items():
            assert np.isfinite(v).all(), (label, key)
    fr, pi = res["PI frictionless"], res["pi"]
    assert (pi["iae"][sticky] > fr["iae"][sticky]).sum() >= 6     # stiction costs the PI
    assert np.median(pi["iae"][sticky] / fr["iae"][sticky]) > 1.1
    assert np.median(fr["offset"]) < 0.001                        # within the noise (0.5-3 pv x1000)
    assert fr["offset"].max() < 0.004
    assert np.median(pi["travel"][sticky]) < 0.5 * np.median(fr["travel"][sticky])
    np.testing.assert_allclose(np.median(pi["iae"][~sticky] / fr["iae"][~sticky]), 1.0, atol=0.1)


def _one(eighth, valve, S, J, kind="turbine", **kw):
    row = dict(next(r for r in eighth.draw(12, 1) if r["kind"] == kind), valve=valve, S=S, J=J, x0=0.5, **kw)
    sim = eighth.EighthLoops([row], 0.5, False)
    return sim, sim.reset()


def _ramp(sim, u0, rate, seconds, scan=0.5):
    """The stem under a ramp of the controller's output from ``u0`` at ``rate`` per s."""
    return np.array([sim.step(np.array([u0 + rate * scan * k]), np.zeros(1))[1][0]
                     for k in range(1, int(seconds / scan) + 1)])


@pytest.mark.parametrize("valve", ["reset", "ageing", "slewing"])
@pytest.mark.parametrize("S, J", [(0.03, 0.012), (0.05, 0.045)])
def test_each_valve_has_the_band_and_slip_it_claims(eighth, valve, S, J):
    rate, scan = 0.0005, 0.5
    for direction, band in ((-1.0, S), (1.0, J)):              # a reversal from rest needs S, a move on J
        sim, (_, x, u0) = _one(eighth, valve, S, J)
        row = sim.rows[0]
        assert u0[0] - x[0] == pytest.approx((S - J) / 2)
        xs = _ramp(sim, u0[0], direction * rate, 4 * S / rate)
        jumps = direction * np.diff(np.concatenate([[0.5], xs]))
        pre = 2 * row["z_s"] * S if valve == "reset" else 0.0   # the reset integrator's presliding
        k = int(np.argmax(np.abs(xs - 0.5) > pre + 1e-6))      # the breakaway: stuck until then
        lag = rate * (row["tau_p"] + row["tau_a"])              # the positioner and air lags behind the ramp
        assert band <= rate * scan * (k + 1) - lag + 0.01 * S <= band + pre + 0.02 * S
        first = jumps[k:k + 4].sum()                            # the breakaway's slip (within 2 s)
        assert 0.85 * J <= first <= 1.15 * J + rate * 2.0 + pre
        assert jumps.min() > -pre - 1e-9                        # never back against the ramp
        assert abs(xs[-1] - (u0[0] + direction * rate * scan * xs.size - direction * (S - J) / 2)) < J + 0.002


def test_the_aged_seal_sticks_harder_than_a_fresh_one(eighth):
    """After a long rest the ageing valve needs ``S`` to reverse; right after a stop ``J (1 - beta)`` less."""
    S, J = 0.04, 0.03
    sim, (_, x, u0) = _one(eighth, "ageing", S, J)
    sim.st[0, eighth.S_DWELL] = 0.0                             # the stem has just stopped
    xs = _ramp(sim, u0[0], -0.002, 30.0)
    k = int(np.argmax(np.abs(xs - 0.5) > 1e-4))
    lag = 0.002 * (sim.rows[0]["tau_p"] + sim.rows[0]["tau_a"])
    band = 0.002 * 0.5 * (k + 1) - lag
    assert S - J * (1 - sim.rows[0]["beta"]) <= band + 0.001 < S       # aged over the few seconds of the ramp


def test_opening_the_valve_raises_every_plant_as_stated(eighth):
    rows = [r for r in eighth.draw(48, 8181) if r["scan"] == 1.0][:16]
    assert {r["kind"] for r in rows} == set(eighth.KINDS)
    sim = eighth.EighthLoops(rows, 1.0, True)
    y0, _, u0 = sim.reset()
    dx = 0.02
    ys = np.array([sim.step(u0 + dx, np.zeros(len(rows)))[0] for _ in range(1800)])
    for i, r in enumerate(rows):
        dy = ys[:, i] - y0[i]
        assert dy[-1] > 0 and (np.diff(dy) > -1e-9).all(), r["kind"]      # reverse acting, no overshoot
        x0, x1 = r["x0"], r["x0"] + dx
        if r["kind"] == "pipeline":                 # plug flow: T - T_g falls as exp(-V / (q tau_L))
            want = r["dT"] / eighth.T_SPAN * (math.exp(-r["loss"] * x0 / x1) - math.exp(-r["loss"]))
            assert dy[-1] == pytest.approx(want, rel=1e-3)
            assert dy[int(0.5 * r["tau_r"] * x0 / x1)] < 0.5 * want       # the new flow takes a residence to tell
        elif r["kind"] == "aeration":               # C = C_s - OUR / kLa(q)
            our = (r["C_s"] - r["C0"]) / r["tau"]
            want = (r["C_s"] - our * r["tau"] * (x0 / x1) ** r["n_kla"] - r["C0"]) / eighth.DO_SPAN
            assert dy[-1] == pytest.approx(want, rel=0.01)
        elif r["kind"] == "turbine":                # q (a - b w) = w^2
            b = r["droop"] / x0
            a = 1 / x0 + b
            w = (-x1 * b + math.sqrt((x1 * b) ** 2 + 4 * x1 * a)) / 2
            assert dy[-1] == pytest.approx((w - 1) / r["w_span"], rel=1e-3)
        else:                                       # the analyser: a staircase, one step per cycle
            steps = np.flatnonzero(np.abs(np.diff(ys[:, i])) > 1e-12) + 1
            assert len(steps) > 3 and np.allclose(np.diff(steps[:5]), r["cycle"])
            assert steps[0] > r["cycle"]                          # the line and one cycle's analysis first


def test_measurements_and_loads(eighth):
    rows = [r for r in eighth.draw(48, 8181) if r["scan"] == 1.0]
    T = 3600
    noise, load = eighth.EighthLoops.disturbances(rows, 1.0, T, 3600.0)
    t = np.arange(T)
    for i, r in enumerate(rows):
        w = noise[:, i] / r["noise"]
        assert 0.7 < w.std() < 1.3
        rho = np.corrcoef(w[1:], w[:-1])[0, 1]
        if r["kind"] == "analyser":                 # held for a cycle
            assert (np.diff(w)[(t[1:] % r["cycle"]) != 0] == 0).all()
        elif r["t_noise"] == 0.0:
            assert abs(rho) < 0.1
        else:
            assert rho == pytest.approx(math.exp(-1.0 / r["t_noise"]), abs=0.1)
        d = load[:, i]
        assert abs(d[0]) < 0.002 + 3 * r["ou"]                  # every load starts near 0
        if r["load"] == "steps":
            jumps = np.sort(np.abs(np.diff(d)))[::-1]
            assert jumps[len(r["steps"]) - 1] >= 0.005 - 0.001
        if r["load"] == "daily":
            assert np.abs(d).max() < 2.5 * r["sine"] + 0.005
    sim = eighth.EighthLoops(rows, 1.0, False)
    y0, _, _ = sim.reset()
    read = sim.measure(y0 + 0.0123456, np.zeros(len(rows)))
    np.testing.assert_allclose(read * eighth.LEVELS, np.round(read * eighth.LEVELS), atol=1e-6)
