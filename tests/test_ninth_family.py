"""The ninth held-out family (``benchmarks/learned_ninth_check.py``): its simulators under the PI alone."""
from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest


@pytest.fixture(scope="module")
def ninth(repo_module):
    return repo_module("benchmarks/learned_ninth_check.py", "learned_ninth_check")


def test_the_design_is_a_balanced_factorial_with_every_third_valve_healthy(ninth):
    rows = ninth.draw(48, 9191)
    assert len({(r["kind"], r["valve"], r["load"]) for r in rows}) == 48
    sticky = np.array([r["S"] >= ninth.HEALTHY_S for r in rows])
    assert ninth.HEALTHY_S == 0.004
    assert not sticky[::3].any() and sticky[1::3].all() and sticky[2::3].all()
    S, J = np.array([r["S"] for r in rows]), np.array([r["J"] for r in rows])
    assert S[sticky].min() >= 0.005 and S[sticky].max() <= 0.10 and S[~sticky].max() < ninth.HEALTHY_S
    assert (J >= 0).all() and (J <= S).all()
    combos = Counter((r["kind"], r["valve"]) for r, s in zip(rows, sticky) if s)
    assert len(combos) == 12 and min(combos.values()) >= 2
    assert Counter(r["load"] for r in rows) == {lk: 12 for lk in ninth.LOAD_KINDS}
    assert Counter(r["kind"] for r in rows) == {k: 12 for k in ninth.KINDS}
    assert Counter(r["valve"] for r in rows) == {v: 16 for v in ninth.VALVE_KINDS}
    assert set(Counter(r["scan"] for r in rows)) == {0.5, 1.0, 2.0}
    for r in rows:
        assert r["scan"] in ninth.SCANS[r["kind"]]
        lo, hi = ninth.NOISE[r["kind"]]
        assert 0.0005 <= lo <= r["noise"] <= hi <= 0.003
        assert 0.35 <= r["x0"] <= 0.65 and 0.2 <= r["tau_p"] <= 2.0 and 0.1 <= r["tau_a"] <= 0.4
        assert 0.6 <= r["zeta"] <= 0.9 and 15.0 <= r["stroke_s"] <= 60.0 and 0.03 <= r["torque"] <= 0.12
        assert 0.03 <= r["supply"] <= 0.08 and 0.5 <= r["phi"] <= 0.9 and 0.02 <= r["tau_c"] <= 0.1
        assert r["cycle"] * r["rise"] >= 120.0               # the supply rises through the first two minutes
        if r["load"] == "ou_small":
            assert 0.001 <= r["ou"] <= 0.005 and not r["steps"] and r["ramp"] == 0.0
        elif r["load"] == "ou_large":
            assert 0.01 <= r["ou"] <= 0.03 and not r["steps"] and r["ramp"] == 0.0
        elif r["load"] == "steps":
            assert 2 <= len(r["steps"]) <= 4 and r["ou"] == 0.001 and r["ramp"] == 0.0
            assert all(0.1 <= w <= 0.9 and 0.005 <= abs(d) <= 0.02 for w, d in r["steps"])
        else:
            assert 0.005 <= abs(r["ramp"]) <= 0.02 and r["ou"] == 0.001 and not r["steps"]
        if r["kind"] == "desuper":
            assert 1.0 <= r["dead"] <= 4.0 and 0.04 <= r["s0"] <= 0.08
        if r["kind"] == "tower":
            assert 20.0 <= r["dead"] <= 60.0 and 100.0 <= r["tau"] <= 360.0


def test_every_loop_starts_at_rest_at_its_set_point(ninth, starts_at_rest):
    starts_at_rest(ninth.NinthLoops, ninth.draw(12, 7), output_above=True, read=True)


def test_loops_are_finite_and_the_frictionless_pi_holds_the_set_point(ninth):
    rows = ninth.draw(12, 3)
    res = ninth.check_family(ninth.NinthLoops, rows, ["pi"], 3600.0, test_s=ninth.TEST_S)
    sticky = np.array([r["S"] >= ninth.HEALTHY_S for r in rows])
    assert sticky.sum() == 8 and {r["valve"] for r in rows} == set(ninth.VALVE_KINDS)
    assert {r["kind"] for r in rows} == set(ninth.KINDS)
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


def _one(ninth, valve, S, J, **kw):
    row = dict(next(r for r in ninth.draw(12, 1) if r["kind"] == "compressor"), valve=valve, S=S, J=J, x0=0.45,
               **kw)
    sim = ninth.NinthLoops([row], 0.5, False)
    return sim, sim.reset()


