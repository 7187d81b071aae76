"""The sixth held-out family (``benchmarks/learned_sixth_check.py``): its simulators under the PI alone."""
from __future__ import annotations

from collections import Counter

import numpy as np
import pytest


@pytest.fixture(scope="module")
def sixth(repo_module):
    return repo_module("benchmarks/learned_sixth_check.py", "learned_sixth_check")


def test_the_design_is_a_balanced_factorial_with_every_third_valve_healthy(sixth):
    rows = sixth.draw(48, 6161)
    assert len({(r["kind"], r["valve"], r["load"]) for r in rows}) == 48
    sticky = np.array([r["S"] >= sixth.HEALTHY_S for r in rows])
    assert not sticky[::3].any() and sticky[1::3].all() and sticky[2::3].all()
    S, J = np.array([r["S"] for r in rows]), np.array([r["J"] for r in rows])
    assert S[sticky].min() >= 0.005 and S[sticky].max() <= 0.10 and S[~sticky].max() < sixth.HEALTHY_S
    assert (J >= 0).all() and (J <= S).all()
    # every plant meets every valve sticky, and half the loops carry a small load
    combos = Counter((r["kind"], r["valve"]) for r, s in zip(rows, sticky) if s)
    assert len(combos) == 12 and min(combos.values()) >= 2
    assert sum(r["load"] in ("ou", "drift") for r in rows) == 24
    assert {r["scan"] for r in rows} == {0.5, 1.0, 2.0}
    for r in rows:
        assert r["scan"] in sixth.SCANS[r["kind"]]
        lo, hi = sixth.NOISE[r["kind"]]
        assert lo <= r["noise"] <= hi
        assert 0.35 <= r["x0"] <= 0.65


def test_every_loop_starts_at_rest_at_its_set_point(sixth, starts_at_rest):
    starts_at_rest(sixth.SixthLoops, sixth.draw(12, 7), output_above=True, read=True)


def test_loops_are_finite_and_the_frictionless_pi_holds_the_set_point(sixth):
    rows = sixth.draw(12, 3)
    res = sixth.check_family(sixth.SixthLoops, rows, ["pi"], 900.0, test_s=sixth.TEST_S)
    sticky = np.array([r["S"] >= sixth.HEALTHY_S for r in rows])
    assert sticky.sum() == 8 and {r["valve"] for r in rows} == set(sixth.VALVE_KINDS)
    assert {r["kind"] for r in rows} == set(sixth.KINDS)
    for label in ("PI frictionless", "pi"):
        for key, v in res[label].items():
            assert np.isfinite(v).all(), (label, key)
    fr, pi = res["PI frictionless"], res["pi"]
    assert (pi["iae"][sticky] > fr["iae"][sticky]).all()
    assert fr["iae"][sticky].sum() < 0.8 * pi["iae"][sticky].sum()
    assert np.median(pi["iae"][sticky] / fr["iae"][sticky]) > 1.3
    assert np.median(fr["offset"]) < 0.001                  # within the noise (0.5-3 pv x1000)
    assert fr["offset"].max() < 0.005                       # the slow tray under its load, at worst
    assert np.median(pi["travel"][sticky]) < 0.6 * np.median(fr["travel"][sticky])
    np.testing.assert_allclose(np.median(pi["iae"][~sticky] / fr["iae"][~sticky]), 1.0, atol=0.1)


def _one(sixth, valve, S, J, scan=0.5, **kw):
    row = dict(sixth.draw(12, 1)[2 + 4 * sixth.VALVE_KINDS.index(valve)])   # a header loop of that valve
    assert row["kind"] == "header" and row["valve"] == valve
    row.update(S=S, J=J, x0=0.5, **kw)
    sim = sixth.SixthLoops([row], scan, False)
    return sim, sim.reset()


def _drive(sim, ops):
    xs = []
    for op in ops:
        _, x = sim.step(np.array([op]), np.zeros(1))
        xs.append(x[0])
    return np.array(xs)


def _band(sim, direction=-1.0, rate=0.0005, scan=0.5, limit=0.3):
    """The input move from where it rests at which the stem first moves under a slow ramp, less the lag of the
    positioner and the air (``rate (tau_p + tau_a)``)."""
    x_start, u0 = sim.st[0, 2], sim.st[0, 0]                # X_X, X_P: the stem and the positioner at rest
    lag = rate * (sim.rows[0]["tau_p"] + sim.rows[0]["tau_a"])
    for k in range(1, int(limit / (rate * scan))):
        _, x = sim.step(np.array([u0 + direction * rate * scan * k]), np.zeros(1))
        if abs(x[0] - x_start) > 1e-6:
            return rate * scan * k - lag
    return np.inf


