"""The third held-out family (``benchmarks/learned_third_check.py``): its simulators under the PI alone."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def third(repo_module):
    return repo_module("benchmarks/learned_third_check.py", "learned_third_check")


def test_loops_are_finite_and_the_frictionless_pi_holds_the_set_point(third):
    rows = third.draw(12, 5)
    res = third.check_family(third.ThirdLoops, rows, ["pi"], 900.0, test_s=third.TEST_S)
    sticky = np.array([r["S"] >= third.HEALTHY_S for r in rows])
    assert sticky.sum() == 8 and {r["valve"] for r in rows} == set(third.VALVE_KINDS)
    for label in ("PI frictionless", "pi"):
        for key, v in res[label].items():
            assert np.isfinite(v).all(), (label, key)
    fr, pi = res["PI frictionless"], res["pi"]
    assert np.median(fr["iae"][sticky]) < np.median(pi["iae"][sticky])
    assert fr["iae"][sticky].sum() < 0.8 * pi["iae"][sticky].sum()
    assert np.median(fr["offset"]) < 0.002                  # within the noise (0.5-4 pv x1000)
    assert np.median(pi["travel"][sticky]) < np.median(fr["travel"][sticky])


def _one(third, valve, S, J, scan=1.0):
    row = dict(third.draw(12, 1)[3 + 4 * third.VALVE_KINDS.index(valve)])    # block 0: a flow loop with that valve
    assert row["kind"] == "flow" and row["valve"] == valve
    row.update(S=S, J=J, x0=0.5)
    sim = third.ThirdLoops([row], scan, False)
    return sim, sim.reset()


def test_dead_band_valve_ignores_input_moves_inside_its_band(third):
    S = 0.04
    sim, (_, x, u0) = _one(third, "dead_band", S, 0.0)
    assert x[0] == 0.5 and u0[0] == pytest.approx(0.5 + S / 2)
    rng = np.random.default_rng(0)
    for op in 0.5 + rng.uniform(-0.45 * S, 0.45 * S, 200):   # every input within the band
        _, x = sim.step(np.array([op]), np.zeros(1))
        assert x[0] == 0.5
    for _ in range(30):                                     # beyond it, dragged at S/2 behind
        _, x = sim.step(np.array([0.5 + S / 2 + 0.01]), np.zeros(1))
    assert x[0] == pytest.approx(0.51, abs=1e-6)


@pytest.mark.parametrize("valve", ["force_balance", "lugre"])
def test_sticky_valves_hold_inside_the_band_and_slip_beyond_it(third, valve):
    S, J = 0.04, 0.02
    sim, (_, x, u0) = _one(third, valve, S, J)
    for op in np.linspace(u0[0], u0[0] - 0.8 * S, 60):     # back into the band: stuck (LuGre: pre-sliding)
        _, x = sim.step(np.array([op]), np.zeros(1))
    assert abs(x[0] - 0.5) < 0.002
    xs = []
    for op in np.linspace(u0[0] - 0.8 * S, u0[0] - 2.0 * S, 240):   # on beyond it: stick-slip downwards
        _, x = sim.step(np.array([op]), np.zeros(1))
        xs.append(x[0])
    jumps = -np.diff(xs)
    assert xs[-1] < 0.5 - S / 2 and jumps.max() > 0.5 * J and np.isfinite(xs).all()


def test_the_second_familys_harness_runs_its_own_simulator(repo_module):
    """The harness the third family reuses still runs the second family's loops (``Loops``)."""
    second = repo_module("benchmarks/learned_unseen_check.py", "learned_unseen_check")
    rows = second.draw(3, 913)
    res = second.check_family(second.Loops, rows, ["pi"], 600.0)
    assert list(res) == ["PI frictionless", "pi"]
    assert all(np.isfinite(v).all() for p in res.values() for v in p.values())


def test_known_rows_hand_each_loop_its_true_band(third, monkeypatch):
    """The ``--known`` rows build their blocks with each loop's own ``S`` (knocker: ``S``; adaptive: ``S0``, frozen)."""
    harness = third.check_family.__module__
    mod = __import__(harness)
    seen = {}

    def spy(name, **kw):
        seen.setdefault(name, kw)
        return real(name, **kw)

    real = mod.load_controller
    monkeypatch.setattr(mod, "load_controller", spy)
    rows = [r for r in third.draw(12, 5) if r["scan"] == third.draw(12, 5)[0]["scan"]][:3]
    res = third.check_family(third.ThirdLoops, rows, ["pi", *third.KNOWN], 120.0, test_s=third.TEST_S)
    S = np.array([r["S"] for r in rows])
    np.testing.assert_allclose(seen["knocker"]["S"], np.maximum(S, 0.001))
    np.testing.assert_allclose(seen["learned"]["S0"], np.clip(S, 0.001, 0.06))
    assert seen["learned"]["eta"] == 0.01
    assert all(np.isfinite(v).all() for label in third.KNOWN for v in res[label].values())