def _ramp(sim, u0, rate, seconds, scan=0.5):
    """The stem under a ramp of the controller's output from ``u0`` at ``rate`` per s."""
    return np.array([sim.step(np.array([u0 + rate * scan * k]), np.zeros(1))[1][0]
                     for k in range(1, int(seconds / scan) + 1)])


@pytest.mark.parametrize("valve", ["electric", "piston", "butterfly"])
@pytest.mark.parametrize("S, J", [(0.03, 0.012), (0.06, 0.054)])
def test_each_valve_has_the_band_and_slip_it_claims(ninth, valve, S, J):
    rate, scan, x0 = 0.0005, 0.5, 0.45
    for direction, band in ((-1.0, S), (1.0, J)):              # a reversal from rest needs S, a move on J
        sim, (_, x, u0) = _one(ninth, valve, S, J, supply=0.0)  # a steady air supply
        row = sim.rows[0]
        torque = row["torque"] * math.sin(math.pi * x0) if valve == "butterfly" else 0.0
        assert u0[0] - x[0] == pytest.approx((S - J) / 2 + torque)
        xs = _ramp(sim, u0[0], direction * rate, 4 * S / rate)
        jumps = direction * np.diff(np.concatenate([[x0], xs]))
        k = int(np.argmax(np.abs(xs - x0) > 1e-6))             # the breakaway: stuck until then
        lag = rate * (row["tau_p"] + {"electric": 0.0, "piston": row["tau_c"], "butterfly": row["tau_a"]}[valve])
        assert band - 0.01 * S <= rate * scan * (k + 1) - lag <= band + rate * scan + 0.01 * S
        t_slip = J * row["stroke_s"] if valve == "electric" else 1.0   # the motor runs at its fixed speed
        n = int(t_slip / scan) + 2
        first = jumps[k:k + n].sum() - rate * scan * n          # the breakaway's slip, less the ramp meanwhile
        hi = {"electric": 1.02, "piston": 1.9, "butterfly": 1.25}[valve]
        assert 0.85 * J <= first <= hi * J + 0.001
        assert jumps.min() > -1e-9                              # never back against the ramp
        assert abs(xs[-1] - (u0[0] - torque + direction * rate * scan * xs.size - direction * (S - J) / 2)) < 1.9 * J


def test_the_electric_motor_runs_at_its_fixed_speed(ninth):
    S, J = 0.06, 0.05
    sim, (_, x, u0) = _one(ninth, "electric", S, J)
    xs = _ramp(sim, u0[0] + J + 0.002, 0.0, 20.0, scan=0.5)    # an input move of J and a bit more, at once
    speed = np.diff(np.concatenate([[x[0]], xs])) / 0.5
    assert speed.max() == pytest.approx(1.0 / sim.rows[0]["stroke_s"], rel=0.02)
    assert (speed > 0.9 * speed.max()).sum() >= 3                # a run at that speed, not a jump
    assert xs[-1] - x[0] == pytest.approx(J + 0.002, abs=1e-4)   # stops (S - J) / 2 short of its input again


def test_the_piston_seals_grip_harder_as_the_air_supply_rises(ninth):
    S, J = 0.04, 0.01
    sim, (_, x, u0) = _one(ninth, "piston", S, J, supply=0.08, phi=0.9, cycle=600.0, rise=0.5)
    m = np.array([ninth.supply_scale(sim.cols[0], t) for t in (0.0, 150.0, 300.0, 450.0, 600.0)])
    np.testing.assert_allclose(m, [1 - 0.072, 1.0, 1 + 0.072, 1.0, 1 - 0.072], atol=1e-12)
    fc0 = (S - J) / 2 * m[0]
    assert u0[0] - x[0] == pytest.approx(fc0)                    # at rest at cut-in
    rate = 0.0002                                               # a reversal down while the supply rises
    xs = _ramp(sim, u0[0], -rate, 400.0)
    k = int(np.argmax(np.abs(xs - x[0]) > 1e-6))
    t = 0.5 * (k + 1)
    band = rate * (t - sim.rows[0]["tau_p"] - sim.rows[0]["tau_c"])
    want = fc0 + (S + J) / 2 * float(ninth.supply_scale(sim.cols[0], t))
    assert band == pytest.approx(want, abs=0.0005) and band > S * (1 - 0.072) + 0.001