def _rest_at(sim, x, lead):
    """Put the stem at rest at ``x``, the positioner and the air ``lead`` above it."""
    sim.st[0, 2], sim.st[0, 3], sim.st[0, 5] = x, 0.0, 0.0  # X_X, X_V, X_M
    sim.st[0, 0] = sim.st[0, 1] = x + lead                  # X_P, X_A


@pytest.mark.parametrize("valve", ["dahl_karnopp", "wear_band", "drying"])
def test_sticky_valves_hold_inside_the_band_and_slip_beyond_it(sixth, valve):
    S, J = 0.04, 0.02
    sim, (_, x, u0) = _one(sixth, valve, S, J, g=0.0)
    assert x[0] == 0.5 and u0[0] == pytest.approx(0.5 + (S - J) / 2)
    xs = _drive(sim, np.linspace(u0[0], u0[0] - 0.95 * S, 80))    # back into the band: held, not a hair moved
    assert np.abs(xs - 0.5).max() < 1e-9
    xs = _drive(sim, np.linspace(u0[0] - 0.95 * S, u0[0] - 2.5 * S, 400))   # on beyond it: stick-slip downwards
    jumps = -np.diff(xs)
    assert np.isfinite(xs).all() and xs[-1] < 0.5 - S
    assert jumps.max() > 0.7 * J and (jumps > 0.5 * J).sum() >= 2
    assert jumps.min() > -1e-3                                   # it never goes back up


@pytest.mark.parametrize("valve", ["dahl_karnopp", "wear_band", "drying"])
def test_the_reversal_band_is_S_and_a_move_on_needs_J(sixth, valve):
    S, J = 0.03, 0.012
    sim, _ = _one(sixth, valve, S, J, g=0.0)
    assert _band(sim) == pytest.approx(S, abs=0.03 * S)           # a reversal from rest
    sim, _ = _one(sixth, valve, S, J, g=0.0)
    assert _band(sim, direction=1.0) == pytest.approx(J, abs=0.03 * S)   # on in the same direction


@pytest.mark.parametrize("valve", ["dahl_karnopp", "wear_band", "drying"])
def test_dead_band_only_valves_do_not_slip(sixth, valve):
    """``J = 0``: the stem is dragged through the band smoothly, ``F_c = S / 2`` behind the input."""
    sim, (_, x, u0) = _one(sixth, valve, 0.04, 0.0, g=0.0, w_w=0.0)
    ops = np.linspace(u0[0], u0[0] - 0.1, 200)
    xs = np.concatenate([x, _drive(sim, ops)])
    assert np.abs(np.diff(xs)).max() < 2.0 * abs(ops[1] - ops[0]) + 1e-4
    assert xs[-1] == pytest.approx(ops[-1] + 0.02, abs=0.004)


def test_the_dahl_friction_relaxes_along_the_path(sixth):
    """The slip after a breakaway shrinks as the Dahl path ``lambda`` grows against ``J``."""
    S, J = 0.04, 0.03

    def first_slip(lam):
        sim, (_, x, u0) = _one(sixth, "dahl_karnopp", S, J, lam=lam, zeta=0.8)
        xs = _drive(sim, u0[0] - np.arange(1, 200) * 0.0005)
        return float(np.max(-np.diff(np.concatenate([x, xs]))))

    short, long_ = first_slip(0.02), first_slip(1.0)
    assert short == pytest.approx(J, rel=0.15)
    assert long_ < 0.5 * short


def test_the_wear_band_is_easiest_at_the_operating_point(sixth):
    S, J, w = 0.03, 0.01, 1.0
    sim, _ = _one(sixth, "wear_band", S, J, w_w=w, b_w=0.03, x_w=0.0)
    assert sixth.wear_factor(0.5, sim.par[0]) == pytest.approx(1.0)
    far = sixth.wear_factor(0.8, sim.par[0])
    assert far == pytest.approx(1.0 + w, rel=1e-6)               # the packing's unworn part
    _rest_at(sim, 0.8, (S - J) / 2 * far)
    assert _band(sim) == pytest.approx(S * far, abs=0.03 * S)
    _rest_at(sim, 0.8, (S - J) / 2 * far)
    assert _band(sim, direction=1.0) == pytest.approx(J * far, abs=0.03 * S)


