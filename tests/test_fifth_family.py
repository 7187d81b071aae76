"""The fifth held-out family (``benchmarks/learned_fifth_check.py``): its simulators under the PI alone."""
from __future__ import annotations

from collections import Counter

import numpy as np
import pytest


@pytest.fixture(scope="module")
def fifth(repo_module):
    return repo_module("benchmarks/learned_fifth_check.py", "learned_fifth_check")


def test_the_design_is_a_balanced_factorial_with_every_third_valve_healthy(fifth):
    rows = fifth.draw(48, 5151)
    assert len({(r["kind"], r["valve"], r["load"]) for r in rows}) == 48
    sticky = np.array([r["S"] >= fifth.HEALTHY_S for r in rows])
    assert not sticky[::3].any() and sticky[1::3].all() and sticky[2::3].all()
    S, J = np.array([r["S"] for r in rows]), np.array([r["J"] for r in rows])
    assert S[sticky].min() >= 0.005 and S[sticky].max() <= 0.10 and S[~sticky].max() < fifth.HEALTHY_S
    assert (J >= 0).all() and (J <= S).all()
    # every plant meets every valve sticky, and half the loops carry a small load
    combos = Counter((r["kind"], r["valve"]) for r, s in zip(rows, sticky) if s)
    assert len(combos) == 12 and min(combos.values()) >= 2
    assert sum(r["load"] in ("ou", "drift") for r in rows) == 24
    for r in rows:
        assert r["scan"] in fifth.SCANS[r["kind"]]
        lo, hi = fifth.NOISE[r["kind"]]
        assert lo <= r["noise"] <= hi
        if r["kind"] == "basis":
            assert r["traverse"] / r["scan"] == pytest.approx(round(r["traverse"] / r["scan"]))


def test_every_loop_starts_at_rest_at_its_set_point(fifth, starts_at_rest):
    starts_at_rest(fifth.FifthLoops, fifth.draw(12, 7), output_above=True, read=True)


def test_loops_are_finite_and_the_frictionless_pi_holds_the_set_point(fifth):
    rows = fifth.draw(12, 5)
    res = fifth.check_family(fifth.FifthLoops, rows, ["pi"], 900.0, test_s=fifth.TEST_S)
    sticky = np.array([r["S"] >= fifth.HEALTHY_S for r in rows])
    assert sticky.sum() == 8 and {r["valve"] for r in rows} == set(fifth.VALVE_KINDS)
    assert {r["kind"] for r in rows} == set(fifth.KINDS)
    for label in ("PI frictionless", "pi"):
        for key, v in res[label].items():
            assert np.isfinite(v).all(), (label, key)
    fr, pi = res["PI frictionless"], res["pi"]
    assert np.median(fr["iae"][sticky]) < np.median(pi["iae"][sticky])
    assert fr["iae"][sticky].sum() < 0.8 * pi["iae"][sticky].sum()
    assert (pi["iae"][sticky] > fr["iae"][sticky]).mean() >= 0.75
    assert np.median(fr["offset"]) < 0.002                  # within the noise (0.5-3 pv x1000)
    assert np.median(pi["travel"][sticky]) < 0.6 * np.median(fr["travel"][sticky])
    np.testing.assert_allclose(np.median(pi["iae"][~sticky] / fr["iae"][~sticky]), 1.0, atol=0.1)


def _one(fifth, valve, S, J, scan=0.5, **kw):
    row = dict(fifth.draw(12, 1)[2 + 4 * fifth.VALVE_KINDS.index(valve)])   # a kiln loop of that valve
    assert row["kind"] == "kiln" and row["valve"] == valve
    row.update(S=S, J=J, x0=0.5, **kw)
    sim = fifth.FifthLoops([row], scan, False)
    return sim, sim.reset()


def _drive(sim, ops):
    xs = []
    for op in ops:
        _, x = sim.step(np.array([op]), np.zeros(1))
        xs.append(x[0])
    return np.array(xs)


@pytest.mark.parametrize("valve", ["elastoplastic", "armstrong"])
def test_sticky_valves_hold_inside_the_band_and_slip_beyond_it(fifth, valve):
    S, J = 0.04, 0.02
    sim, (_, x, u0) = _one(fifth, valve, S, J)
    assert x[0] == 0.5 and u0[0] == pytest.approx(0.5 + (S - J) / 2)
    xs = _drive(sim, np.linspace(u0[0], u0[0] - 0.85 * S, 80))    # back into the band: held (presliding only)
    assert abs(xs[-1] - 0.5) < 0.1 * S
    xs = _drive(sim, np.linspace(u0[0] - 0.85 * S, u0[0] - 2.5 * S, 400))   # on beyond it: stick-slip downwards
    jumps = -np.diff(xs)
    assert np.isfinite(xs).all() and xs[-1] < 0.5 - S
    assert jumps.max() > 0.7 * J and (jumps > 0.5 * J).sum() >= 2


