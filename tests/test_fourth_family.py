"""The fourth held-out family (``benchmarks/learned_fourth_check.py``): its simulators under the PI alone."""
from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest


@pytest.fixture(scope="module")
def fourth(repo_module):
    return repo_module("benchmarks/learned_fourth_check.py", "learned_fourth_check")


def test_the_design_is_a_balanced_factorial_with_every_third_valve_healthy(fourth):
    rows = fourth.draw(48, 4242)
    assert Counter((r["kind"], r["valve"], r["load"]) for r in rows).most_common(1)[0][1] == 1
    assert len({(r["kind"], r["valve"], r["load"]) for r in rows}) == 48
    sticky = np.array([r["S"] >= fourth.HEALTHY_S for r in rows])
    assert not sticky[::3].any() and sticky[1::3].all() and sticky[2::3].all()
    S, J = np.array([r["S"] for r in rows]), np.array([r["J"] for r in rows])
    assert S[sticky].min() >= 0.005 and S[sticky].max() <= 0.10 and S[~sticky].max() < fourth.HEALTHY_S
    assert (J >= 0).all() and (J <= S).all()
    # every plant meets every valve sticky, and half the loops carry a small load
    combos = Counter((r["kind"], r["valve"]) for r, s in zip(rows, sticky) if s)
    assert len(combos) == 12 and min(combos.values()) >= 2
    assert sum(r["load"] in ("ou", "drift") for r in rows) == 24
    for r in rows:
        assert r["scan"] in fourth.SCANS[r["kind"]]


def test_every_loop_starts_at_rest_at_its_set_point(fourth, starts_at_rest):
    starts_at_rest(fourth.FourthLoops, fourth.draw(12, 7))


def test_loops_are_finite_and_the_frictionless_pi_holds_the_set_point(fourth):
    rows = fourth.draw(12, 5)
    res = fourth.check_family(fourth.FourthLoops, rows, ["pi"], 900.0, test_s=fourth.TEST_S)
    sticky = np.array([r["S"] >= fourth.HEALTHY_S for r in rows])
    assert sticky.sum() == 8 and {r["valve"] for r in rows} == set(fourth.VALVE_KINDS)
    assert {r["kind"] for r in rows} == set(fourth.KINDS)
    for label in ("PI frictionless", "pi"):
        for key, v in res[label].items():
            assert np.isfinite(v).all(), (label, key)
    fr, pi = res["PI frictionless"], res["pi"]
    assert np.median(fr["iae"][sticky]) < np.median(pi["iae"][sticky])
    assert fr["iae"][sticky].sum() < 0.8 * pi["iae"][sticky].sum()
    assert np.median(fr["offset"]) < 0.002                  # within the noise (0.5-3 pv x1000)
    assert np.median(pi["travel"][sticky]) < 0.6 * np.median(fr["travel"][sticky])
    np.testing.assert_allclose(np.median(pi["iae"][~sticky] / fr["iae"][~sticky]), 1.0, atol=0.1)


def _one(fourth, valve, S, J, scan=0.5, **kw):
    row = dict(fourth.draw(12, 1)[3 + 4 * fourth.VALVE_KINDS.index(valve)])   # block 0: a pressure loop
    assert row["kind"] == "pressure" and row["valve"] == valve
    row.update(S=S, J=J, x0=0.5, **kw)
    sim = fourth.FourthLoops([row], scan, False)
    return sim, sim.reset()


@pytest.mark.parametrize("valve", ["bliman_sorine", "gms", "rotary"])
def test_sticky_valves_hold_inside_the_band_and_slip_beyond_it(fourth, valve):
    S, J = 0.04, 0.02
    sim, (_, x, u0) = _one(fourth, valve, S, J)
    assert x[0] == 0.5 and u0[0] > 0.5
    for op in np.linspace(u0[0], u0[0] - 0.85 * S, 80):    # back into the band: held (pre-sliding creep only)
        _, x = sim.step(np.array([op]), np.zeros(1))
    assert abs(x[0] - 0.5) < 0.1 * S
    xs = []
    for op in np.linspace(u0[0] - 0.85 * S, u0[0] - 2.5 * S, 400):   # on beyond it: stick-slip downwards
        _, x = sim.step(np.array([op]), np.zeros(1))
        xs.append(x[0])
    jumps = -np.diff(xs)
    assert np.isfinite(xs).all() and xs[-1] < 0.5 - S
    assert jumps.max() > 0.5 * J


