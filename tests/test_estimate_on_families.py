"""``benchmarks/estimate_on_families.py``: the learned compensator's band estimate on the held-out families."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def est(repo_module):
    return repo_module("benchmarks/estimate_on_families.py", "estimate_on_families")


def test_estimates_are_the_blocks_own_and_in_range(est):
    S, S_hat = est.estimates("third", duration=600.0, n=6)
    assert S.shape == S_hat.shape == (6,) and np.isfinite(S_hat).all()
    assert np.all((S_hat >= 0.001) & (S_hat <= 0.2))          # the block's clip of its estimate
    assert np.unique(np.round(S_hat, 6)).size > 1              # each loop's own estimate, not one shared value


def test_bad_duration_is_one_clear_error(est, capsys):
    with pytest.raises(SystemExit) as exc:
        est.main(["--duration", "0"])
    assert exc.value.code == 2 and "--duration must be > 0" in capsys.readouterr().err


def test_answers_row_reads_the_blocks_own_reversals_and_answers(est):
    r = est._run("seventh", duration=600.0, n=6)
    sticky = r["S"] >= est.HEALTHY_S
    assert sticky.sum() == 4 and (r["flips"] >= r["answers"]).all()   # an answer needs a reversal before it
    ok = np.isfinite(r["travel"])
    assert ok.any() and (r["travel"][ok] > 0).all()
    row = est.answers_table("seventh", duration=600.0, n=6)
    assert row.startswith("| seventh | 4 | ") and row.count("|") == 8