@pytest.mark.parametrize("valve", ["elastoplastic", "armstrong"])
def test_dead_band_only_valves_do_not_slip(fifth, valve):
    """``J = 0``: the stem is dragged through the band smoothly, ``F_c = S / 2`` behind the input."""
    sim, (_, x, u0) = _one(fifth, valve, 0.04, 0.0)
    ops = np.linspace(u0[0], u0[0] - 0.1, 200)
    xs = np.concatenate([x, _drive(sim, ops)])
    assert np.abs(np.diff(xs)).max() < 2.0 * abs(ops[1] - ops[0]) + 1e-4
    assert xs[-1] == pytest.approx(ops[-1] + 0.02, abs=0.004)


def test_elastoplastic_presliding_below_z_ba_is_elastic(fifth):
    """Forces under ``beta F_c`` move the stem elastically: it comes back to the same place, cycle after cycle."""
    S, J = 0.04, 0.01
    sim, (_, x, u0) = _one(fifth, "elastoplastic", S, J, beta=0.8)
    fc = (S - J) / 2
    hi, lo = u0[0] - fc, u0[0] - fc - 0.7 * 0.8 * fc            # applied force 0 and -0.56 F_c (z_ba = 0.8 F_c)
    ends = []
    for _ in range(20):
        _drive(sim, [lo] * 20)
        ends.append(_drive(sim, [hi] * 20)[-1])
    assert abs(ends[0] - 0.5) < 0.05 * S
    assert np.ptp(ends) < 1e-6


def test_armstrong_breakaway_rises_with_the_dwell(fifth):
    """The static level grows from ``F_C + F_S,a`` to ``F_C + J`` over the dwell (time constant ``gamma``)."""
    S, J = 0.04, 0.03

    def band(wait):
        sim, (_, x, u0) = _one(fifth, "armstrong", S, J, scan=0.2, gam=200.0, fsa=0.2)
        _drive(sim, [u0[0]] * int(wait / 0.2))
        ops = u0[0] - np.arange(1, 400) * 0.0002                  # 1e-3 stroke/s down
        xs = _drive(sim, ops)
        k = int(np.argmax(0.5 - xs > 0.3 * J))
        return u0[0] - ops[k]

    short, long_ = band(0.0), band(4000.0)
    assert long_ == pytest.approx(S, abs=0.1 * S)
    assert long_ - short > 0.6 * (J - 0.2 * J)


def test_the_positioner_integrates_outside_its_dead_band_only(fifth):
    S, J, ti = 0.04, 0.01, 40.0
    sim, (_, x, u0) = _one(fifth, "positioner", S, J, ti=ti, db=0.05)
    assert u0[0] - 0.5 == pytest.approx(0.05 * S / 2)
    xs = _drive(sim, [0.5 + 0.9 * 0.05 * S] * 600 + [0.5 - 0.9 * 0.05 * S] * 600)   # inside the dead band: held
    assert np.abs(xs - 0.5).max() < 1e-9
    xs = _drive(sim, [u0[0] - 0.85 * S] * int(2.5 * ti / 0.5))      # a quick move back: held, then broken away
    assert np.abs(xs[: int(0.1 * ti / 0.5)] - 0.5).max() < 1e-9
    assert xs[-1] < 0.5 - 0.5 * S
    sim, (_, x, u0) = _one(fifth, "positioner", S, J, ti=ti, db=0.05)
    xs = _drive(sim, [u0[0] - 1.3 * S] * 12)                      # beyond the band: at once (behind the lags)
    assert xs[-1] < 0.5 - 0.2 * S


@pytest.mark.parametrize("J, hunts", [(0.024, True), (0.0, False)])
def test_the_positioner_hunts_when_its_slips_jump_the_dead_band(fifth, J, hunts):
    S = 0.04
    sim, (_, x, u0) = _one(fifth, "positioner", S, J, ti=30.0, db=0.05)
    xs = _drive(sim, [u0[0] + 0.3] * 3000)                        # a move up, then the input held
    late = xs[-1200:]
    moves = np.diff(late)
    assert abs(np.median(late) - (u0[0] + 0.3)) <= J + 0.06 * S
    if hunts:
        assert (moves > 0.5 * J).sum() >= 3 and (moves < -0.5 * J).sum() >= 3
    else:
        assert np.abs(moves).max() < 1e-9 and abs(late[-1] - (u0[0] + 0.3)) <= 0.05 * S + 1e-9