def test_the_drying_packing_tightens_over_the_hour(sixth):
    S, J, g = 0.03, 0.01, 0.6
    sim, (_, x, u0) = _one(sixth, "drying", S, J, g=g)
    assert u0[0] - 0.5 == pytest.approx((S - J) / 2 * (1 - g / 2))
    assert _band(sim) == pytest.approx(S * (1 - g / 2), abs=0.03 * S)
    sim, (_, x, u0) = _one(sixth, "drying", S, J, g=g)
    xs = _drive(sim, [u0[0]] * int(sixth.HOUR / 0.5))            # an hour at rest: still stuck
    assert np.abs(xs - 0.5).max() < 1e-12
    fc0, fs1 = (S - J) / 2 * (1 - g / 2), (S + J) / 2 * (1 + g / 2)
    assert _band(sim) == pytest.approx(fc0 + fs1, abs=0.03 * S)   # the rest offset, then the tighter packing


def _step(sixth, kind, du, seconds, scan=0.5, seed=3, **kw):
    """Open-loop step of ``du`` on the frictionless loops of ``kind``: ``(rows, pv - pv_0 (T, n))``."""
    rows = [dict(r, **kw) for r in sixth.draw(48, seed) if r["kind"] == kind]
    sim = sixth.SixthLoops(rows, scan, True)
    y0, _, u0 = sim.reset()
    ys = np.array([sim.step(u0 + du, np.zeros(len(rows)))[0] for _ in range(int(seconds / scan))])
    return rows, ys - y0


def test_the_reactor_runs_hotter_as_its_coolant_valve_closes_and_its_exotherm_overshoots(sixth):
    rows, up = _step(sixth, "cstr", 0.05, 1800.0)
    _, down = _step(sixth, "cstr", -0.05, 1800.0)
    assert (up[-1] > 0).all() and (down[-1] < 0).all()           # air to close: closing it heats the reactor
    assert (up[-1] > -down[-1]).all()                            # the gain falls as more coolant flows
    assert (np.abs(up[-1] - up[-200]) < 0.01 * up[-1]).all()     # open-loop stable: settled
    over = up.max(axis=0) / up[-1]
    assert (over >= 1.0).all() and over.max() > 1.1              # the conversion takes back part of the rise
    for r in rows:                                               # the design point is a steady state
        c = sixth.cstr_design(r)
        k = c["k0"]
        assert (1 - c["c0"]) / r["theta"] - k * c["c0"] == pytest.approx(0.0, abs=1e-12)
        gen = c["dT_ad"] * k * c["c0"] - c["alpha"] * (r["T0"] - c["Tj0"]) - (r["T0"] - c["T_f"]) / r["theta"]
        assert gen == pytest.approx(0.0, abs=1e-9)
        assert c["T_ci"] < c["Tj0"] < r["T0"] and c["T_f"] <= r["T0"] and c["alpha"] > 0


def test_the_tray_cools_first_then_heats_with_more_steam(sixth):
    rows, ys = _step(sixth, "tray", 0.005, 900.0)
    for i, r in enumerate(rows):
        assert ys[: int(60 / 0.5), i].min() < -0.02 * ys[-1, i]     # inverse response
        assert ys[-1, i] / 0.005 == pytest.approx(r["K"], rel=0.05)   # the gain at the operating point
    for du in (0.1, -0.1):                                       # large moves: along the front's sigmoid
        _, ys = _step(sixth, "tray", du, 900.0)
        for i, r in enumerate(rows):
            z, o, ws = r["R"] ** du - 1.0, r["off"], r["w_s"]
            amp = r["K"] * ws * np.cosh(o) ** 2 / np.log(r["R"])
            assert ys[-1, i] == pytest.approx(amp * (np.tanh(z / ws + o) - np.tanh(o)), rel=1e-3)


