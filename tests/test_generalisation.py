"""The benchmark's generalisation part: its plants (written apart from the core), its draw and its scores."""
from __future__ import annotations

import ast
import pathlib

import numpy as np

from valve_gym.agents.bench.config import BenchConfig
from valve_gym.agents.bench.generalisation import GenFamily, gen_lineup, gen_loops, run_generalisation
from valve_gym.agents.bench.unseen_plants import PlantSpec, UnseenPlants, pi_tuning

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _spec(**kw):
    base = dict(process="tank", valve="stick_band", S=0.04, J=0.01, tau_p=0.5, tau_s=0.5, area=0.3, q_max=0.01,
                k_out=0.005, theta=0.0, level=1.0)
    return PlantSpec(**{**base, **kw})


def test_unseen_plants_share_no_code_with_the_core():
    tree = ast.parse((ROOT / "valve_gym/agents/bench/unseen_plants.py").read_text(encoding="utf-8"))
    mods = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    mods |= {str(n.module) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(m.startswith(("valve_gym", ".")) or m in ("core", "plant", "friction", "params") for m in mods)


def test_each_process_rests_at_its_operating_point():
    specs = [_spec(), _spec(process="integrating", area=1.0), _spec(process="fopdt", q_max=2.0, k_out=10.0,
                                                                     theta=2.0, level=1.0)]
    p = UnseenPlants(specs, 1.0)
    y0, x0, u0 = p.reset()
    for _ in range(200):
        y, x = p.step(u0, np.zeros(3))
    np.testing.assert_allclose(y, y0, atol=1e-9)
    np.testing.assert_allclose(x, x0)


def test_valves_stick_within_the_band_and_slip_beyond():
    for valve in ("stick_band", "force_balance"):
        p = UnseenPlants([_spec(valve=valve, S=0.04, J=0.01)], 1.0)
        _, x0, u0 = p.reset()
        _, x = p.step(u0 - 0.01, np.zeros(1))             # 1 % back: inside the stick band
        for _ in range(5):
            _, x = p.step(u0 - 0.01, np.zeros(1))
        assert x[0] == x0[0], valve
        for _ in range(10):
            _, x = p.step(u0 + 0.08, np.zeros(1))          # 8 % on: the stem moves, lagging by about (S - J)/2
        assert 0.04 < x[0] - x0[0] < 0.08, (valve, x[0] - x0[0])
        q = UnseenPlants([_spec(valve=valve)], 1.0, frictionless=True)
        _, xf, uf = q.reset()
        for _ in range(20):
            _, xf = q.step(uf - 0.01, np.zeros(1))
        assert abs(xf[0] - (uf[0] - 0.01)) < 1e-6          # no friction: the stem follows the positioner


def test_tuning_is_simc_of_the_loop_model():
    Kc, Ti = pi_tuning(_spec(process="fopdt", q_max=2.0, k_out=10.0, theta=1.0, tau_p=0.5), 1.0)
    theta = 1.0 + 0.5 + 0.5
    tc = max(10.0 / 8.0, 4.0 * theta)
    assert np.isclose(Kc, 10.0 / (2.0 * (tc + theta))) and np.isclose(Ti, min(10.0, 4.0 * (tc + theta)))


def test_family_is_fixed_and_covers_its_cases():
    a, b = gen_loops(), gen_loops()
    assert a.n == 48 and all(np.array_equal(x, y) for x, y in zip(a.load, b.load))
    ss = a.band != "healthy"
    for arr in (a.process, a.model, a.load_level):
        assert all(np.sum(ss & (arr == v)) >= 8 for v in set(arr.tolist()))
    assert set(a.scan_s.tolist()) == {0.5, 1.0, 2.0}


def test_family_follows_the_size_of_the_run():
    assert GenFamily.for_config(BenchConfig()) == GenFamily()
    q = GenFamily.for_config(BenchConfig().quick_version())
    assert (q.n_healthy, q.n_sticky, q.n_severe) == (1, 1, 1) and q.duration_s == 2400.0 * 600.0 / 3600.0
    small, full = gen_loops(q), gen_loops()
    assert small.specs[0] == full.specs[0]                 # loop i is the same loop in every size


def test_quick_part_scores_every_row_with_the_benchmark_scores():
    cfg = BenchConfig().quick_version()
    fam = GenFamily(n_healthy=1, n_sticky=1, n_severe=1, duration_s=240.0, scans=(1.0,))
    res = run_generalisation(cfg, fam, jobs=1, learned=())
    labels = [s.label for s in gen_lineup(cfg, ())]
    assert list(res.scores) == labels
    assert {r.part for r in res.summary} == {"generalisation"}
    r = {(x.controller, x.band, x.metric): x.estimate.value for x in res.summary}
    assert r[("PI (SIMC)", "sticky+severe", "R")] == 0.0
    assert r[("PI frictionless", "sticky+severe", "lc_share")] == 0.0


def test_a_row_may_build_its_block_per_group_of_loops():
    """``policies`` rows with ``for_loops(loops, idx, scan_s)`` get the loops' settings: a row that builds the
    loops' own SIMC PI scores exactly as the PI row, and one that reads the loops' true S as the knocker's
    estimate scores as the "(S known)" row."""
    from valve_gym.agents import load_controller

    class Rows:
        def __init__(self, make):
            self.make = make

        def for_loops(self, loops, idx, scan_s):
            return self.make(loops, idx, scan_s)

    cfg = BenchConfig().quick_version()
    fam = GenFamily(n_healthy=1, n_sticky=1, n_severe=1, duration_s=240.0, scans=(1.0,))
    seen = []

    def pi(loops, idx, scan_s):
        seen.append(idx.copy())
        return load_controller("pi", Kc=loops.Kc[idx], Ti=loops.Ti[idx], scan_s=scan_s)

    def knocker(loops, idx, scan_s):
        return load_controller("knocker", Kc=loops.Kc[idx], Ti=loops.Ti[idx], scan_s=scan_s,
                               S=np.maximum(loops.S[idx], 0.001))

    res = run_generalisation(cfg, fam, jobs=1, learned=(), policies={"my PI": Rows(pi), "my knocker": Rows(knocker)})
    assert any(i.size == 3 for i in seen)                       # one block for the group of all three loops
    for mine, theirs in (("my PI", "PI (SIMC)"), ("my knocker", "knocker (S known)")):
        np.testing.assert_array_equal(res.scores[mine].iae_per_h, res.scores[theirs].iae_per_h)


def test_breakdown_splits_the_loops_by_slip():
    from valve_gym.agents.bench.generalisation import breakdown

    cfg = BenchConfig().quick_version()
    fam = GenFamily(n_healthy=1, n_sticky=3, n_severe=3, duration_s=240.0, scans=(1.0,))
    res = run_generalisation(cfg, fam, jobs=1, learned=())
    rows = {r.split(" | ")[0].lstrip("| "): int(r.split(" | ")[1]) for r in breakdown(res, ()) if r.startswith("| ")
            and not r.startswith("| group")}
    slip = np.array([s.J / s.S for s, b in zip(res.loops.specs, res.loops.band) if b != "healthy"])
    assert rows["slip J/S < 1/3"] == int((slip < 1 / 3).sum())
    assert rows["slip J/S >= 2/3"] == int((slip >= 2 / 3).sum())
    assert sum(v for k, v in rows.items() if k.startswith("slip")) == 6     # each sticky loop in one slip group
