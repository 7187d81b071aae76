"""The held-out stiction validation scores the features ``diagnose`` computes, not a copy of its own."""
from __future__ import annotations

import copy

import pytest


@pytest.mark.slow
def test_refresh_reproduces_the_features_of_diagnose(repo_module):
    vs = repo_module("benchmarks/validate_stiction.py", "validate_stiction")
    # a sticky textbook loop logged as the simulator scans (pairing 1): the model reads it re-paired,
    # the data-driven methods as logged; the refresh must recompute exactly what diagnose gave
    items = [dict(it, op_lag="auto") for it in vs._sim_items(4)]
    item = next(it for it in items if it["label"] == 1)
    r = vs._run_one(item)
    assert r["op_lag_chosen"] == 1
    before = copy.deepcopy(r["features"])
    vs.refresh([r], items)
    assert r["features"].keys() == before.keys()
    for k, v in before.items():
        assert abs(r["features"][k] - v) <= 1e-12, k