def test_the_header_valve_chokes(sixth):
    assert sixth.choke(0.3) == sixth.choke(sixth.R_CRIT) == 1.0
    r = np.linspace(sixth.R_CRIT, 1.0, 20)
    f = np.array([sixth.choke(v) for v in r])
    assert (np.diff(f) < 0).all() and f[-1] == 0.0
    rows, ys = _step(sixth, "header", 0.005, 120.0, scan=0.5)
    for i, rw in enumerate(rows):
        P0, pb, st = rw["P0"], rw["P_b"], rw["s_t"]
        out = st / P0 + 0.5 * (1 - st) / (P0 - pb)               # the consumers' slope: turbine and users
        if P0 < sixth.R_CRIT:                                     # choked: the inflow ignores the header
            assert ys[-1, i] / 0.005 == pytest.approx(1 / (rw["x0"] * out), rel=0.03)
        else:                                                     # not choked: the header holds its feed back
            assert ys[-1, i] / 0.005 < 0.97 / (rw["x0"] * out)
        t63 = (np.argmax(ys[:, i] >= 0.632 * ys[-1, i]) + 1) * 0.5
        assert rw["tau_h"] < t63 < rw["tau_h"] + rw["Tm"] + rw["tau_p"] + rw["tau_a"] + 1.0


def test_the_two_tanks_share_their_head(sixth):
    rows, ys = _step(sixth, "twotank", 0.1, 3000.0)
    for i, r in enumerate(rows):
        q = (r["x0"] + 0.1) / r["x0"]
        assert ys[-1, i] + r["L2"] + r["dL"] == pytest.approx((r["L2"] + r["dL"]) * q ** 2, rel=2e-3)
        early = ys[int(3 * r["tau1"] / 0.5), i]                   # the first tank's head over the hand valve first
        assert early > 0.6 * r["dL"] * (q ** 2 - 1)
        assert early < 0.7 * ys[-1, i]


def test_measurements_and_loads(sixth):
    rows = [r for r in sixth.draw(48, 6161) if r["scan"] == 1.0]
    assert {"tray", "header", "cstr", "twotank"} <= {r["kind"] for r in rows}
    T = 3600
    noise, load = sixth.SixthLoops.disturbances(rows, 1.0, T, 3600.0)
    for i, r in enumerate(rows):
        w = noise[:, i] / r["noise"]
        big = np.abs(w) > 4.0
        if r["kind"] == "tray":                                   # white, with outliers
            assert big.sum() >= 0.4 * r["p_spike"] * T
            assert abs(np.corrcoef(w[1:], w[:-1])[0, 1]) < 0.1
        else:
            assert big.sum() <= 3
            assert 0.7 < w.std() < 1.3
        if r["kind"] == "header":                                 # the transmitter's damping filters its noise
            assert r["t_noise"] == r["Tm"]
        if r["kind"] in ("header", "twotank"):
            assert r["t_noise"] > 0.0
        if r["t_noise"] > 0.0:                                    # coloured
            assert np.corrcoef(w[1:], w[:-1])[0, 1] > 0.5 * np.exp(-1.0 / r["t_noise"])
        d = load[:, i]
        assert abs(d[0]) < 0.003                                  # every load starts near zero
        assert np.abs(d).max() < (0.02 if r["load"] in ("ou", "drift") else 0.02 + abs(r["tri"] + r["tel"]))
    bare = [dict(r, ou=0.0) for r in rows if r["load"] in ("triangle", "telegraph")]   # without their small OU
    _, load = sixth.SixthLoops.disturbances(bare, 1.0, T, 3600.0)
    for i, r in enumerate(bare):
        d = load[:, i]
        if r["load"] == "telegraph":                              # two levels, switching now and then
            assert set(np.unique(d)) == {0.0, r["tel"]}
            n = np.abs(np.diff(d)).astype(bool).sum()
            assert 0.3 * T / r["tel_dwell"] < n < 2.0 * T / r["tel_dwell"]
        else:                                                     # from zero, between -tri and tri
            assert d[0] == 0.0 and np.abs(d).max() == pytest.approx(abs(r["tri"]), rel=0.01)
            assert np.abs(np.diff(d)).max() == pytest.approx(4 * abs(r["tri"]) / r["tri_period"], rel=1e-6)
    sim = sixth.SixthLoops(rows, 1.0, False)
    y0, _, _ = sim.reset()
    read = sim.measure(y0 + 0.0123456, np.zeros(len(rows)))
    np.testing.assert_allclose(read / sim.res, np.round(read / sim.res), atol=1e-6)
    np.testing.assert_allclose(read, y0 + 0.0123456, atol=sim.res.max())
