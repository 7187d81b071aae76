"""The selection's confirmation rule: a candidate is refitted with the full budget only when its screening
fit lowered the criterion, or its effect's fit is rugged (slip-jump friction)."""
from __future__ import annotations

import importlib
from types import SimpleNamespace

import numpy as np

from valve_gym.diagnosis.fit import fit_with_friction
from valve_gym.diagnosis.model import DataScales, ModelStructure
from valve_gym.diagnosis.synthetic import make_recording
from valve_gym.effects import effect_spec

select = importlib.import_module("valve_gym.diagnosis.select")


def _select(monkeypatch, effect, seed, candidates):
    """Round-1 screening criterion changes ``{effect: dIC}`` and the selection (every candidate shortlisted)."""
    rec = make_recording(effect, seed=seed, n=600)
    n_fit = 420
    st = ModelStructure("tank", "valve", (), DataScales.from_signals(rec.op[:n_fit], rec.pv[:n_fit], rec.dt))
    base = fit_with_friction(st, rec.op, rec.pv, n_fit, rng=0, effort="fast")[0]
    first: dict[str, float] = {}
    compare = select.compare

    def spy(old, new, rule, n_eff=None):
        out = compare(old, new, rule, n_eff)
        if old is base:                                   # round 1; the screening fits are compared first
            first.setdefault(new.structure.effects[-1], out[0])
        return out

    monkeypatch.setattr(select, "compare", spy)
    sel = select.select_effects(base, rec.op, rec.pv, candidates, seed=0, effort="normal",
                                screen_effort="fast", n_confirm=len(candidates))
    return first, sel


def _check(first, sel):
    round1 = [c for c in sel.candidates if c.round == 1]
    assert {c.effect for c in round1} == set(first)
    for c in round1:
        assert c.confirmed == (first[c.effect] < select.CONFIRM_BELOW or effect_spec(c.effect).rugged), c.effect
    return round1


def test_a_candidate_is_confirmed_only_when_its_screening_found_a_gain(monkeypatch):
    first, sel = _select(monkeypatch, "overflow", 32, ("overflow", "leak", "dead_time", "slip_jump"))
    round1 = _check(first, sel)
    assert sel.effects[:1] == ["overflow"]
    assert first["overflow"] < 0 and any(c.confirmed for c in round1)


def test_a_clean_record_confirms_only_what_gains_or_is_rugged(monkeypatch):
    first, sel = _select(monkeypatch, "none", 4, ("leak", "dead_time", "slip_jump"))
    round1 = _check(first, sel)
    assert sel.effects == []
    assert any(not c.confirmed for c in round1)            # a screening without gain is not refitted
    assert next(c for c in round1 if c.effect == "slip_jump").confirmed


def _fit(cost, k, holdout):
    return SimpleNamespace(n_fit=1000, cost=cost, k=k, holdout_rmse=holdout)


def test_a_swap_of_equal_size_must_only_predict_the_held_out_end_better():
    rule = select.SelectionRule()
    old = _fit(1.0, 6, 0.100)
    # the criterion falls well past its margin in every case below (n_eff 200, SSE halved)
    swap_small_gain = _fit(0.5, 6, 0.095)           # held-out 5 % better, no new parameter
    add_small_gain = _fit(0.5, 7, 0.095)            # the same, with one parameter more
    add_big_gain = _fit(0.5, 7, 0.089)              # 11 % better, one parameter more
    swap_worse = _fit(0.5, 6, 0.101)                # no new parameter, held-out 1 % worse
    assert select.compare(old, swap_small_gain, rule, 200.0)[2]
    assert not select.compare(old, add_small_gain, rule, 200.0)[2]
    assert select.compare(old, add_big_gain, rule, 200.0)[2]
    assert not select.compare(old, swap_worse, rule, 200.0)[2]
    assert select.holdout_need(rule, 0) == 0.0 and select.holdout_need(rule, 2) == rule.holdout_gain
    # the reason names what is missing
    cf = select.CandidateFit(round=1, effect="slip_jump", variant=None, fit=swap_worse, delta_ic=-50.0,
                             holdout_change=0.01, pays=False)
    assert select._reason(cf, rule, 0).endswith("held-out RMSE does not fall")
    cf = select.CandidateFit(round=1, effect="leak", variant=None, fit=add_small_gain, delta_ic=-50.0,
                             holdout_change=-0.05, pays=False)
    assert select._reason(cf, rule, 1).endswith("held-out RMSE does not fall by 10 %")


def test_a_friction_law_is_named_only_with_a_band_that_governs_the_loop():
    rule = select.SelectionRule()
    wide = np.linspace(0.2, 0.8, 500)                   # output working range 0.58: the 1 % band rules
    narrow = 0.5 + 0.005 * np.sin(np.arange(500.0))     # range 1 %: half of it, 0.5 %, is enough
    assert rule.band_needed(wide) == rule.abs_band
    assert abs(rule.band_needed(narrow) - rule.rel_band * select.op_working_range(narrow)) < 1e-12
    assert rule.band_needed(np.full(500, 0.5)) == rule.min_band
    paper = SimpleNamespace(physical={"valve.e_dead": 0.004}, k=6)
    small = SimpleNamespace(physical={"slip_jump.S": 0.006, "slip_jump.J": 0.003}, k=6)
    large = SimpleNamespace(physical={"slip_jump.S": 0.02, "slip_jump.J": 0.01}, k=6)
    leak = SimpleNamespace(physical={"valve.e_dead": 0.004, "leak.q": 0.1}, k=7)
    need = rule.band_needed(wide)
    assert select.friction_band(paper) == 0.008 and select.friction_band(small) == 0.006
    assert select._small_friction(paper, small, need)           # a 0.6 % band governs no loop of this output
    assert not select._small_friction(paper, large, need)
    assert not select._small_friction(paper, leak, need)        # not a change of the friction law
    assert not select._small_friction(small, SimpleNamespace(physical={**small.physical, "leak.q": 0.1}), need)
    cf = select.CandidateFit(round=1, effect="slip_jump", variant=None, fit=small, delta_ic=-9.5,
                             holdout_change=-0.07, pays=False)
    assert "its friction band (0.6 % of the stroke) is smaller than the 1 %" in select._reason(cf, rule, 0, need)