def test_opening_the_valve_raises_every_plant_as_stated(ninth):
    from scipy.optimize import fsolve

    rows = [dict(r, valve="electric") for r in ninth.draw(48, 9191) if r["scan"] == 1.0][:16]
    assert {r["kind"] for r in rows} == set(ninth.KINDS)
    sim = ninth.NinthLoops(rows, 1.0, True)
    y0, _, u0 = sim.reset()
    dx = 0.02
    ys = np.array([sim.step(u0 + dx, np.zeros(len(rows)))[0] for _ in range(4000)])
    for i, r in enumerate(rows):
        dy = ys[:, i] - y0[i]
        assert dy[-1] > 0 and dy.min() > -1e-9 and dy.max() < 1.005 * dy[-1], r["kind"]  # reverse acting
        if r["kind"] != "compressor":               # (the emptying discharge drum takes back up to 0.5 %)
            assert (np.diff(dy) > -1e-9).all(), r["kind"]                 # no overshoot
        x0, x1 = r["x0"], r["x0"] + dx
        if r["kind"] == "boiler":                   # the users' draw k sqrt(P^2 - P_b^2) matches the firing
            P0, Pb = r["P0"], r["Pb"] * r["P0"]
            P1 = math.sqrt((x1 / x0) ** 2 * (P0 * P0 - Pb * Pb) + Pb * Pb)
            assert dy[-1] == pytest.approx(P1 - P0, rel=1e-3)
            assert dy[int(r["dead"]) - 1] == 0.0                          # the burners' dead time
        elif r["kind"] == "desuper":                # more spray cools the steam: pv counts down the temperature
            T = [r["E"] / (1 + r["s0"] * x / x0) for x in (x0, x1)]
            assert dy[-1] == pytest.approx((T[0] - T[1]) / ninth.DS_SPAN, rel=1e-3)
            assert sim.st[i, ninth.S_Y2] < T[0]
        elif r["kind"] == "tower":                  # the basin over the wet bulb: dT / ((1 - b) eff) - dT
            th = [r["dT"] / ((1 - r["bmax"] * x) * r["eff"]) for x in (x0, x1)]
            assert dy[-1] == pytest.approx((th[1] - th[0]) / ninth.TW_SPAN, rel=0.01)
        else:                                       # suction and discharge balances
            qc0 = x0 / r["rs"]
            qi0, Pd0, Ph = qc0 - x0, r["Pd"], r["Ph"] * r["Pd"]

            def bal(z, qc0=qc0, qi0=qi0, Pd0=Pd0, Ph=Ph, r=r, x1=x1):
                ps, pd = z
                rec = x1 * math.sqrt(max(pd - ps, 0.0) / (Pd0 - 1))
                return [qi0 * math.sqrt(max(r["Pu"] - ps, 0.0) / (r["Pu"] - 1)) + rec - qc0 * ps,
                        qc0 * ps - rec - qi0 * math.sqrt(max(pd - Ph, 0.0) / (Pd0 - Ph))]

            ps, _ = fsolve(bal, [1.0, Pd0])
            assert dy[-1] == pytest.approx((ps - 1.0) / r["w"], rel=1e-3)


def test_measurements_and_loads(ninth):
    rows = [r for r in ninth.draw(48, 9191) if r["scan"] == 1.0]
    T = 3600
    noise, load = ninth.NinthLoops.disturbances(rows, 1.0, T, 3600.0)
    t = np.arange(T)
    for i, r in enumerate(rows):
        w = noise[:, i] / r["noise"]
        assert 0.7 < w.std() < 1.3
        rho = np.corrcoef(w[1:], w[:-1])[0, 1]
        if r["t_noise"] == 0.0:
            assert abs(rho) < 0.1
        else:
            assert rho == pytest.approx(math.exp(-1.0 / r["t_noise"]), abs=0.1)
        d = load[:, i]
        assert abs(d[0]) < 0.002 + 3 * r["ou"]                  # every load starts near 0
        if r["load"] == "steps":
            jumps = np.sort(np.abs(np.diff(d)))[::-1]
            assert jumps[len(r["steps"]) - 1] >= 0.005 - 0.001
            assert abs(d[-1] - d[0] - sum(s for _, s in r["steps"])) < 0.01
        if r["load"] == "ramp":
            trend = np.polyfit(t, d, 1)[0] * 3600.0
            assert trend == pytest.approx(r["ramp"], abs=0.006)
    sim = ninth.NinthLoops(rows, 1.0, False)
    y0, _, _ = sim.reset()
    read = sim.measure(y0 + 0.0123456, np.zeros(len(rows)))
    np.testing.assert_allclose(read * ninth.LEVELS, np.round(read * ninth.LEVELS), atol=1e-6)