def test_dead_band_only_valves_do_not_slip(fourth):
    """``J = 0``: the stem is dragged through the band smoothly, no move larger than the input's."""
    for valve in fourth.VALVE_KINDS:
        sim, (_, x, u0) = _one(fourth, valve, 0.04, 0.0)
        xs = [x[0]]
        ops = np.linspace(u0[0], u0[0] - 0.1, 200)
        for op in ops:
            _, x = sim.step(np.array([op]), np.zeros(1))
            xs.append(x[0])
        assert np.abs(np.diff(xs)).max() < 2.0 * abs(ops[1] - ops[0]) + 1e-4, valve
        assert xs[-1] == pytest.approx(ops[-1] + 0.02, abs=0.004), valve        # F_c = S / 2 behind


def test_rotary_breakaways_vary_from_stick_to_stick(fourth):
    S, J = 0.04, 0.03
    sim, (_, x, u0) = _one(fourth, "rotary", S, J, scan=2.0)
    xs = [x[0]]
    for op in np.linspace(u0[0], u0[0] + 0.3, 1500):      # on upwards: one slip of J u at a time
        _, x = sim.step(np.array([op]), np.zeros(1))
        xs.append(x[0])
    moves = np.diff(xs)
    slips, run = [], 0.0
    for d in moves:                                     # a slip may span two scans
        if d > 1e-4:
            run += d
        elif run > 0.0:
            slips.append(run)
            run = 0.0
    slips = np.array(slips)
    assert len(slips) >= 5 and slips.min() > 0.3 * J
    assert slips.std() > 0.1 * J and 0.7 * J < slips.mean() < 1.3 * J


@pytest.mark.parametrize("valve", ["bliman_sorine", "gms", "rotary"])
def test_a_stem_stopped_after_an_upward_move(fourth, valve):
    """Bliman-Sorine follows a further upward move at once; the others hold until the input has gone ``J`` on."""
    S, J = 0.04, 0.02
    sim, (_, x, u0) = _one(fourth, valve, S, J)
    for op in np.linspace(u0[0], u0[0] + 0.4 * J, 40):
        _, x = sim.step(np.array([op]), np.zeros(1))
    if valve == "bliman_sorine":
        assert x[0] - 0.5 > 0.3 * J
    else:
        assert x[0] - 0.5 < 0.05 * J


def test_bliman_sorine_levels_put_the_friction_peak_j_above_coulomb(fourth):
    for S, J, eps, eta in [(0.04, 0.02, 0.03, 0.1), (0.01, 0.009, 0.08, 0.25), (0.05, 0.0, 0.05, 0.2)]:
        f1, f2 = fourth.bs_levels(S, J, eps * S, eta)
        assert f1 - f2 == pytest.approx((S - J) / 2)
        s = np.linspace(0.0, 20 * eps * S, 20001)
        F = f1 - 2 * f1 * np.exp(-s / (eta * eps * S)) - f2 + 2 * f2 * np.exp(-s / (eps * S))
        assert F.max() - (f1 - f2) == pytest.approx(J, abs=1e-4 * S)


def test_the_exchangers_gain_falls_as_the_hot_flow_grows(fourth):
    f = np.linspace(0.05, 1.0, 40)
    th = np.array([fourth.hex_outlet(v, 0.7, 1.0, 1.4) for v in f])
    assert (np.diff(th) > 0).all() and (np.diff(th, 2) < 0).all()
    assert th[-1] < 1.0 - math.exp(-2.0) + 1e-9                 # below the infinite hot flow's limit
