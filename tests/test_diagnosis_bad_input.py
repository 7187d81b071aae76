"""Bad or degenerate input to :func:`valve_gym.diagnosis.diagnose`: a clear error, never a crash or a silent answer."""
from __future__ import annotations

import numpy as np
import pytest

from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.recording import Recording
from valve_gym.diagnosis.synthetic import make_recording


def _flat_pv_record(n=200):
    """An OP that wanders while the PV sits still for most of the record (a frozen transmitter)."""
    rng = np.random.default_rng(0)
    op = np.clip(0.5 + np.cumsum(rng.normal(0, 0.003, n)), 0, 1)
    pv = np.where(np.arange(n) < 180, 0.8, 0.7)
    return Recording(np.arange(float(n)), op, pv, name="flat")


@pytest.mark.parametrize("op_lag", ["auto", 0])
def test_a_pv_that_does_not_move_over_the_fitted_part_is_refused(op_lag):
    # before: op_lag 'auto' crashed with ZeroDivisionError (both pairings fit exactly), and op_lag 0 called
    # the valve sticky with a band of 0
    with pytest.raises(ValueError, match=r"the PV takes only 1 value\(s\) \(0.8\) over the fitted part "
                                         r"\(samples 0-139 of 200\).*use a stretch where the PV moves"):
        diagnose(_flat_pv_record(), plant="first_order", candidates=(), effort="fast", op_lag=op_lag)


def test_the_pairing_test_has_no_underflow_for_a_pv_in_tiny_units():
    from valve_gym.diagnosis.diagnose import _choose_op_lag
    from valve_gym.diagnosis.fit import effective_n
    from valve_gym.diagnosis.select import SelectionRule

    class Fit:                                       # the two base fits' errors, as the test reads them
        def __init__(self, rmse):
            self.rmse, self.residual, self.n_fit = rmse, np.random.default_rng(0).normal(0, rmse, 300), 300

    rec = make_recording("none", seed=1, n=300)
    reaction = {"op_lag": None}
    lag, test = _choose_op_lag({0: (rec, Fit(2e-200), 300), 1: (rec, Fit(1e-200), 300)}, SelectionRule(),
                               "auto", rec, reaction)
    assert np.isfinite(test["delta_ic"]) and test["delta_ic"] < 0          # ln(1/4) n_eff: finite, negative
    assert lag == 1
    assert test["n_eff"] == effective_n(Fit(1.0).residual)                   # the units do not matter


def test_too_few_samples_after_the_holdout_says_what_to_do():
    rec = make_recording("none", seed=1, n=300)
    short = Recording(rec.t[:55], rec.op[:55], rec.pv[:55], name="fifty-five")
    with pytest.raises(ValueError, match=r"only 39 samples to fit after the holdout of 0.3; need >= 40: lower the "
                                         r"holdout \(--holdout 0.1"):
        diagnose(short, plant="tank", candidates=())


def test_candidates_may_be_a_string_and_bad_seed_or_sensor_range_are_named():
    rec = make_recording("overflow", seed=32, n=300)
    res = diagnose(rec, plant="tank", candidates="overflow", effort="fast")        # one effect, not 'o','v',...
    assert res.settings["candidates"] == ["overflow"] or tuple(res.settings["candidates"]) == ("overflow",)
    with pytest.raises(ValueError, match="unknown effect 'lek'"):
        diagnose(rec, plant="tank", candidates="overflow, lek")
    with pytest.raises(ValueError, match="seed must be a whole number >= 0, got -1"):
        diagnose(rec, plant="tank", candidates=(), seed=-1)
    with pytest.raises(ValueError, match=r"saturation \(lo, hi\) must be finite with lo < hi"):
        diagnose(rec, plant="tank", candidates=(), saturation=(2.0, 1.0))
    with pytest.raises(ValueError, match="saturation must be 'auto', None or a pair"):
        diagnose(rec, plant="tank", candidates=(), saturation="0-2")