def test_the_drum_shrinks_before_it_fills(fifth):
    row = dict(fifth.draw(4, 3)[0])
    assert row["kind"] == "drum"
    sim = fifth.FifthLoops([row], 0.5, True)
    y0, _, u0 = sim.reset()
    ys = np.array([sim.step(u0 + 0.05, np.zeros(1))[0][0] for _ in range(1200)]) - y0[0]
    assert ys[: int(row["t_s"] / 2 / 0.5)].min() < -1e-3           # shrink: the level falls first
    ramp = (ys[-1] - ys[-200]) / (199 * 0.5)
    assert ramp == pytest.approx(0.05 / row["T_f"], rel=0.02)       # then fills at k_i * 0.05


def test_the_weir_head_follows_the_notch_law(fifth):
    row = dict(fifth.draw(4, 3)[1])
    assert row["kind"] == "weir"
    heads = []
    for du in (0.0, 0.1):
        sim = fifth.FifthLoops([row], 1.0, True)
        y0, _, u0 = sim.reset()
        for _ in range(int(12 * row["T"])):
            y, _ = sim.step(u0 + du, np.zeros(1))
        heads.append(y[0] - row["h_w"])
    q0, q1 = row["x0"], row["x0"] + 0.1
    assert heads[0] == pytest.approx(row["h0"])
    assert heads[1] == pytest.approx(row["h0"] * (q1 / q0) ** (2 / 3), rel=1e-3)


def test_the_kilns_losses_grow_faster_than_its_temperature(fifth):
    u = np.linspace(0.8, 1.6, 9)
    loss = np.array([fifth.kiln_loss(v, 1.0, 0.5) for v in u])
    assert (np.diff(loss) > 0).all() and (np.diff(loss, 2) > 0).all()


def test_basis_weight_jumps_by_the_retention_creeps_and_is_read_once_a_traverse(fifth):
    row = dict(fifth.draw(4, 3)[3])
    assert row["kind"] == "basis"
    sim = fifth.FifthLoops([row], row["scan"], True)
    y0, _, u0 = sim.reset()
    n = int(900 / row["scan"])
    ys = np.array([sim.step(u0 + 0.05, np.zeros(1))[0][0] for _ in range(n)]) - y0[0]
    final = 0.05 * row["pv0"] / row["x0"]
    assert ys[-1] == pytest.approx(final, rel=0.05)
    fast = ys[int((row["delay"] + 2 * row["traverse"] + 6 * row["T_m"]) / row["scan"])]
    assert 0.8 * row["ret"] * final < fast < row["ret"] * final + 0.5 * (1 - row["ret"]) * final
    changes = np.flatnonzero(np.diff(ys) != 0) + 1
    assert len(changes) > 5
    gaps = np.diff(changes) * row["scan"]
    assert np.allclose(gaps, row["traverse"])


def test_measurements(fifth):
    rows = [r for r in fifth.draw(16, 9) if r["scan"] == 1.0]
    kinds = {r["kind"] for r in rows}
    assert {"basis", "weir"} <= kinds
    noise, load = fifth.FifthLoops.disturbances(rows, 1.0, 600, 600.0)
    for i, r in enumerate(rows):
        w = noise[:, i]
        assert 0.5 * r["noise"] < w.std() < 2.0 * r["noise"]
        if r["kind"] == "basis":                                 # held for a traverse
            assert len(np.unique(w)) == int(np.ceil(600 / r["traverse"]))
    sim = fifth.FifthLoops(rows, 1.0, False)
    y0, _, _ = sim.reset()
    sim.measure(y0, np.zeros(len(rows)))
    read = sim.measure(y0 + 0.05, np.zeros(len(rows)))            # a 5-cm jump: the weir's gauge slews
    for i, r in enumerate(rows):
        if r["kind"] == "weir":
            assert read[i] - y0[i] == pytest.approx(r["slew"], abs=sim.res[i])
        else:
            assert read[i] - y0[i] == pytest.approx(0.05, abs=sim.res[i])
            if r["kind"] == "kiln":
                assert read[i] / fifth.KILN_RES == pytest.approx(round(read[i] / fifth.KILN_RES))
