"""The selection's confirmation rule: a candidate is refitted with the full budget only when its screening
fit lowered the criterion, or its effect's fit is rugged (slip-jump friction)."""
from __future__ import annotations

import importlib

from valve_gym.diagnosis.fit import fit_with_friction
from valve_gym.diagnosis.model import DataScales, ModelStructure
from valve_gym.diagnosis.synthetic import make_recording
from valve_gym.effects import effect_spec

select = importlib.import_module("valve_gym.diagnosis.select")


def _select(monkeypatch, effect, seed, candidates):
    """Round-1 screening criterion changes ``{(effect, variant): dIC}``, the (effect, variant) pairs refitted
    with the full budget in round 1, and the selection (every candidate shortlisted)."""
    rec = make_recording(effect, seed=seed, n=600)
    n_fit = 420
    st = ModelStructure("tank", "valve", (), DataScales.from_signals(rec.op[:n_fit], rec.pv[:n_fit], rec.dt))
    base = fit_with_friction(st, rec.op, rec.pv, n_fit, rng=0, effort="fast")[0]
    first: dict[tuple, float] = {}
    confirmed: set[tuple] = set()
    compare, fit_candidate = select.compare, select._fit_candidate

    def key(structure):
        e = structure.effects[-1]
        return e, structure.variants.get(e)

    def spy(old, new, rule, n_eff=None):
        out = compare(old, new, rule, n_eff)
        if old is base:                                   # round 1; the screening fits are compared first
            first.setdefault(key(new.structure), out[0])
        return out

    def spy_fit(args):
        res = fit_candidate(args)
        if args[0] is base and args[7] == "normal":      # a round-1 fit with the full budget
            confirmed.add(key(res.structure))
        return res

    monkeypatch.setattr(select, "compare", spy)
    monkeypatch.setattr(select, "_fit_candidate", spy_fit)
    sel = select.select_effects(base, rec.op, rec.pv, candidates, seed=0, effort="normal",
                                screen_effort="fast", n_confirm=len(candidates))
    return first, confirmed, sel


def _check(first, confirmed, sel):
    """Of each effect, the variant whose screening scored best is confirmed exactly when that score
    lowered the criterion or the effect is rugged; no other fit is confirmed."""
    round1 = [c for c in sel.candidates if c.round == 1]
    assert {c.effect for c in round1} == {e for e, _ in first}
    want = set()
    for e in {e for e, _ in first}:
        best = min((k for k in first if k[0] == e), key=first.__getitem__)
        if first[best] < select.CONFIRM_BELOW or effect_spec(e).rugged:
            want.add(best)
    assert confirmed == want
    for c in round1:
        assert c.confirmed == ((c.effect, c.variant) in confirmed), c.effect
    return round1


def test_a_candidate_is_confirmed_only_when_its_screening_found_a_gain(monkeypatch):
    first, confirmed, sel = _select(monkeypatch, "overflow", 32, ("overflow", "leak", "dead_time", "slip_jump"))
    round1 = _check(first, confirmed, sel)
    assert sel.effects[:1] == ["overflow"]
    assert first[("overflow", None)] < 0 and any(c.confirmed for c in round1)


def test_a_clean_record_confirms_only_what_gains_or_is_rugged(monkeypatch):
    first, confirmed, sel = _select(monkeypatch, "none", 4, ("leak", "dead_time", "slip_jump"))
    _check(first, confirmed, sel)
    assert sel.effects == []
    assert ("leak", None) not in confirmed or ("dead_time", None) not in confirmed   # no gain: not refitted
    assert sum(e == "slip_jump" for e, _ in confirmed) == 1      # rugged: one form refitted whatever it scored
