"""``python -m valve_gym.agents.learned_eval``: the noise option reaches the loops, bad values are refused."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.agents.learned_eval import evaluate_learned, main


def test_noise_option_sets_the_loops_measurement_noise():
    res = evaluate_learned(n=3, seed=11, compensators=False, noise_std=0.0005)
    assert res["config"].regulation.noise_std == 0.0005
    std = float(np.std(res["scenarios"].noise))
    assert 0.0004 < std < 0.0006, std
    assert set(res["scores"]) >= {"PI (SIMC)", "PI frictionless", "learned"}


@pytest.mark.parametrize("bad", ["-0.001", "nan", "2"])
def test_bad_noise_is_refused_with_the_reason(bad, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--n", "3", "--noise", bad])
    assert exc.value.code == 2
    assert "--noise must be a standard deviation in m" in capsys.readouterr().err


def test_by_model_table_counts_each_sticky_loop_once_under_its_friction_model():
    from valve_gym.agents.learned_eval import _by_model

    res = evaluate_learned(n=9, seed=11, compensators=False)
    scen = res["scenarios"]
    sticky = np.asarray(scen.band).astype(str) != "healthy"
    rows = [r for r in _by_model(res).splitlines() if r.startswith("| ") and not r.startswith("| friction")]
    counted = {r.split(" | ")[0][2:]: int(r.split(" | ")[1]) for r in rows}
    models, n = np.unique(np.asarray(scen.model).astype(str)[sticky], return_counts=True)
    assert counted == dict(zip(models.tolist(), n.tolist()))
    for r in rows:                                     # shares are fractions of the model's loops
        assert all(0.0 <= float(x) <= 1.0 for x in r.strip(" |").split(" | ")[3:])
